"""What the commands share about mechanism files and the click context.

A file (docs/mechanisms.md, "Mechanism files") that cannot be read, or that the schema check refuses,
ends with one line `Error: FILE, line N: ...` and exit code 2.
"""

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import typer


def plain(v: Any) -> Any:
    """A JSON-ready value: a list for an array, a Python number for a scalar."""
    v = np.asarray(v)
    return v.tolist() if v.ndim else v.item()


def load(path: Path) -> tuple[Any, Any]:
    """The file's mechanism and the paper's model's waveform (or `None`); a file that cannot be read
    is a `ValueError` naming it."""
    from ..model._files import load_mechanism

    try:
        mech, wave = load_mechanism(path, with_waveform=True)
    except OSError as err:
        raise ValueError(f"{path}: cannot read the mechanism file ({err.strerror or err}).") from None
    return mech, wave


def context() -> Any:
    """The click context of the running command (`None` outside one): typer's own copy of click where it has one."""
    try:
        from typer._click.globals import get_current_context  # pyright: ignore  # typer >= 0.20 vendors click
    except ImportError:
        from click import get_current_context
    return get_current_context(silent=True)


def given(names: Iterable[str]) -> list[str]:
    """The options among `names` (Python names) that the command line or the environment set, not their defaults."""
    ctx = context()
    if ctx is None:
        return []
    sources = {n: ctx.get_parameter_source(n) for n in names}
    return [n for n, source in sources.items() if source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT")]


def refuse_options(file: Path, names: Iterable[str]) -> None:
    """`ValueError` if any option of `names` was given beside a mechanism file, which describes the mechanism."""
    named = given(names)
    if named:
        options = ", ".join("--" + n.replace("_", "-") for n in named)
        raise ValueError(f"{options}: the mechanism comes from {file}; change it there, or leave out the file.")


def note(message: str) -> None:
    """A progress line on stderr before a long computation (stdout stays the report, or one JSON object)."""
    typer.echo(message, err=True)


def echo_fields(fields: dict[str, Any]) -> None:
    """One line per field: numbers to 6 digits, lists to 4."""
    for name, v in fields.items():
        if isinstance(v, list):
            v = "[" + ", ".join(f"{x:.4g}" if isinstance(x, float) else str(x) for x in v) + "]"
        typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")


def label(file: Path, mech: Any, wave: Any) -> str:
    """`worm.toml: chain of 4 masses, ...`: the first line of a command's report on a file."""
    return f"{file}: {mech.describe()}" + ("" if wave is None else f", {type(wave).__name__} waveform")


def travelling_wave(file: Path) -> dict[str, float] | None:
    """The file's `[waveform]` of type TravellingWave as `{a, omega, phi}`, else `None`.

    Read from the text, because a [`Chain`][] keeps only the normal form of its waveforms; call it
    after [`load`][], which has checked the file.
    """
    from ..model._files import tomllib

    table = tomllib.loads(file.read_text("utf-8")).get("waveform")
    if not (isinstance(table, dict) and table.get("type") == "TravellingWave"):
        return None
    return {"a": float(table["a"]), "omega": float(table["omega"]), "phi": float(table.get("phi", 0.0))}


def with_wave(chain: Any, wave: Any, check: bool = True) -> Any:
    """The file's chain driven by the waveform(s) `wave` instead of its own."""
    from ..model._chain import Chain

    return Chain(masses=chain.m, k=chain.k, d=chain.d, lbar=chain.lbar, c=chain.c, waveforms=wave,
                 friction=chain.friction, actuator=chain.actuator, layout=chain.layout, check=check)  # fmt: skip
