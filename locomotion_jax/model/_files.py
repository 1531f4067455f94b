"""Mechanism files: a robot described in TOML, read by [`load_mechanism`][] and written by [`save_mechanism`][].

A file holds one configuration of one kind of mechanism (`kind = "paper"`: the two-mass model,
[`Params`][]; `kind = "chain"`: a [`Chain`][]; `kind = "mechanism"`: a [`Mechanism`][], bodies and
links in arrays of tables, `_files_mechanism.py`). Its friction law, actuator and waveforms are typed
tables (`type = "AnisotropicCoulomb"`, `type = "TravellingWave"`, ...) named after the classes, so a
new element is one more entry of a table below, and a new kind (bodies, links and anchors of SPEC §9)
reuses them in its own tables. Unknown kinds, tables, fields and types are refused, never ignored.

Reading checks the file's structure and types first (an error names the file, the line where it can
be found, the table and the field), then the constructors check the values (their messages come
through with the file's name in front). Every error is a [`MechanismFileError`][], a `ValueError`.

`sweep FILE --vary PATH=VALUES` (`cli/_vary.py`) reads a parsed file again with some of its numbers
replaced by [`Swept`][] values ([`read_document`][]): the same reader then builds a batch of chains or
mechanisms, one per configuration.
"""

import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np


if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # pyright: ignore[reportMissingImports]

from ._actuator import AbstractActuator, InternalForce, RestLength
from ._chain import Chain
from ._friction import AbstractFriction, AnisotropicCoulomb, Coulomb, Stribeck
from ._params import PARAM_NAMES, Params
from ._springwaves import SpringFourier, TravellingWave
from ._waveform import AbstractWaveform, Fourier, Sinusoid, Spline


SCHEMA = 1
"""The schema version that this reader writes and reads (`schema = 1`, optional in a file)."""

KINDS: tuple[str, ...] = ("paper", "chain", "mechanism")
"""The kinds of mechanism a file may describe."""

FRICTION: dict[str, tuple[type[AbstractFriction], tuple[str, ...], tuple[str, ...]]] = {
    "Coulomb": (Coulomb, ("mu_s", "mu_k"), ()),
    "AnisotropicCoulomb": (AnisotropicCoulomb, ("mu_s_fwd", "mu_s_bwd", "mu_k_fwd", "mu_k_bwd"), ()),
    "Stribeck": (Stribeck, ("mu_s", "mu_k", "v_s"), ("mu_s_bwd", "mu_k_bwd")),
}
"""Friction laws by `type`: class, required coefficients, optional ones (each a number or one per mass)."""

ACTUATORS: dict[str, type[AbstractActuator]] = {"RestLength": RestLength, "InternalForce": InternalForce}


class MechanismFileError(ValueError):
    """A mechanism file that cannot be read or written: its message names the file, the line
    where known, the table and the field (`worm.toml, line 12: [friction] mu_k: expected ...`)."""


class Swept:
    """A number of a parsed file replaced by one value per configuration (`values`, 1-D): the reader
    passes it where it would pass the number, so the mechanism it builds is a batch (`sweep` of a file)."""

    def __init__(self, values: Any):
        self.values = np.asarray(values, float)

    def __repr__(self) -> str:
        return f"<{self.values.size} swept values>"


def value_of(x: Any) -> float | np.ndarray:
    """A number of a parsed file as the reader passes it on: a float, or a [`Swept`][]'s values."""
    return x.values if isinstance(x, Swept) else float(x)


def stacked(items: Sequence[Any]) -> Any:
    """Numbers (one per body, spring or harmonic), along a last axis: the list itself, unless a
    [`Swept`][] among them makes it a batch (configurations, len(items))."""
    if not any(isinstance(x, (Swept, np.ndarray)) for x in items):
        return list(items)
    return np.stack(np.broadcast_arrays(*(np.asarray(value_of(x) if isinstance(x, Swept) else x, float)
                                          for x in items)), axis=-1)  # fmt: skip


# -- reading: one table at a time ------------------------------------------------------------------------------


class _Table:
    """A table of a file being read: its values, and where it stands (for messages)."""

    def __init__(self, source: "_Source", name: str, data: Any, index: int | None = None):
        self.source, self.name, self.index = source, name, index
        if not isinstance(data, dict):
            self.source.fail(f"[{name}]: expected a table, got {_shown(data)}", self._line(None))
        self.data: dict[str, Any] = data

    @property
    def label(self) -> str:
        if not self.name:
            return ""
        return f"[[{self.name}]] #{self.index + 1} " if self.index is not None else f"[{self.name}] "

    def _line(self, key: str | None) -> int | None:
        return self.source.line_of(self.name, self.index, key)

    def fail(self, key: str | None, message: str) -> NoReturn:
        self.source.fail(f"{self.label}{key + ': ' if key else ''}{message}".rstrip(), self._line(key))

    def only(self, allowed: Sequence[str], hint: str = "") -> None:
        for key in self.data:
            if key not in allowed:
                valid = ", ".join(allowed)
                self.fail(key, f"unknown field{hint}; the fields of this table are {valid}")

    def has(self, key: str) -> bool:
        return key in self.data

    def required(self, key: str) -> Any:
        if key not in self.data:
            self.fail(None, f"missing field '{key}'")
        return self.data[key]

    def number(self, key: str, default: float | None = None) -> float | np.ndarray:
        if key not in self.data and default is not None:
            return default
        value = self.required(key)
        if not _is_number(value):
            self.fail(key, f"expected a number, got {_shown(value)}")
        return value_of(value)

    def numbers(self, key: str, n: int, what: str, default: float | None = None) -> float | list[float] | np.ndarray:
        """A number (broadcast) or a list of `n` numbers (one per `what`); a list of one is broadcast too."""
        if key not in self.data and default is not None:
            return default
        value = self.required(key)
        if _is_number(value):
            v = value_of(value)
            return v[:, None] if isinstance(v, np.ndarray) else v  # swept: (configurations, 1), broadcast
        if isinstance(value, list) and len(value) in (1, n) and all(_is_number(v) for v in value):
            return stacked([value_of(v) for v in value])
        self.fail(key, f"expected a number or a list of {n} numbers (one per {what}), got {_shown(value)}")

    def vector(self, key: str, at_least: int = 1) -> np.ndarray:
        value = self.required(key)
        if not (isinstance(value, list) and len(value) >= at_least and all(_is_number(v) for v in value)):
            self.fail(key, f"expected a list of at least {at_least} number(s), got {_shown(value)}")
        return np.asarray(stacked(value), float)

    def matrix(self, key: str, rows: int, what: str) -> np.ndarray:
        value = self.required(key)
        ok = isinstance(value, list) and len(value) == rows and all(isinstance(r, list) and r for r in value)
        ok = ok and len({len(r) for r in value}) == 1 and all(_is_number(v) for r in value for v in r)
        if not ok:
            self.fail(key, f"expected a list of {rows} lists (one per {what}) of as many numbers, got {_shown(value)}")
        lines = [np.asarray(stacked(r), float) for r in value]
        return np.stack(np.broadcast_arrays(*lines), axis=-2)

    def choice(self, key: str, choices: Sequence[str]) -> str:
        value = self.required(key)
        if value not in choices:
            self.fail(key, f"expected one of {', '.join(map(repr, choices))}, got {_shown(value)}")
        return value

    def sub(self, key: str) -> "_Table | None":
        return _Table(self.source, key, self.data[key]) if key in self.data else None


class _Source:
    """A file's name and text: where a table's key stands, and the errors that name it."""

    def __init__(self, name: str, text: str):
        self.name, self.lines = name, text.splitlines()

    def fail(self, message: str, line: int | None = None) -> NoReturn:
        at = f", line {line}" if line is not None else ""
        raise MechanismFileError(f"{self.name}{at}: {message}.")

    def line_of(self, table: str, index: int | None, key: str | None) -> int | None:
        """The line of `key` in `table` (its `index`-th header for an array of tables), or of the
        header itself; `None` where the text does not show it plainly (inline or dotted tables)."""
        start = 0
        if table:
            header = re.compile(rf"^\s*\[\[?\s*{re.escape(table)}\s*\]\]?\s*(#.*)?$")
            found = [i for i, line in enumerate(self.lines) if header.match(line)]
            if len(found) <= (index or 0):
                return None
            if key is None:
                return found[index or 0] + 1
            start = found[index or 0] + 1
        elif key is None:
            return None
        item = re.compile(rf"^\s*(\"?){re.escape(key)}\1\s*=")
        for i in range(start, len(self.lines)):
            if _HEADER.match(self.lines[i]):
                break
            if item.match(self.lines[i]):
                return i + 1
        return None if table else self.line_of(key, 0, None)  # a top-level key may be a table


_HEADER = re.compile(r"^\s*\[\[?\s*[A-Za-z_\"][\w.\"-]*\s*\]\]?\s*(#.*)?$")
"""A table's header line (not a line of a multi-line array, which starts with a number or a bracket)."""


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, Swept)) and not isinstance(value, bool)


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# -- reading: the kinds ----------------------------------------------------------------------------------------


def _waveform_of_paper(t: _Table, params: Params) -> AbstractWaveform:
    kind = t.choice("type", ("Sinusoid", "Fourier", "Spline"))
    omega = t.number("omega", float(params.omega))
    lbar = t.number("lbar", float(params.lbar))
    if kind == "Sinusoid":
        t.only(("type", "a", "omega", "lbar"))
        return Sinusoid(t.number("a"), omega, lbar)
    if kind == "Fourier":
        t.only(("type", "cos", "sin", "omega", "lbar"))
        cos, sin = t.vector("cos"), t.vector("sin")
        if len(cos) != len(sin):
            t.fail("sin", f"expected as many numbers as 'cos' ({len(cos)}, one per harmonic), got {len(sin)}")
        return Fourier(cos, sin, omega, lbar)
    t.only(("type", "control", "omega", "lbar"))
    return Spline(t.vector("control", 4), omega, lbar)


def _paper(doc: _Table) -> tuple[Params, AbstractWaveform | None]:
    doc.only(("schema", "kind", "description", "params", "waveform"))
    table = doc.sub("params")
    values: dict[str, Any] = {}
    if table is not None:
        table.only(PARAM_NAMES)
        values = {n: table.number(n) for n in PARAM_NAMES if table.has(n)}
    params = Params.from_dict(values)  # the others: the paper's defaults
    wave = doc.sub("waveform")
    return params, None if wave is None else _waveform_of_paper(wave, params)


def _spring_waveform(t: _Table, lbar: Any) -> AbstractWaveform:
    """One spring's waveform: its mean rest length is the spring's (`[chain] lbar`)."""
    kind = t.choice("type", ("Sinusoid", "Fourier"))
    hint = " ('lbar' is the spring's: give it in [chain] lbar)" if t.has("lbar") else ""
    if kind == "Sinusoid":
        t.only(("type", "a", "omega"), hint)
        return Sinusoid(t.number("a"), t.number("omega"), lbar)
    t.only(("type", "cos", "sin", "omega"), hint)
    cos, sin = t.vector("cos"), t.vector("sin")
    if cos.shape[-1] != sin.shape[-1]:  # the last axis: harmonics (a swept coefficient adds a batch axis)
        t.fail("sin", f"expected as many numbers as 'cos' ({cos.shape[-1]}, one per harmonic), got {sin.shape[-1]}")
    return Fourier(cos, sin, t.number("omega"), lbar)


def _chain_waveforms(doc: _Table, springs: int, lbar: Any) -> Any:
    lb = np.asarray(lbar, float)  # a number, one per spring, or swept: (configurations, 1 or springs)
    lbars = np.broadcast_to(lb, lb.shape[:-1] + (springs,)) if lb.ndim > 1 else np.broadcast_to(lb, (springs,))
    lbars = [lbars[..., j] if lb.ndim > 1 else float(lbars[j]) for j in range(springs)]
    if doc.has("waveform") and doc.has("waveforms"):
        doc.fail("[[waveforms]]", "give either [waveform] (one for the chain) or [[waveforms]] (one per spring)")
    if doc.has("waveforms"):
        items = doc.data["waveforms"]
        if not (isinstance(items, list) and len(items) == springs):
            n = len(items) if isinstance(items, list) else _shown(items)
            doc.fail("waveforms", f"expected {springs} [[waveforms]] tables (one per spring), got {n}")
        return [_spring_waveform(_Table(doc.source, "waveforms", w, j), lbars[j]) for j, w in enumerate(items)]
    t = doc.sub("waveform")
    if t is None:
        return None
    kind = t.choice("type", ("TravellingWave", "SpringFourier", "Sinusoid", "Fourier"))
    if kind == "TravellingWave":
        t.only(("type", "a", "omega", "phi"))
        return TravellingWave(t.number("a"), t.number("omega"), t.number("phi", 0.0))
    if kind == "SpringFourier":
        t.only(("type", "cos", "sin", "omega"))
        cos, sin = t.matrix("cos", springs, "spring"), t.matrix("sin", springs, "spring")
        if sin.shape[-1] != cos.shape[-1]:
            t.fail("sin", f"expected {cos.shape[-1]} harmonics per spring, as 'cos' has, got {sin.shape[-1]}")
        return SpringFourier(cos, sin, t.number("omega"))
    return [_spring_waveform(t, lbars[j]) for j in range(springs)]  # every spring in phase


def _friction(t: _Table, n: int) -> AbstractFriction:
    law = t.choice("type", tuple(FRICTION))
    cls, required, optional = FRICTION[law]
    t.only(("type", *required, *optional))
    values = {k: t.numbers(k, n, "mass") for k in (*required, *(k for k in optional if t.has(k)))}
    return cls(**values)


def _chain(doc: _Table, check: bool = True) -> Chain:
    doc.only(("schema", "kind", "description", "chain", "friction", "actuator", "waveform", "waveforms"))
    if not doc.has("chain"):
        doc.fail(None, "missing table [chain] (masses, k, d, lbar, c)")
    t = _Table(doc.source, "chain", doc.data["chain"])
    t.only(("masses", "k", "d", "lbar", "c"))
    masses = t.vector("masses", 2)
    n = masses.shape[-1]
    k, d, lbar = (
        t.numbers(name, n - 1, "spring", default) for name, default in (("k", 50.0), ("d", 0.5), ("lbar", 3.0))
    )
    c = t.numbers("c", n, "mass", 0.01)
    friction = doc.sub("friction")
    actuator = doc.sub("actuator")
    if actuator is not None:
        actuator.only(("type",))
    waves = _chain_waveforms(doc, n - 1, lbar)
    return Chain(
        masses=masses, k=k, d=d, lbar=lbar, c=c, waveforms=waves,
        friction=None if friction is None else _friction(friction, n),
        actuator=None if actuator is None else ACTUATORS[actuator.choice("type", tuple(ACTUATORS))](), check=check,
    )  # fmt: skip


_TABLES: tuple[str, ...] = ("params", "chain", "friction", "waveform")
"""Where the field that a constructor's message names is looked for, to give its line."""


def _read(source: _Source, text: str) -> tuple[Any, AbstractWaveform | None]:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        message = str(err)
        found = re.search(r"\(at line (\d+), column (\d+)\)", message)
        line = int(found.group(1)) if found else None
        source.fail(f"not valid TOML: {message}", line)
    return read_document(source, data)


def read_document(source: _Source, data: dict[str, Any], check: bool = True) -> tuple[Any, AbstractWaveform | None]:
    """The mechanism (and paper's waveform) of a parsed file `data`, whose text `source` holds;
    `check=False`: a chain or a `kind = "mechanism"` is built unchecked (its invalid values are flagged
    where it runs)."""
    doc = _Table(source, "", data)
    schema = doc.number("schema", float(SCHEMA))
    if schema != SCHEMA:
        doc.fail("schema", f"this version of locomotion_jax reads schema {SCHEMA}, got {_shown(data['schema'])}")
    if doc.has("description") and not isinstance(doc.data["description"], str):
        doc.fail("description", f"expected a string, got {_shown(doc.data['description'])}")
    kind = doc.choice("kind", KINDS)
    try:
        if kind == "paper":
            return _paper(doc)
        if kind == "mechanism":
            from ._files_mechanism import read_mechanism

            return read_mechanism(doc, _friction, check), None
        return _chain(doc, check), None
    except MechanismFileError:
        raise
    except (ValueError, TypeError) as err:  # the constructors' checks of the values
        named = re.match(r"Invalid parameter '(\w+)'", str(err))
        lines = [source.line_of(table, None, named.group(1)) for table in _TABLES] if named else []
        if kind == "mechanism":
            from ._files_mechanism import line_of_message

            lines = [line_of_message(source, str(err))]
        source.fail(str(err).rstrip("."), next((line for line in lines if line is not None), None))


# -- the public functions --------------------------------------------------------------------------------------


def load_mechanism(path: str | Path, *, with_waveform: bool = False) -> Any:
    """Read a mechanism from a TOML file (docs/mechanisms.md, "Mechanism files").

    **Arguments:**

    - `path`: the file.
    - `with_waveform`: return `(mechanism, waveform)`: the paper's model's `[waveform]` table as an
      [`AbstractWaveform`][locomotion_jax.AbstractWaveform] (`None` without one, and for a chain, which
      carries its own), for `measure(mechanism, waveform=waveform)` and `simulate`.

    **Returns:** a [`Params`][locomotion_jax.Params] (`kind = "paper"`), a [`Chain`][locomotion_jax.Chain]
    (`kind = "chain"`) or a [`Mechanism`][locomotion_jax.Mechanism] (`kind = "mechanism"`: bodies and links,
    SPEC §9), or the pair of `with_waveform`.

    **Raises:** [`MechanismFileError`][locomotion_jax.MechanismFileError] (a `ValueError`) naming the file,
    the line where known, the table and the field: a TOML syntax error, an unknown kind, table, field or
    type, a missing field, a value of the wrong type or length, or a value that the constructors refuse
    (their message after the file's name); also for a paper's model with a `[waveform]` without
    `with_waveform=True`, which would drop it. `OSError` if the file cannot be read.

    !!! Example

        ```python
        worm = lj.load_mechanism("examples/worm.toml")  # a Chain
        lj.measure(worm, z=5.0)
        params, wave = lj.load_mechanism("examples/paper.toml", with_waveform=True)
        ```
    """
    path = Path(path)
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise MechanismFileError(f"{path}: not a text file in UTF-8 ({err.reason} at byte {err.start}).") from None
    mech, wave = _read(_Source(str(path), text), text)
    if with_waveform:
        return mech, wave
    if wave is not None:
        raise MechanismFileError(
            f"{path}: [waveform] drives the paper's model, and a Params does not carry it; "
            "load_mechanism(path, with_waveform=True) returns (params, waveform)."
        )
    return mech
