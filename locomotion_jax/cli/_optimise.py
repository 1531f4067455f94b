"""`locomotion-jax optimize`: the actuation optimiser from the command line (SPEC §7).

`register(app)` adds the subcommand to a `typer.Typer` app (the main CLI in
`_main.py` calls it; the global `--x64` flag is handled there, before any JAX
array exists). Progress goes to stderr, so that `--json` prints exactly one
JSON object on stdout.
"""

import sys
from pathlib import Path
from typing import Any

import typer

from ._errors import friendly
from ._options import expand, model_options, to_params, Values


def _eps_schedule(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        values = ()
    if not values or any(not (v > 0) for v in values):
        raise typer.BadParameter(f"--eps must be a comma-separated list of positive numbers, got {text!r}.")
    return values


def register(app: typer.Typer) -> None:
    """Add the `optimize` subcommand to `app`."""

    @app.command("optimize")
    @friendly
    @expand(model=model_options(("k", "c", "d", "lbar", "mu_s", "mu_k", "mhat")))  # no a, omega: the waveform's
    def optimize(
        file: Path | None = typer.Argument(
            None, help="A mechanism file (TOML), instead of the model options: the paper's model or a chain."
        ),
        *,
        v_min: float = typer.Option(..., "--v-min", help="Required mean speed (> 0) in --direction."),
        a_max: float | None = typer.Option(
            None, "--a-max", help="Stroke bound: max |l0(t) - lbar| <= a_max (default with a FILE: its amplitude)."
        ),
        direction: int | None = typer.Option(None, "--direction", help="+1 forward (default) or -1 backward."),
        omega: float | None = typer.Option(None, "--omega", help="Fix the base frequency (default: optimised)."),
        method: str = typer.Option(
            "exact", "--method", help="'exact' (steady gaits of the exact model) or 'smoothed' (the older method)."
        ),
        harmonics: int | None = typer.Option(
            None,
            "--harmonics",
            help="Number of Fourier harmonics N (smoothed: default 3; exact with --shape fourier: default 16).",
        ),
        shape: str = typer.Option(
            "spline", "--shape", help="Exact: 'spline' (periodic cubic B-spline stroke) or 'fourier'."
        ),
        knots: int = typer.Option(64, "--knots", help="Exact, spline: number of control values."),
        model: Values,
        margin: float = typer.Option(0.05, "--margin", help="Normal-force margin (on the orbit, or smoothed)."),
        local: int = typer.Option(4, "--local", help="Exact: starts refined locally, in lockstep."),
        max_iter: int = typer.Option(150, "--max-iter", help="Exact: iterations of each local trust-region run."),
        starts: int = typer.Option(8, "--starts", help="Smoothed: starts optimised in parallel."),
        outer: int = typer.Option(3, "--outer", help="Smoothed: augmented-Lagrangian blocks per smoothing stage."),
        inner: int = typer.Option(30, "--inner", help="Smoothed: Adam steps per block."),
        eps: str = typer.Option("1e-2,3e-3,1e-3", "--eps", help="Smoothed: continuation in the smoothing scale."),
        transient: float = typer.Option(12.0, "--transient", help="Smoothed rollout: transient (time units)."),
        measured: float = typer.Option(6.0, "--measured", help="Smoothed rollout: measured time (time units)."),
        corrections: int = typer.Option(1, "--corrections", help="Smoothed: exact-feedback correction rounds."),
        sweep_omegas: int = typer.Option(32, "--sweep-omegas", help="Frequencies in the sinusoid sweep."),
        sweep_amplitudes: int = typer.Option(6, "--sweep-amplitudes", help="Amplitudes in the sinusoid sweep."),
        seed: int = typer.Option(0, "--seed"),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object instead of the report."),
        out: Path | None = typer.Option(None, "--out", help="Directory for the plots."),
        verbose: bool = typer.Option(False, "--verbose", help="Progress per block (stderr)."),
    ) -> None:
        """Optimise the actuation waveform for least cost of transport at a required speed,
        verify it on the exact model and compare it with the best sinusoid.

        With a mechanism FILE the mechanism is the file's, and --a-max defaults to the amplitude of its
        sinusoid or travelling wave (the waveform itself is what is optimised). A chain's file is
        optimised as by `chain-optimize` (exact method; --harmonics default 3; --local, --max-iter,
        --margin, --omega, --direction, --out, --json and --verbose apply); a `kind = "mechanism"` file's
        actuated elements as by `lj.optimise` of a Mechanism (--a-max required; --harmonics default 2;
        --local, --max-iter, --margin, --omega, --direction, --json and --verbose apply)."""
        from ..optimisation import _optimise, _pareto
        from ..optimisation._optimum import ExactSettings, Settings

        try:
            if method not in ("exact", "smoothed"):
                raise ValueError(f"--method must be 'exact' or 'smoothed', got {method!r}.")
            if file is None:
                if a_max is None:
                    raise ValueError("--a-max is required (without a mechanism file, whose amplitude it defaults to).")
                params = to_params(model)
            else:
                from ._file_commands import amplitude
                from ._files import given, kind_of, load, refuse_options

                refuse_options(file, model)
                mech, wave = load(file, mechanism_ok=True)
                if kind_of(mech) == "mechanism":
                    steps = max_iter if given(["max_iter"]) else None  # the optimiser's own default otherwise
                    return _optimise_mechanism(file, mech, v_min, a_max, direction, omega, harmonics, method, local,
                                               margin, steps, verbose, json_out)  # fmt: skip
                a_max = amplitude(file, mech, wave) if a_max is None else a_max
                if kind_of(mech) == "chain":
                    import locomotion_jax as lj

                    from ._chain_optimise import optimise_chain

                    if method != "exact":
                        raise ValueError("--method: a chain is optimised by the exact method only.")
                    chain_settings = lj.ChainOptimiseSettings(local=local, margin=margin, verbose=verbose)
                    if given(["max_iter"]):  # the chain's own default otherwise
                        chain_settings = lj.ChainOptimiseSettings(
                            local=local, margin=margin, verbose=verbose, max_iter=max_iter
                        )
                    sign, n_harm = 1 if direction is None else direction, 3 if harmonics is None else harmonics
                    return optimise_chain(mech, v_min, a_max, sign, omega, n_harm, chain_settings, out, json_out)
                params = mech
            settings: ExactSettings | Settings
            if method == "exact":
                settings = ExactSettings(
                    shape=shape, knots=knots, local=local, max_iter=max_iter, margin=margin, seed=seed, verbose=verbose
                )
            else:
                settings = Settings(
                    starts=starts,
                    outer=outer,
                    inner=inner,
                    eps_schedule=_eps_schedule(eps),
                    margin=margin,
                    seed=seed,
                    verbose=verbose,
                    transient=transient,
                    measured=measured,
                    corrections=corrections,
                )
            n_harm = harmonics if harmonics is not None else (16 if method == "exact" else 3)
            # Validate before the (long) sinusoid sweep.
            from ..optimisation._constraints import check_inputs

            check_inputs(params, v_min, a_max, direction, n_harm, omega, margin)
            log = (lambda msg: print(msg, file=sys.stderr, flush=True)) if verbose or not json_out else (lambda m: None)
            log(f"sweeping {sweep_amplitudes} x {sweep_omegas} sinusoids on the exact model ...")
            sweep = _pareto.sinusoid_sweep(
                params,
                a_max,
                omegas=_pareto.default_omegas(params, sweep_omegas),
                amplitudes=sweep_amplitudes,
            )
            log("optimising ...")
            result = _optimise.optimise(
                params,
                v_min,
                a_max,
                method=method,
                direction=direction,
                omega=omega,
                harmonics=harmonics,
                settings=settings,
                sweep=sweep,
            )
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(code=2) from None
        if out is not None:
            from ..optimisation._plots import save_all

            paths = save_all(result, params, sweep, Path(out))
            if not json_out:
                typer.echo("plots: " + ", ".join(str(p) for p in paths), err=True)
        if json_out:
            typer.echo(result.to_json())
        else:
            typer.echo(result.summary())


def _optimise_mechanism(file: Path, mech: Any, v_min: float, a_max: float | None, direction: int | None,
                        omega: float | None, harmonics: int | None, method: str, local: int, margin: float,
                        max_iter: int | None, verbose: bool, json_out: bool) -> None:  # fmt: skip
    """`optimize FILE` for a `kind = "mechanism"` file: `lj.optimise` of the file's mechanism, printed."""
    import locomotion_jax as lj

    from .._json import dumps

    if method != "exact":
        raise ValueError("--method: a mechanism is optimised by the exact method only.")
    if a_max is None:
        raise ValueError(f"--a-max is required for {file} (a mechanism of bodies and links): the bound on every "
                         "actuated signal's excursion about its mean.")  # fmt: skip
    settings = lj.ChainOptimiseSettings(local=local, margin=margin, verbose=verbose)
    if max_iter is not None:
        settings = lj.ChainOptimiseSettings(local=local, margin=margin, verbose=verbose, max_iter=max_iter)
    opt = lj.optimise(mech, v_min, a_max, direction=1 if direction is None else direction, omega=omega,
                      harmonics=2 if harmonics is None else harmonics, settings=settings)  # fmt: skip
    record = {**opt.to_dict(), "mechanism": str(file), "kind": "mechanism"}
    if json_out:
        typer.echo(dumps(record))
        return
    typer.echo(f"{file}: optimal actuation of links {opt.elements} ({opt.harmonics} harmonics)")
    for name in ("omega", "mean_speed_exact", "cost_of_transport_exact", "feasible_exact", "stable_exact",
                 "sinusoid", "improvement_vs_sinusoid", "mean_speed_simulated", "cost_of_transport_simulated",
                 "cos", "sin"):  # fmt: skip
        typer.echo(f"  {name:<28} {record[name]}")
