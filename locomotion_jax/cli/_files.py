"""`locomotion-jax measure FILE`: measure the mechanism that a TOML file describes ([`load_mechanism`][]).

`register(app)` adds the subcommand to the main CLI (`_main.py`). The file is the paper's model or a
chain (docs/mechanisms.md, "Mechanism files"); the run settings are the options of `simulate`. A file
that cannot be read, or that the schema check refuses, ends with one line `Error: FILE, line N: ...`
and exit code 2.
"""

from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from .._json import dumps
from ._errors import friendly
from ._options import expand, run_options, Values


def _plain(v: Any) -> Any:
    v = np.asarray(v)
    return v.tolist() if v.ndim else v.item()


def load(path: Path) -> tuple[Any, Any]:
    """The file's mechanism and the paper's model's waveform (or `None`); a file that cannot be read
    is a `ValueError` naming it."""
    from ..model._files import load_mechanism

    try:
        return load_mechanism(path, with_waveform=True)
    except OSError as err:
        raise ValueError(f"{path}: cannot read the mechanism file ({err.strerror or err}).") from None


def register(app: typer.Typer) -> None:
    """Add the `measure` subcommand to `app`."""

    @app.command("measure")
    @friendly
    @expand(run=run_options())
    def measure(
        file: Annotated[Path, typer.Argument(help="A mechanism file (TOML): examples/paper.toml, examples/worm.toml.")],
        *,
        run: Values,
        t_start: Annotated[
            float | None,
            typer.Option(help="Measurement start (default: 80 periods of the lowest natural frequency)."),
        ] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the measurements as one JSON object.")] = False,
    ) -> None:
        """Measure the mechanism of a file: time and energy to travel z, speed, regime, stick fractions.

        Example: `locomotion-jax measure examples/worm.toml --json`. With --json, stdout is one JSON
        object: every measurement field (per-mass fields of a chain as lists), `regime_name`,
        `status_name`, `mechanism` (the file), `kind` and the settings; non-finite numbers are null.
        """
        import locomotion_jax as lj

        from ..model._files import describe

        mech, wave = load(file)
        settings = {n: run[n] for n in ("z", "horizon", "window", "contact", "start", "dt")}
        extra = {} if wave is None else {"waveform": wave}
        m = lj.measure(mech, run["z"], horizon=run["horizon"], window=run["window"], t_start=t_start,
                       contact=run["contact"], start=run["start"], dynamics=lj.Exact(dt=run["dt"]),
                       **extra)  # fmt: skip
        fields = {name: _plain(v) for name, v in m.to_numpy().items()}
        fields["regime_name"] = lj.Regime(int(m.regime)).name
        fields["status_name"] = lj.Status(int(m.status)).name
        kind = "chain" if isinstance(mech, lj.Chain) else "paper"
        if as_json:
            typer.echo(dumps({**fields, "mechanism": str(file), "kind": kind, **settings, "t_start": t_start}))
            return
        label = describe(mech) + ("" if wave is None else f", {type(wave).__name__} waveform")
        typer.echo(f"{file}: {label}")
        typer.echo("settings: " + ", ".join(f"{n}={v}" for n, v in settings.items()))
        for name, v in fields.items():
            if isinstance(v, list):
                v = "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
            typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")
