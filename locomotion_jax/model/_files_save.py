"""Writing mechanism files: [`save_mechanism`][], the inverse of [`load_mechanism`][] (`_files.py`, the schema)."""

import re
from pathlib import Path
from typing import Any

import numpy as np

from ._bodies import Mechanism
from ._chain import Chain
from ._files import ACTUATORS, FRICTION, MechanismFileError, SCHEMA
from ._files_mechanism import dump_mechanism
from ._params import PARAM_NAMES, Params
from ._waveform import AbstractWaveform, Fourier, Sinusoid, Spline


HEADER = "# A locomotion_jax mechanism file (schema 1): see docs/mechanisms.md, 'Mechanism files'.\n"


def _plain(x: Any, keep_vector: bool) -> float | list:
    """An array of one configuration as TOML values: a number for a 0-d array (and for a 1-element
    vector unless `keep_vector`), else (nested) lists."""
    a = np.asarray(x)
    if a.ndim == 0 or (a.shape == (1,) and not keep_vector):
        return float(a.reshape(()))
    return a.astype(float).tolist()


def _single(shape: tuple[int, ...]) -> None:
    if shape != ():
        raise MechanismFileError(f"save_mechanism: a file describes one configuration; got a batch of shape {shape}.")


def _dump_paper(params: Params, waveform: AbstractWaveform | None) -> dict[str, Any]:
    _single(params.batch_shape)
    doc: dict[str, Any] = {"schema": SCHEMA, "kind": "paper",
                           "params": {n: float(getattr(params, n)) for n in PARAM_NAMES}}  # fmt: skip
    if waveform is not None:
        if type(waveform) not in (Sinusoid, Fourier, Spline):
            raise MechanismFileError(
                f"save_mechanism: a {type(waveform).__name__} waveform cannot be written; a file holds a "
                "Sinusoid, a Fourier or a Spline."
            )
        fields = {"Sinusoid": ("a",), "Fourier": ("cos", "sin"), "Spline": ("control",)}[type(waveform).__name__]
        if any(np.ndim(getattr(waveform, f)) != (0 if f == "a" else 1) for f in fields) or any(
            np.ndim(getattr(waveform, f)) for f in ("omega", "lbar")
        ):
            raise MechanismFileError("save_mechanism: a file describes one configuration; the waveform is batched.")
        table = {"type": type(waveform).__name__}
        table |= {f: _plain(getattr(waveform, f), True) for f in (*fields, "omega", "lbar")}
        doc["waveform"] = table
    return doc


def _friction_table(law: Any, what: str) -> dict[str, Any]:
    """One body's friction law as a table (scalar coefficients)."""
    name = type(law).__name__
    if name not in FRICTION or FRICTION[name][0] is not type(law):
        raise MechanismFileError(
            f"save_mechanism: the friction law {name} of {what} cannot be written; a file holds {', '.join(FRICTION)}."
        )
    fields = law.fields()
    if any(np.ndim(x) for x in fields.values()):
        raise MechanismFileError(
            f"save_mechanism: a file describes one configuration; the friction law of {what} is batched."
        )
    return {"type": name, **{n: float(x) for n, x in fields.items()}}


def _dump_chain(chain: Chain, waveform: None) -> dict[str, Any]:
    _single(chain.batch_shape)
    law = type(chain.friction).__name__
    if law not in FRICTION or FRICTION[law][0] is not type(chain.friction):
        raise MechanismFileError(
            f"save_mechanism: the friction law {law} cannot be written; a file holds {', '.join(FRICTION)}."
        )
    actuator = type(chain.actuator).__name__
    if actuator not in ACTUATORS or ACTUATORS[actuator] is not type(chain.actuator):
        raise MechanismFileError(
            f"save_mechanism: the actuator {actuator} cannot be written; a file holds {', '.join(ACTUATORS)}."
        )
    fr = chain.friction.fields()
    if any(np.ndim(x) > 1 for x in fr.values()):
        raise MechanismFileError("save_mechanism: a file describes one configuration; the friction law is batched.")
    if chain.signals is not None:
        raise MechanismFileError(
            "save_mechanism: a chain driven by waveforms other than Sinusoid/Fourier (a Spline) cannot be written; "
            "a file holds a chain's actuation as Fourier coefficients."
        )
    w = chain.waves
    return {
        "schema": SCHEMA,
        "kind": "chain",
        "chain": {"masses": _plain(chain.m, True),
                  **{n: _plain(getattr(chain, n), False) for n in ("k", "d", "lbar", "c")}},
        "friction": {"type": law, **{n: _plain(x, np.ndim(x) > 0) for n, x in fr.items()}},
        "actuator": {"type": actuator},
        "waveform": {"type": "SpringFourier", "cos": _plain(w.cos, True), "sin": _plain(w.sin, True),
                     "omega": float(w.omega)},
    }  # fmt: skip


def _dump_mechanism(mechanism: Mechanism, waveform: None) -> dict[str, Any]:
    return {"schema": SCHEMA, "kind": "mechanism", **dump_mechanism(mechanism, _friction_table)}


_DUMP = {"paper": _dump_paper, "chain": _dump_chain, "mechanism": _dump_mechanism}
"""The document of each kind of mechanism (`AbstractMechanism.kind`, the file's `kind`)."""


def save_mechanism(
    mechanism: "Params | Chain | Mechanism",
    path: str | Path,
    *,
    waveform: AbstractWaveform | None = None,
    description: str = "",
) -> Path:
    """Write one mechanism to a TOML file that [`load_mechanism`][locomotion_jax.load_mechanism] reads back
    exactly (every number written with the digits that restore it, every per-mass or per-spring shape kept).

    **Arguments:**

    - `mechanism`: a [`Params`][locomotion_jax.Params] or a [`Chain`][locomotion_jax.Chain], one configuration
      (no batch axes). A chain's actuation is written in its normal form, a `SpringFourier` table (the chain
      does not keep the `TravellingWave` it was built with).
    - `path`: the file (overwritten).
    - `waveform`: the paper's model's rest length, a `Sinusoid`, `Fourier` or `Spline` (a `[waveform]` table);
      `None`: eq. (13) with the parameters' `a`, `omega`, `lbar`.
    - `description`: a line of text kept in the file (`description = "..."`).

    **Returns:** the path written.

    **Raises:** [`MechanismFileError`][locomotion_jax.MechanismFileError] for a batch, a friction law, actuator
    or waveform that a file cannot hold (your own classes), or a `waveform` given with a chain.
    """
    import tomli_w  # writing only; reading needs the standard library's tomllib

    kind = getattr(mechanism, "kind", None)
    if kind not in _DUMP:
        raise MechanismFileError(
            f"save_mechanism: expected a Params, a Chain or a Mechanism, got {type(mechanism).__name__}."
        )
    if kind != "paper" and waveform is not None:
        raise MechanismFileError(
            f"save_mechanism: a {type(mechanism).__name__} carries its own waveforms; waveform= is for Params."
        )
    try:
        doc = _DUMP[kind](mechanism, waveform)
    except MechanismFileError:
        raise
    except ValueError as err:
        raise MechanismFileError(str(err)) from None
    if description:
        doc = {"schema": doc.pop("schema"), "kind": doc.pop("kind"), "description": description, **doc}
    path = Path(path)
    path.write_text(HEADER + _compact(tomli_w.dumps(doc)))
    return path


_NUMBERS = re.compile(r"\[\n((?:[ \t]*[-+\w.]+,\n)+)[ \t]*\]")
"""A multi-line array of numbers as tomli-w writes it (one per line)."""


def _compact(text: str) -> str:
    """tomli-w writes every array one item per line; a row of numbers reads better on one line
    (a matrix keeps one row per line). The test of the round trip reads the result back."""
    return _NUMBERS.sub(lambda m: "[" + ", ".join(v.strip().rstrip(",") for v in m.group(1).splitlines()) + "]", text)
