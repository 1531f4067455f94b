"""Mechanism files of `kind = "mechanism"` (SPEC §9): a [`Mechanism`][locomotion_jax.Mechanism] as arrays of
tables, read by [`load_mechanism`][] and written by [`save_mechanism`][] (`_files.py` holds the schema's
shared parts).

```toml
kind = "mechanism"

[[bodies]]                 # body 0: the capsule
mass = 1.0
friction = { type = "Coulomb", mu_s = 0.5, mu_k = 0.4 }   # or a [bodies.friction] table below
x0 = 0.0                   # optional, with v0, c, and for contact = "hop" y0, w0, restitution (default 0)

[[bodies]]                 # body 1: the internal mass
mass = 0.5
carried_by = 0             # no friction: carried by body 0 (or free without carried_by)

[[links]]
type = "Spring"            # Spring (a, b, k, rest), TiltedSpring (a, b, k, d, rest), Damper (a, b, c),
a = 0                      # Force (a, b, waveform), ExternalForce (i, waveform); "wall" for a body index
b = 1
k = 10.0
```

A signal (a spring's `rest`, a force's `waveform`) is a number or a waveform table: `type = "Sinusoid"`
(`a`, `omega`, `lbar`), `"Fourier"` (`cos`, `sin`, `omega`, `lbar`) or `"Spline"` (`control`, `omega`,
`lbar`); `lbar` defaults to 0. A body without `friction` does not touch the ground. A top-level
`zeno_speed` (default `1e-3`) is the hopping reading's Zeno threshold.
"""

import re
from typing import Any, NoReturn

import numpy as np

from ._bodies import Mechanism
from ._elements import AbstractElement, Damper, End, ExternalForce, Force, Spring, TiltedSpring, WALL
from ._files import _Source, _Table, stacked, Swept
from ._physics import ZENO_SPEED
from ._waveform import AbstractWaveform, Fourier, Sinusoid, Spline


LINKS: dict[str, tuple[type[AbstractElement], tuple[str, ...]]] = {
    "Spring": (Spring, ("a", "b", "k", "rest")),
    "TiltedSpring": (TiltedSpring, ("a", "b", "k", "d", "rest")),
    "Damper": (Damper, ("a", "b", "c")),
    "Force": (Force, ("a", "b", "waveform")),
    "ExternalForce": (ExternalForce, ("i", "waveform")),
}
"""Links by `type`: class and fields (a spring's `rest` and a tilted spring's `d` are optional, default 0)."""

WAVES: dict[str, tuple[type[AbstractWaveform], tuple[str, ...]]] = {
    "Sinusoid": (Sinusoid, ("a",)),
    "Fourier": (Fourier, ("cos", "sin")),
    "Spline": (Spline, ("control",)),
}
"""Waveforms of a signal by `type`: class and coefficient fields (besides `omega`, `lbar`)."""

HOP_FIELDS: tuple[str, ...] = ("y0", "w0", "restitution")
"""The bodies' fields of the hopping reading (SPEC §10), the [`Mechanism`][locomotion_jax.Mechanism]'s
of those names, default 0: written only where not 0 (and the top-level `zeno_speed` where not its
default, `ZENO_SPEED`)."""

BODY_FIELDS: tuple[str, ...] = ("mass", "friction", "carried_by", "c", "x0", "v0", *HOP_FIELDS)


def _block(lines: list[str], name: str, index: int) -> tuple[int, int] | None:
    """The lines `[start, end)` of the `index`-th `[[name]]` table (its sub-tables included)."""
    header = re.compile(rf"^\s*\[\[\s*{re.escape(name)}\s*\]\]\s*(#.*)?$")
    found = [i for i, line in enumerate(lines) if header.match(line)]
    if len(found) <= index:
        return None
    end = found[index + 1] if index + 1 < len(found) else len(lines)
    other = re.compile(r"^\s*\[\[\s*[\w\"-]+\s*\]\]\s*(#.*)?$")  # the next array of tables ends it too
    for i in range(found[index] + 1, end):
        if other.match(lines[i]):
            end = i
            break
    return found[index], end


class _Item(_Table):
    """A table of an array of tables (`[[bodies]] #2`), or a table inside one (`[[bodies]] #2 friction`),
    as `_Table` of `_files.py`: typed fields, and errors that name the file, line, table and field."""

    def __init__(self, source: _Source, array: str, index: int, data: Any, sub: str | None = None):
        self.source, self.array, self.index, self.part = source, array, index, sub
        self.name = array
        self._label = f"[[{array}]] #{index + 1} " + (f"{sub}." if sub else "")
        if not isinstance(data, dict):
            where = self.label.rstrip(".").rstrip()
            self.source.fail(f"{where}: expected a table, got {_shown(data)}", self.line(None))
        self.data: dict[str, Any] = data

    @property
    def label(self) -> str:
        return self._label

    def _line(self, key: str | None) -> int | None:
        return self.line(key)

    def line(self, key: str | None) -> int | None:
        lines = self.source.lines
        block = _block(lines, self.array, self.index)
        if block is None:
            return None
        start, end = block
        if key is None and self.part is None:
            return start + 1
        item = lambda k: re.compile(rf"^\s*(\"?){re.escape(k)}\1\s*=")
        if self.part is not None:  # [array.part] header, or an inline `sub = {...}` line
            header = re.compile(rf"^\s*\[\s*{re.escape(self.array)}\.{re.escape(self.part)}\s*\]\s*(#.*)?$")
            for i in range(start, end):
                if header.match(lines[i]):
                    if key is None:
                        return i + 1
                    for j in range(i + 1, end):
                        if lines[j].lstrip().startswith("["):
                            break
                        if item(key).match(lines[j]):
                            return j + 1
                    return i + 1
            for i in range(start, end):
                if item(self.part).match(lines[i]):
                    return i + 1
            return None
        for i in range(start + 1, end):
            if lines[i].lstrip().startswith("["):
                break
            if item(key or "").match(lines[i]):
                return i + 1
        return start + 1

    def fail(self, key: str | None, message: str) -> NoReturn:
        where = f"{self.label}{key}: " if key else f"{self.label.rstrip('.').rstrip()}: "
        self.source.fail(f"{where}{message}".rstrip(), self.line(key))

    def numbers(self, key: str, n: int, what: str, default: float | None = None) -> float | np.ndarray:
        """One body's coefficient (the friction reader's call; a body's law has one value per field)."""
        return self.number(key, default)

    def end(self, key: str, n: int) -> End:
        """A body index (0 to n - 1) or `"wall"`."""
        value = self.required(key)
        if value == WALL:
            return WALL
        if not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value < n):
            self.fail(key, f'expected a body index (0 to {n - 1}) or "wall", got {_shown(value)}')
        return value

    def inner(self, key: str) -> "_Item":
        return _Item(self.source, self.array, self.index, self.data[key], key)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, Swept)) and not isinstance(value, bool)


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _wave(t: _Item) -> AbstractWaveform:
    kind = t.choice("type", tuple(WAVES))
    cls, fields = WAVES[kind]
    t.only(("type", *fields, "omega", "lbar"))
    omega, lbar = t.number("omega"), t.number("lbar", 0.0)
    if kind == "Sinusoid":
        return Sinusoid(t.number("a"), omega, lbar)
    if kind == "Fourier":
        cos, sin = t.vector("cos"), t.vector("sin")
        if cos.shape[-1] != sin.shape[-1]:  # the last axis: harmonics (a swept coefficient adds a batch axis)
            t.fail("sin", f"expected as many numbers as 'cos' ({cos.shape[-1]}, one per harmonic), got {sin.shape[-1]}")
        return Fourier(cos, sin, omega, lbar)
    return Spline(t.vector("control", 4), omega, lbar)


def _signal(t: _Item, key: str, default: float | None = None) -> float | np.ndarray | AbstractWaveform:
    if key not in t.data and default is not None:
        return default
    value = t.required(key)
    if isinstance(value, dict):
        return _wave(t.inner(key))
    if not _is_number(value):
        t.fail(key, f'expected a number or a waveform table (type = "Sinusoid", ...), got {_shown(value)}')
    return t.number(key)


def line_of_message(source: Any, message: str) -> int | None:
    """The line of the `[[links]]` or `[[bodies]]` table that a constructor's message names first."""
    found = re.search(r"links\[(\d+)\]|body (\d+)", message)
    if found is None:
        return None
    array, index = ("links", found.group(1)) if found.group(1) is not None else ("bodies", found.group(2))
    block = _block(source.lines, array, int(index))
    if block is None:
        return None
    named = re.match(r"Invalid parameter '(\w+)'", message)
    key = {"masses": "mass"}.get(named.group(1), named.group(1)) if named else None
    if key is not None:
        item = re.compile(rf"^\s*(\"?){re.escape(key)}\1\s*=")
        for i in range(block[0] + 1, block[1]):
            if item.match(source.lines[i]):
                return i + 1
    return block[0] + 1


def read_mechanism(doc: Any, friction_of: Any, check: bool = True) -> Mechanism:
    """The `Mechanism` of a parsed file (`doc`: the top-level `_Table`); `friction_of(table, n)` reads a
    friction law (`_files._friction`); `check` as `Mechanism`'s. A [`Swept`][locomotion_jax.model._files.Swept]
    number makes the mechanism a batch, one configuration per swept value."""
    doc.only(("schema", "kind", "description", "bodies", "links", "zeno_speed"))
    items = doc.data.get("bodies")
    if not (isinstance(items, list) and items):
        doc.fail("bodies", "expected one [[bodies]] table per body (at least one)")
    n = len(items)
    bodies = [_Item(doc.source, "bodies", i, b) for i, b in enumerate(items)]
    masses, c, x0, v0, laws, carried = [], [], [], [], [], []
    hop: dict[str, list] = {name: [] for name in HOP_FIELDS}
    for i, b in enumerate(bodies):
        b.only(BODY_FIELDS)
        masses.append(b.number("mass"))
        c.append(b.number("c", 0.0))
        x0.append(b.number("x0", 0.0))
        v0.append(b.number("v0", 0.0))
        for name, values in hop.items():
            values.append(b.number(name, 0.0))
        if "friction" in b.data:
            value = b.data["friction"]
            if not isinstance(value, dict):
                b.fail("friction", f'expected a friction table (type = "Coulomb", ...), got {_shown(value)}')
            laws.append(friction_of(b.inner("friction"), 1))
        else:
            laws.append(None)
        if "carried_by" in b.data:
            j = b.data["carried_by"]
            if not (isinstance(j, int) and not isinstance(j, bool) and 0 <= j < n and j != i):
                b.fail("carried_by", f"expected the index of another body (0 to {n - 1}, not {i}), got {_shown(j)}")
            carried.append(j)
        else:
            carried.append(None)
    raw = doc.data.get("links", [])
    if not isinstance(raw, list):
        doc.fail("links", f"expected [[links]] tables, got {_shown(raw)}")
    links: list[AbstractElement] = []
    for k, item in enumerate(raw):
        t = _Item(doc.source, "links", k, item)
        kind = t.choice("type", tuple(LINKS))
        cls, fields = LINKS[kind]
        t.only(("type", *fields))
        if kind == "Spring":
            links.append(Spring(t.end("a", n), t.end("b", n), t.number("k"), _signal(t, "rest", 0.0)))
        elif kind == "TiltedSpring":
            d = t.number("d", 0.0)
            links.append(TiltedSpring(t.end("a", n), t.end("b", n), t.number("k"), d, _signal(t, "rest", 0.0)))
        elif kind == "Damper":
            links.append(Damper(t.end("a", n), t.end("b", n), t.number("c")))
        elif kind == "Force":
            links.append(Force(t.end("a", n), t.end("b", n), _signal(t, "waveform")))
        else:
            i = t.end("i", n)
            if i == WALL:
                t.fail("i", 'expected a body index, not "wall"')
            links.append(ExternalForce(int(i), _signal(t, "waveform")))
    fields = (("masses", masses), ("c", c), ("x0", x0), ("v0", v0), *hop.items())
    per_body = {name: stacked(values) for name, values in fields}
    zeno = doc.number("zeno_speed", ZENO_SPEED)
    return Mechanism(friction=laws, carried_by=carried, links=links, check=check, zeno_speed=zeno, **per_body)


# -- writing ---------------------------------------------------------------------------------------------------


def _scalar(x: Any, what: str) -> float:
    a = np.asarray(x)
    if a.ndim:
        raise ValueError(f"save_mechanism: a file describes one configuration; {what} is batched (shape {a.shape}).")
    return float(a)


def _wave_table(w: Any, what: str) -> float | dict[str, Any]:
    if not isinstance(w, AbstractWaveform):
        return _scalar(w, what)
    name = type(w).__name__
    if name not in WAVES or WAVES[name][0] is not type(w):
        raise ValueError(
            f"save_mechanism: {what}: a {name} waveform cannot be written; a file holds {', '.join(WAVES)}."
        )
    table: dict[str, Any] = {"type": name}
    for f in WAVES[name][1]:
        x = np.asarray(getattr(w, f))
        if x.ndim != (0 if f == "a" else 1):
            raise ValueError(f"save_mechanism: a file describes one configuration; the waveform of {what} is batched.")
        table[f] = float(x) if x.ndim == 0 else x.astype(float).tolist()
    table["omega"] = _scalar(w.omega, what)
    table["lbar"] = _scalar(w.lbar, what)
    return table


def _end(e: Any) -> int | str:
    return WALL if e == WALL else int(e)


def dump_mechanism(mech: Mechanism, friction_table: Any) -> dict[str, Any]:
    """A `Mechanism` of one configuration as the TOML document `read_mechanism` reads back exactly;
    `friction_table(law, what)` writes a friction law (`_files_save`)."""
    if mech.batch_shape != ():
        raise ValueError(
            f"save_mechanism: a file describes one configuration; got a batch of shape {mech.batch_shape}."
        )
    bodies = []
    for i in range(mech.n_bodies):
        body: dict[str, Any] = {"mass": float(mech.m[i])}
        law = mech.friction[i]
        if law is not None:
            body["friction"] = friction_table(law, f"body {i}")
        if mech.carried_by[i] is not None:
            body["carried_by"] = int(mech.carried_by[i])  # type: ignore[arg-type]
        body |= {"c": float(mech.c[i]), "x0": float(mech.x0[i]), "v0": float(mech.v0[i])}
        hop = {name: float(getattr(mech, name)[i]) for name in HOP_FIELDS}
        body |= {name: x for name, x in hop.items() if x != 0}
        bodies.append(body)
    links = []
    for k, el in enumerate(mech.links):
        what = f"links[{k}] {el.describe()}"
        if isinstance(el, Spring):
            links.append({"type": "Spring", "a": _end(el.a), "b": _end(el.b), "k": _scalar(el.k, what),
                          "rest": _wave_table(el.rest, what)})  # fmt: skip
        elif isinstance(el, TiltedSpring):
            links.append({"type": "TiltedSpring", "a": _end(el.a), "b": _end(el.b), "k": _scalar(el.k, what),
                          "d": _scalar(el.d, what), "rest": _wave_table(el.rest, what)})  # fmt: skip
        elif isinstance(el, Damper):
            links.append({"type": "Damper", "a": _end(el.a), "b": _end(el.b), "c": _scalar(el.c, what)})
        elif isinstance(el, Force):
            wave = _wave_table(el.waveform, what)
            links.append({"type": "Force", "a": _end(el.a), "b": _end(el.b), "waveform": wave})
        elif isinstance(el, ExternalForce):
            links.append({"type": "ExternalForce", "i": el.i, "waveform": _wave_table(el.waveform, what)})
        else:
            raise ValueError(f"save_mechanism: {what}: a {type(el).__name__} cannot be written.")
    doc: dict[str, Any] = {"bodies": bodies}
    if links:
        doc["links"] = links
    if float(mech.zeno_speed) != ZENO_SPEED:
        doc["zeno_speed"] = float(mech.zeno_speed)
    return doc
