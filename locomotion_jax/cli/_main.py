"""The `locomotion-jax` command line: the global options, `figures`, and the commands of [`PLUGINS`][].

Heavy imports (the package's numerics, matplotlib, xarray) happen inside the
commands, so `--help` is quick and `--x64` takes effect before any array exists.

Errors in the arguments end with `Error: ...` on stderr and exit code 2, never a traceback.
JSON output (`--json`) encodes every non-finite number as `null` (`_json.py`).
"""

import importlib
import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from ._errors import friendly as _friendly, os_error_message


FIGURES: tuple[str, ...] = ("4b", "5", "6", "7", "8", "9", "10", "12")
"""Figure names accepted by `figures` (the paper's numbering, SPEC §6)."""

app = typer.Typer(
    name="locomotion-jax",
    help="Friction-driven (stick-slip) locomotion: the paper's two-mass model (Zhou, Majidi, O'Reilly 2014), "
    "chains of N masses and mechanism files; measure, simulate, map, optimise, reproduce.",
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
    "locomotion_jax.cli._commands",
    "locomotion_jax.cli._gait",
    "locomotion_jax.cli._optimise",
    "locomotion_jax.cli._animate",
    "locomotion_jax.cli._aliases",
)
"""Modules that add subcommands (`measure`, `simulate`, `sweep`, `gait`, `continue`, `optimize`, `animate`,
and the hidden `chain-*` aliases) through `register(app)`; [`_register_optional`][] skips one whose module
is absent."""


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
