"""`locomotion-jax chain-optimize`: the chain optimiser from the command line (SPEC §7 and §8).

`register(app)` adds the subcommand; the mechanism options are those of `chain`
(`_chain_options`). Progress goes to stderr, so that `--json` prints exactly one JSON
object on stdout.
"""

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from ._chain_options import mechanism_options, to_chain
from ._errors import friendly
from ._options import expand, Values


def _plot(opt, path: Path) -> None:
    """The optimal signals $s_j(t)$ over one period beside the best travelling wave's."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    phase = np.linspace(0, 2 * np.pi, 401)
    n = np.arange(1, opt.cos.shape[1] + 1)
    s = opt.cos @ np.cos(np.outer(n, phase)) + opt.sin @ np.sin(np.outer(n, phase))
    for j, sj in enumerate(s):
        ax.plot(phase / (2 * np.pi), sj, label=f"spring {j}")
    w = opt.travelling_wave
    if w is not None:
        for j in range(s.shape[0]):
            ax.plot(phase / (2 * np.pi), w["a"] * np.sin(phase - j * w["phi"]), color=f"C{j}", ls=":", lw=1)
    ax.axhline(opt.a_max, color="grey", lw=0.8)
    ax.axhline(-opt.a_max, color="grey", lw=0.8)
    ax.set_xlabel("t / T (one actuation period)")
    ax.set_ylabel("l0_j - lbar_j")
    ax.legend(loc="upper right", fontsize="small")
    ax.set_title(f"cost of transport {opt.cost_of_transport_exact:.4g} at speed {opt.mean_speed_exact:.4g} "
                 f"(dotted: best travelling wave)")  # fmt: skip
    fig.savefig(path, dpi=120)


def optimise_chain(chain, v_min: float, a_max: float, direction: int, omega: float | None, harmonics: int,
                   settings, out: Path | None, as_json: bool) -> None:  # fmt: skip
    """Optimise `chain` and print the result (`chain-optimize`, `optimize FILE`); with `out`, save it and a plot."""
    import locomotion_jax as lj

    if out is not None:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ValueError(f"--out {out}: cannot create the directory ({err.strerror or err}).") from None
    opt = lj.optimise(chain, v_min, a_max, direction=direction, omega=omega, harmonics=harmonics, settings=settings)
    if out is not None:
        (out / "chain_optimum.json").write_text(opt.to_json(full=True, indent=1))
        _plot(opt, out / "chain_optimum.png")
        if not as_json:
            typer.echo(f"wrote {out / 'chain_optimum.json'}, {out / 'chain_optimum.png'}", err=True)
    typer.echo(opt.to_json() if as_json else opt.summary())


def register(app: typer.Typer) -> None:
    """Add the `chain-optimize` subcommand to `app`."""

    @app.command("chain-optimize")
    @friendly
    @expand(mech=mechanism_options())
    def chain_optimize(
        *,
        mech: Values,
        v_min: Annotated[float, typer.Option("--v-min", help="Required mean speed (> 0) in --direction.")],
        a_max: Annotated[float, typer.Option("--a-max", help="Stroke bound per spring: max |l0_j - lbar_j|.")],
        direction: Annotated[int, typer.Option(help="+1 forward or -1 backward.")] = 1,
        omega: Annotated[float | None, typer.Option(help="Fix the base frequency (default: optimised).")] = None,
        harmonics: Annotated[int, typer.Option(help="Fourier harmonics per spring.")] = 3,
        amplitudes: Annotated[int, typer.Option(help="Travelling-wave screen: amplitudes up to a_max.")] = 3,
        frequencies: Annotated[int, typer.Option(help="Travelling-wave screen: log-spaced frequencies.")] = 12,
        phases: Annotated[int, typer.Option(help="Travelling-wave screen: phase lags over [-pi, pi).")] = 8,
        zoom_levels: Annotated[int, typer.Option(help="Zoom levels around the best travelling wave.")] = 2,
        zoom_points: Annotated[int, typer.Option(help="Zoom: points per variable and level.")] = 5,
        local: Annotated[int, typer.Option(help="Starts refined locally, in lockstep.")] = 4,
        max_iter: Annotated[int, typer.Option(help="Iterations of each local descent.")] = 60,
        margin: Annotated[float, typer.Option(help="Normal-force margin on the orbit (units of weight).")] = 0.05,
        transient: Annotated[int, typer.Option(help="Actuation periods before each orbit is solved.")] = 30,
        dt: Annotated[float, typer.Option(help="Step of the exact engine.")] = 0.01,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the report.")] = False,
        out: Annotated[Path | None, typer.Option(help="Directory for chain_optimum.json and a plot.")] = None,
        verbose: Annotated[bool, typer.Option(help="Progress on stderr.")] = False,
    ) -> None:
        """Optimise a chain's per-spring actuation for least cost of transport at a required speed.

        The best travelling wave of a screen is refined to per-spring harmonics; the optimum is
        verified on its steady gait and a direct simulation.

        With --json, stdout is one JSON object (non-finite numbers are null): `feasible_exact`,
        `mean_speed_exact`, `cost_of_transport_exact`, `travelling_wave`, `improvement_vs_travelling_wave`,
        the coefficients `cos`, `sin` (springs x harmonics), `omega`, and the checks. An infeasible
        requirement is reported with `feasible_exact: false`.
        """
        import locomotion_jax as lj

        chain = to_chain(mech)
        settings = lj.ChainOptimiseSettings(
            amplitudes=amplitudes, frequencies=frequencies, phases=phases, zoom_levels=zoom_levels,
            zoom_points=zoom_points, local=local, max_iter=max_iter, margin=margin, transient=transient, dt=dt,
            verbose=verbose,
        )  # fmt: skip
        optimise_chain(chain, v_min, a_max, direction, omega, harmonics, settings, out, as_json)
