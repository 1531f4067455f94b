"""What `simulate`, `gait`, `optimize`, `sweep`, `chain-sweep` and `animate` do with a mechanism file.

Each of these commands takes an optional FILE argument (docs/mechanisms.md, "Mechanism files");
with it, the mechanism comes from the file ([`load_mechanism`][]), and the command's mechanism
options (`--k`, `--masses`, ...) are refused if given (the file describes the mechanism; a silent
mix of the two would be ambiguous). A sweep's axes are the exception: they replace the file's
values of the parameters swept. The paper's model goes through the command's own code with the
file's [`Params`][] and waveform; a chain through the code of the chain commands, so that
`gait worm.toml` prints what `chain-gait` prints.
"""

from pathlib import Path
from typing import Any

import numpy as np
import typer

from .._json import dumps
from ._files import echo_fields, kind_of, label, load, measure_record, RUN_SETTINGS
from ._options import Values


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
                 friction=chain.friction, actuator=chain.actuator, check=check)  # fmt: skip


def amplitude(file: Path, mech: Any, wave: Any) -> float:
    """The default `--a-max` of `optimize FILE`: the amplitude of the file's sinusoid or travelling wave."""
    from ..model._waveform import Sinusoid

    if kind_of(mech) == "chain":
        tw = travelling_wave(file)
        if tw is not None:
            return abs(tw["a"])
    elif wave is None:
        return float(mech.a)
    elif isinstance(wave, Sinusoid):
        return abs(float(wave.a))
    raise ValueError(f"--a-max: {file}'s waveform has no single amplitude to default to; give --a-max.")


def simulate_file(file: Path, run: Values, t_end: float, plot_dir: Path | None, as_json: bool) -> None:
    """`simulate FILE`: the file's measurement (as `measure FILE`) and, with `plot_dir`, a plot vs time."""
    import locomotion_jax as lj

    mech, wave = load(file, mechanism_ok=True)
    kind = kind_of(mech)
    fields = measure_record(mech, wave, run)
    png = None
    if plot_dir is not None:
        extra = {} if wave is None else {"waveform": wave}
        how: dict[str, Any] = dict(dynamics=lj.Exact(dt=run["dt"]), contact=run["contact"], start=run["start"], **extra)
        png = plot_dir / f"simulate_{file.stem}.png"
        if kind in ("chain", "mechanism"):  # a ChainTrajectory, one row per body
            from ._chain_commands import _plot as plot_chain

            plot_chain(lj.simulate(mech, t_end, np.linspace(0.0, t_end, 401), **how), png, label(file, mech, wave))
        else:
            from ._main import _plot

            _plot(lj.simulate(mech, t_end, np.linspace(0.0, t_end, 2001), **how), png, label(file, mech, wave))
    settings = {n: run[n] for n in RUN_SETTINGS}
    if as_json:
        typer.echo(dumps({**fields, "mechanism": str(file), "kind": kind, **settings,
                          "plot": None if png is None else str(png)}))  # fmt: skip
        return
    typer.echo(label(file, mech, wave))
    typer.echo("settings: " + ", ".join(f"{n}={v}" for n, v in settings.items()))
    echo_fields(fields)
    if png is not None:
        typer.echo(f"plot: {png}")


def sweep_axes(file: Path, parsed: dict[str, Any]) -> dict[str, Any]:
    """`sweep FILE`: the file's parameters as fixed values, with the options given (`parsed`) in their place."""
    mech, wave = load(file)
    if kind_of(mech) == "chain":
        raise ValueError(f"{file} is a chain: map it with `locomotion-jax chain-sweep {file} --phi ...`.")
    if wave is not None:
        raise ValueError(f"{file}: sweep maps the paper's sinusoid (eq. 13); its [waveform] table cannot be swept.")
    values: dict[str, Any] = {n: float(v) for n, v in mech.as_dict().items()}
    if "omega_over_wn1" in parsed:
        values.pop("omega")
    return {**parsed, **{n: v for n, v in values.items() if n not in parsed}}  # the options' order first


def chain_sweep_mechanism(file: Path, given: dict[str, str | None]) -> tuple[Any, dict[str, str]]:
    """`chain-sweep FILE`: the file's chain, and the wave's `a`, `omega`, `phi` (text of options)
    with the file's travelling wave's values where `given` has none."""
    mech, _ = load(file)
    if kind_of(mech) != "chain":
        raise ValueError(f"{file} is the paper's model: map it with `locomotion-jax sweep {file} --omega ...`.")
    tw = travelling_wave(file)
    missing = [n for n, text in given.items() if text is None]
    if missing and tw is None:
        options = ", ".join("--" + n for n in missing)
        raise ValueError(f"{options}: {file} has no [waveform] of type TravellingWave to take them from; give them.")
    return mech, {n: text if text is not None else repr(tw[n]) for n, text in given.items()}  # type: ignore[index]
