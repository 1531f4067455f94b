"""The `locomotion-jax` command line: simulate, sweep, figures, and the plug-in commands of [`PLUGINS`][].

Heavy imports (the package's numerics, matplotlib, xarray) happen inside the
commands, so `--help` is quick and `--x64` takes effect before any array exists.

Errors in the arguments end with `Error: ...` on stderr and exit code 2, never a traceback.
JSON output (`--json`) encodes every non-finite number as `null` (`_json.py`).
"""

import importlib
import math
import os
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import typer

from .._json import dumps
from ._errors import friendly as _friendly, os_error_message
from ._options import axis_options, expand, MODEL_NAMES, model_options, run_options, to_params, Values


FIGURES: tuple[str, ...] = ("4b", "5", "6", "7", "8", "9", "10", "12")
"""Figure names accepted by `figures` (the paper's numbering, SPEC §6)."""

app = typer.Typer(
    name="locomotion-jax",
    help="Two-mass stick-slip locomotion (Zhou, Majidi, O'Reilly 2014): simulate, map, reproduce.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))  # the cores this process may use (cgroups, taskset)
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@app.callback()
def _global(
    x64: Annotated[bool, typer.Option("--x64/--no-x64", help="Compute in float64 (default) or float32.")] = True,
    cpu_devices: Annotated[
        int,
        typer.Option(
            help="Host (CPU) devices for sweeps: 0 = one per core, 1 = a single device. XLA runs one "
            "computation on one core, so sweeps shard over these devices to use every core."
        ),
    ] = 0,
    cache: Annotated[
        bool,
        typer.Option(
            "--cache/--no-cache",
            envvar="LOCOMOTION_JAX_CACHE",
            help="Keep compiled code in a per-user cache directory ($LOCOMOTION_JAX_CACHE_DIR, default "
            "~/.cache/locomotion_jax/jax), so the next call does not compile again. Off: --no-cache or "
            "LOCOMOTION_JAX_CACHE=0.",
        ),
    ] = True,
    distributed: Annotated[
        bool,
        typer.Option(
            help="Join a multi-process run: jax.distributed.initialize() with its settings from the environment "
            "(Slurm's srun, Open MPI, Kubernetes; JAX_COORDINATOR_ADDRESS). A sweep into a .zarr store then "
            "shares out its chunks between the processes."
        ),
    ] = False,
) -> None:
    # XLA reads XLA_FLAGS when its backends start (the first computation), so
    # setting it here, before any command computes, is in time. A flag already
    # set by the user wins.
    flags = os.environ.get("XLA_FLAGS", "")
    if cpu_devices < 0:
        raise typer.BadParameter(f"must be >= 0, got {cpu_devices}.", param_hint="--cpu-devices")
    if cpu_devices != 1 and "xla_force_host_platform_device_count" not in flags:
        n = cpu_devices or _cpu_count()
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n}".strip()
    # The one place outside the tests that sets global JAX config (STYLE §4).
    import jax

    jax.config.update("jax_enable_x64", x64)
    if distributed:
        # A process that dies must not take the others with it: without this, JAX's coordination
        # client aborts the survivors (SIGABRT, exit 134) when it learns of the loss, though they
        # can finish a sweep's store by taking over the lost process's chunks.
        jax.config.update("jax_enable_recoverability", True)
        try:
            jax.distributed.initialize()
        except (ValueError, RuntimeError) as err:
            message = f"jax.distributed.initialize() failed: {err}"
            raise typer.BadParameter(message, param_hint="--distributed") from None
    if cache:
        from .._cache import enable_compilation_cache

        try:
            enable_compilation_cache()
        except ValueError as err:  # an unwritable cache costs time, not the result
            typer.echo(f"Warning: {err} Running without the compilation cache.", err=True)


def _plot(traj, path: Path, title: str) -> None:
    from matplotlib.figure import Figure  # no pyplot: no global backend state

    fig = Figure(figsize=(8, 7), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    ok = np.asarray(traj.valid)
    t = np.asarray(traj.t)[ok]
    for name in ("x1", "x2"):
        ax[0].plot(t, np.asarray(getattr(traj, name))[ok], label=name)
    for name in ("v1", "v2"):
        ax[1].plot(t, np.asarray(getattr(traj, name))[ok], label=name)
    ax[2].step(t, np.asarray(traj.mode)[ok], where="post")
    ax[2].set_yticks([0, 1, 2, 3], ["both stick", "both slip", "m1 slips", "m2 slips"])
    ax[0].set_ylabel("position")
    ax[1].set_ylabel("velocity")
    ax[2].set_ylabel("mode")
    ax[2].set_xlabel("t (dimensionless)")
    for a in ax[:2]:
        a.legend(loc="upper left")
    t_lift = float(np.asarray(traj.t_liftoff))
    if math.isfinite(t_lift):
        for a in ax:
            a.axvline(t_lift, color="red", ls="--", lw=1)
        title += f"  [lift-off at t = {t_lift:.4g}]"
    fig.suptitle(title)
    fig.savefig(path, dpi=120)


@app.command()
@_friendly
@expand(model=model_options(), run=run_options())
def simulate(
    file: Annotated[
        Path | None,
        typer.Argument(help="A mechanism file (TOML), instead of the model options: examples/worm.toml."),
    ] = None,
    *,
    model: Values,
    t_end: Annotated[float, typer.Option(help="End time of the plotted trajectory.")] = 20.0,
    run: Values,
    out: Annotated[Path | None, typer.Option(help="Directory for the PNG plot; without it nothing is written.")] = None,
    plot: Annotated[bool, typer.Option(help="With --out, save the plot of x1, x2, v1, v2 and the mode.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the measurements as one JSON object.")] = False,
) -> None:
    """Simulate one configuration: print its measurements; with --out, plot x1, x2, v1, v2, mode vs time.

    With --json, stdout is one JSON object: every Measurement field, `regime_name`,
    `status_name`, the parameters and settings, and `plot` (the PNG path or null).
    Non-finite numbers are null: NaN (not computable) and inf (tau_z and e_z when z is
    not reached, t_liftoff without lift-off; `reached` and `liftoff` say which).

    With a mechanism FILE (a chain or the paper's model), the measurements are those of
    `measure FILE`, and `--json` names the `mechanism` and its `kind` instead of `params`.
    """
    from .. import Exact, measure, PARAM_NAMES, Regime, simulate as simulate_fn, Status

    plot_dir = out if plot else None
    if not (math.isfinite(t_end) and t_end > 0):  # checked whether or not --out asks for the plot
        raise ValueError(f"--t-end must be a finite number > 0, got {t_end!r}.")
    if file is None:
        to_params(model)  # checked before the directory is made
    else:
        from ._files import refuse_options

        refuse_options(file, model)
    if plot_dir is not None:
        try:
            plot_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ValueError(f"--out {out}: cannot create the directory ({err.strerror or err}).") from None
    if file is not None:
        from ._file_commands import simulate_file

        return simulate_file(file, run, t_end, plot_dir, as_json)
    params = to_params(model)
    values = {n: model[n] for n in PARAM_NAMES}  # as given, but omega as computed from --omega-over-wn1
    if model["omega_over_wn1"] is not None:
        values["omega"] = float(params.omega)
    omega, a, d, mhat = values["omega"], values["a"], values["d"], values["mhat"]
    exact: dict[str, Any] = dict(dynamics=Exact(dt=run["dt"]), contact=run["contact"], start=run["start"])
    png = None
    m = measure(params, run["z"], horizon=run["horizon"], window=run["window"], **exact)
    if plot_dir is not None:
        traj = simulate_fn(params, t_end, np.linspace(0.0, t_end, 2001), **exact)
        png = plot_dir / f"simulate_omega{omega:.4g}_a{a:.4g}_d{d:.4g}.png"
        _plot(traj, png, f"omega = {omega:.4g}, a = {a:.4g}, d = {d:.4g}, mhat = {mhat:.4g}")
    fields = {name: np.asarray(v).item() for name, v in m.to_numpy().items()}
    fields["regime_name"] = Regime(int(m.regime)).name
    fields["status_name"] = Status(int(m.status)).name
    settings = {n: run[n] for n in ("z", "horizon", "window", "contact", "start", "dt")}  # in the order printed
    if as_json:
        record = {**fields, "params": values, **settings, "plot": None if png is None else str(png)}
        typer.echo(dumps(record))
        return
    typer.echo("parameters: " + ", ".join(f"{n}={v:g}" for n, v in values.items()))
    typer.echo("settings:   " + ", ".join(f"{n}={v}" for n, v in settings.items()))
    for name, v in fields.items():
        typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")
    if png is not None:
        typer.echo(f"plot: {png}")


# -- sweep ----------------------------------------------------------------------------

SWEEP_NAMES: tuple[str, ...] = MODEL_NAMES
"""Sweep options, in the order their axes become dimensions of the dataset."""


def parse_axis(name: str, text: str) -> float | np.ndarray:
    """Read `--NAME` of `sweep`: `start:stop:count` (linspace), `v1,v2,...`, or one fixed value.

    **Raises:** `ValueError` naming the option for unreadable text or an empty range.
    """
    opt = "--" + name.replace("_", "-")
    form = "expected a value, 'start:stop:count' or 'v1,v2,...'"
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            lo, hi, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError(f"{opt} {text!r}: empty range (count must be >= 1).")
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ValueError(f"{opt} {text!r}: the ends of a range must be finite.")
            return np.linspace(lo, hi, count)
        if "," in text:
            return np.asarray([float(v) for v in text.split(",") if v.strip()], dtype=float)
        return float(text)
    except ValueError as err:
        raise ValueError(str(err) if str(err).startswith(opt) else f"{opt}: cannot read {text!r}; {form}.") from None


@app.command()
@_friendly
@expand(given=axis_options(SWEEP_NAMES), run=run_options())
def sweep(
    file: Annotated[
        Path | None,
        typer.Argument(help="A mechanism file of the paper's model (TOML): its values are the fixed ones."),
    ] = None,
    *,
    out: Annotated[
        Path,
        typer.Option(
            help="Output: a NetCDF file (.nc), or a Zarr store (.zarr) that several processes can fill at once "
            "(jax.distributed). Resumable: rerun with the same path."
        ),
    ],
    given: Values,
    mode: Annotated[
        Literal["grid", "list"], typer.Option(help="'grid' (outer product) or 'list' (zip axes of equal length).")
    ] = "grid",
    chunk_size: Annotated[int, typer.Option(help="Configurations per compiled chunk.")] = 4096,
    run: Values,
    overwrite: Annotated[bool, typer.Option(help="Discard what is stored at --out and recompute.")] = False,
    on_invalid: Annotated[
        Literal["raise", "flag"],
        typer.Option(help="'raise': reject invalid configurations; 'flag': record them as Status.INVALID."),
    ] = "raise",
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    order: Annotated[
        Literal["auto", "natural", "cost"],
        typer.Option(
            help="Chunk order: 'natural' (grid order), 'cost' (sorted by a short pilot run's expected cost, so "
            "slow configurations share chunks) or 'auto' (cost for large exact sweeps). Same results."
        ),
    ] = "auto",
) -> None:
    """Map the measurements over a grid of parameters and write an xarray/NetCDF file or Zarr store.

    Example: `locomotion-jax sweep --omega 1:25:256 --a 0.01:0.1:256 --out maps/ssl.nc`.
    Dimensions follow the order omega, omega_over_wn1, a, d, mhat, mu_s, mu_k, k, c, lbar.
    An interrupted sweep resumes from its finished chunks when rerun with the same
    arguments; a finished one is read back. With a mechanism FILE (the paper's model), the
    parameters not given as options take the file's values (a chain's file: `chain-sweep FILE`).
    """
    from .. import Exact
    from ..maps._sweep import sweep as sweep_fn

    parsed = {n: parse_axis(n, text) for n, text in given.items() if text is not None}  # in SWEEP_NAMES order
    if file is not None:
        from ._file_commands import sweep_axes

        parsed = sweep_axes(file, parsed)
    axes = {n: v for n, v in parsed.items() if isinstance(v, np.ndarray)}
    fixed = {n: v for n, v in parsed.items() if not isinstance(v, np.ndarray)}
    if not axes:
        raise ValueError("nothing to sweep: give at least one range, e.g. --omega 1:25:256.")
    measurement = {n: run[n] for n in ("z", "horizon", "window", "contact", "start")}
    ds = sweep_fn(
        axes,
        fixed=fixed,
        mode=mode,
        **measurement,
        dynamics=Exact(dt=run["dt"]),
        chunk_size=chunk_size,
        path=out,
        overwrite=overwrite,
        progress=progress,
        on_invalid=on_invalid,
        order=order,
    )
    from .._status import Regime, Status

    typer.echo(f"wrote {out}: " + " x ".join(f"{n}[{s}]" for n, s in ds.sizes.items()))
    status = np.asarray(ds.status).ravel()
    regime = np.asarray(ds.regime).ravel()
    typer.echo("status: " + ", ".join(f"{s.name} {int((status == s).sum())}" for s in Status if (status == s).any()))
    typer.echo("regime: " + ", ".join(f"{r.name} {int((regime == r).sum())}" for r in Regime if (regime == r).any()))


# -- figures ----------------------------------------------------------------------------


def figure_names(figs: list[str] | None) -> list[str]:
    """Normalise figure names ('fig6', '6', 'all'); `ValueError` for unknown ones."""
    if not figs or [f.lower() for f in figs] == ["all"]:
        return list(FIGURES)
    names = []
    for f in figs:
        name = f.lower().strip()
        for prefix in ("figure", "fig"):
            name = name.removeprefix(prefix)
        name = name.lstrip("0") or name  # "fig08" -> "8", "04b" -> "4b"
        if name not in FIGURES:
            raise ValueError(f"unknown figure {f!r}; valid figures are {', '.join(FIGURES)} (or 'all').")
        names.append(name)
    return names


@app.command()
@_friendly
def figures(
    figs: Annotated[
        list[str] | None, typer.Argument(help=f"Figures to make ({', '.join(FIGURES)}); default all.")
    ] = None,
    quick: Annotated[bool, typer.Option(help="Small grids and short horizons (CI size).")] = False,
    out: Annotated[Path, typer.Option(help="Output directory for data, PNGs and the report.")] = Path(
        "experiments/output"
    ),
) -> None:
    """Reproduce the paper's figures (SPEC §6): data, PNGs and the reproduction report."""
    names = figure_names(figs)
    from ..paper._figures import run_figures

    for path in run_figures(names, quick, out):
        typer.echo(str(path))


PLUGINS: tuple[str, ...] = (
    "locomotion_jax.cli._optimise",
    "locomotion_jax.cli._animate",
    "locomotion_jax.cli._chain",
    "locomotion_jax.cli._gait",
    "locomotion_jax.cli._chain_commands",
    "locomotion_jax.cli._chain_optimise",
    "locomotion_jax.cli._files",
)
"""Modules that add subcommands (`optimize`, `animate`, `chain`, `gait`, `continue`, `chain-simulate`, `chain-gait`,
`chain-sweep`, `chain-optimize`, `measure`) through `register(app)`;
[`_register_optional`][] skips one whose module is absent."""


def _register_optional(app: typer.Typer, modules: tuple[str, ...] = PLUGINS) -> None:
    """Call `register(app)` of each module of `modules` that exists.

    Only the absence of the module itself is tolerated; an import error inside it is a bug and is raised.
    """
    for name in modules:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name:
                raise
            continue
        module.register(app)


_register_optional(app)


def main(argv: list[str] | None = None) -> None:
    """Entry point of `locomotion-jax` (pyproject `[project.scripts]`)."""
    try:
        app(args=argv, prog_name="locomotion-jax")
    except ValueError as err:  # e.g. raised by a plug-in command without `_friendly`
        typer.echo(f"Error: {err}", err=True)
        sys.exit(2)
    except OSError as err:
        typer.echo(f"Error: {os_error_message(err, {})}", err=True)
        sys.exit(2)


if __name__ == "__main__":
    main()
