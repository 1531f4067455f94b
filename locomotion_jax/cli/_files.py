"""`locomotion-jax measure FILE`, and what every command that takes a mechanism file shares.

`register(app)` adds the `measure` subcommand to the main CLI (`_main.py`). The file is the paper's
model or a chain (docs/mechanisms.md, "Mechanism files"); the run settings are the options of
`simulate`. `simulate`, `gait`, `optimize`, `sweep`, `chain-sweep` and `animate` take the same FILE
argument (`_file_commands.py`). A file that cannot be read, or that the schema check refuses, ends
with one line `Error: FILE, line N: ...` and exit code 2.
"""

from collections.abc import Iterable
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


def load(path: Path, mechanism_ok: bool = False) -> tuple[Any, Any]:
    """The file's mechanism and the paper's model's waveform (or `None`); a file that cannot be read
    is a `ValueError` naming it, and so is a `kind = "mechanism"` file unless `mechanism_ok` (the
    commands that run one: `measure`, `simulate`, `gait`)."""
    from ..model._files import load_mechanism

    try:
        mech, wave = load_mechanism(path, with_waveform=True)
    except OSError as err:
        raise ValueError(f"{path}: cannot read the mechanism file ({err.strerror or err}).") from None
    if not mechanism_ok and kind_of(mech) == "mechanism":
        raise ValueError(
            f'{path}: a mechanism of bodies and links (kind = "mechanism") runs in `measure`, `simulate` and '
            "`gait`; this command takes the paper's model or a chain."
        )
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


def kind_of(mech: Any) -> str:
    """`"chain"`, `"mechanism"` or `"paper"`, as the file's `kind`."""
    from ..model._bodies import Mechanism
    from ..model._chain import Chain

    return "chain" if isinstance(mech, Chain) else "mechanism" if isinstance(mech, Mechanism) else "paper"


def measure_record(mech: Any, wave: Any, run: Values, t_start: float | None = None) -> dict[str, Any]:
    """The measurement of a loaded mechanism with the run settings `run`, as JSON-ready fields."""
    import locomotion_jax as lj

    extra = {} if wave is None else {"waveform": wave}
    m = lj.measure(mech, run["z"], horizon=run["horizon"], window=run["window"], t_start=t_start,
                   contact=run["contact"], start=run["start"], dynamics=lj.Exact(dt=run["dt"]),
                   **extra)  # fmt: skip
    fields = {name: _plain(v) for name, v in m.to_numpy().items()}
    fields["regime_name"] = lj.Regime(int(m.regime)).name
    fields["status_name"] = lj.Status(int(m.status)).name
    return fields


def echo_fields(fields: dict[str, Any]) -> None:
    """One line per field: numbers to 6 digits, lists to 4."""
    for name, v in fields.items():
        if isinstance(v, list):
            v = "[" + ", ".join(f"{x:.4g}" if isinstance(x, float) else str(x) for x in v) + "]"
        typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")


def label(file: Path, mech: Any, wave: Any) -> str:
    """`worm.toml: chain of 4 masses, ...`: the first line of a command's report on a file."""
    from ..model._files import describe

    return f"{file}: {describe(mech)}" + ("" if wave is None else f", {type(wave).__name__} waveform")


RUN_SETTINGS: tuple[str, ...] = ("z", "horizon", "window", "contact", "start", "dt")


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
        mech, wave = load(file, mechanism_ok=True)
        settings = {n: run[n] for n in RUN_SETTINGS}
        fields = measure_record(mech, wave, run, t_start)
        if as_json:
            typer.echo(dumps({**fields, "mechanism": str(file), "kind": kind_of(mech), **settings, "t_start": t_start}))
            return
        typer.echo(label(file, mech, wave))
        typer.echo("settings: " + ", ".join(f"{n}={v}" for n, v in settings.items()))
        echo_fields(fields)
