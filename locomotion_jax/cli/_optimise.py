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
from ._mechanism import build, Built, mechanism_options, NAMES
from ._options import expand, Values


OPTIMISED: tuple[str, ...] = tuple(n for n in NAMES if n not in ("a", "omega", "omega_over_wn1", "phi"))
"""The mechanism options of `optimize`: not the actuation's, which is what is optimised."""


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
    @expand(mech=mechanism_options(OPTIMISED))
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
            "spline",
            "--shape",
            help="Exact: 'spline' (periodic cubic B-spline stroke) or 'fourier' (a chain or mechanism: "
            "default 'fourier').",
        ),
        knots: int = typer.Option(
            64, "--knots", help="Exact, spline: number of control values (a chain or mechanism: default 16)."
        ),
        mech: Values,
        amplitudes: int = typer.Option(3, help="A chain or mechanism: travelling-wave screen, amplitudes."),
        frequencies: int = typer.Option(12, help="A chain or mechanism: screen, log-spaced frequencies."),
        phases: int = typer.Option(8, help="A chain or mechanism: screen, phase lags over [-pi, pi)."),
        zoom_levels: int = typer.Option(2, help="A chain or mechanism: zoom levels around the screen's best."),
        zoom_points: int = typer.Option(5, help="A chain or mechanism: zoom points per variable and level."),
        screen_speed: float = typer.Option(
            0.5, help="A chain: solve the gaits of the waves whose transient reaches this fraction of v_min."
        ),
        margin: float = typer.Option(0.05, "--margin", help="Normal-force margin (on the orbit, or smoothed)."),
        local: int = typer.Option(4, "--local", help="Exact: starts refined locally, in lockstep."),
        max_iter: int = typer.Option(150, "--max-iter", help="Exact: iterations of each local descent."),
        local_method: str = typer.Option(
            "descent",
            "--local-method",
            help="Exact: the local step, 'descent' (L-BFGS on the exact penalty) or 'sqp' (SQP steps on the "
            "linearised constraints, stopped where the cost stalls: fewer evaluations, an optimum a little "
            "costlier).",
        ),
        dt: float | None = typer.Option(
            None, "--dt", help="Exact: the engine's step of the verification and every figure reported (default 0.01)."
        ),
        search_dt: float | None = typer.Option(
            None,
            "--search-dt",
            help="Exact: a coarser step for the search (the screen and the local runs; default: --dt), a faster first "
            "look; the figures reported stay at --dt.",
        ),
        tension_periods: int | None = typer.Option(
            None,
            "--tension-periods",
            help="Exact: periods of the idealised-inchworm starts (each spring's or actuated element's tension a "
            "square wave alternating in sign; default 10 for a spline search, none for a Fourier series; 0: none).",
        ),
        starts: int = typer.Option(8, "--starts", help="Smoothed: starts optimised in parallel."),
        outer: int = typer.Option(3, "--outer", help="Smoothed: augmented-Lagrangian blocks per smoothing stage."),
        inner: int = typer.Option(30, "--inner", help="Smoothed: Adam steps per block."),
        eps: str = typer.Option("1e-2,3e-3,1e-3", "--eps", help="Smoothed: continuation in the smoothing scale."),
        transient: float | None = typer.Option(
            None,
            "--transient",
            help="Smoothed rollout: transient (time units, default 12); a chain or mechanism: "
            "actuation periods before each orbit is solved (default 30).",
        ),
        measured: float = typer.Option(6.0, "--measured", help="Smoothed rollout: measured time (time units)."),
        corrections: int = typer.Option(1, "--corrections", help="Smoothed: exact-feedback correction rounds."),
        sweep_omegas: int = typer.Option(32, "--sweep-omegas", help="Frequencies in the sinusoid sweep."),
        sweep_amplitudes: int = typer.Option(6, "--sweep-amplitudes", help="Amplitudes in the sinusoid sweep."),
        seed: int = typer.Option(0, "--seed"),
        start: Path | None = typer.Option(
            None,
            "--start",
            help="Exact: continuation from an earlier result of the same kind of mechanism, the JSON that "
            "optimize --json printed (or --out's optimum.json): refined too, and a candidate itself.",
        ),
        reuse_screen: Path | None = typer.Option(
            None,
            "--reuse-screen",
            help="The screen kept in an earlier --out's optimum.json (the paper's model: its sinusoid sweep; "
            "the same mechanism, --a-max and screen options), taken as this run's instead of solving it "
            "again: the optimum at another --v-min without a new screen.",
        ),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object instead of the report."),
        out: Path | None = typer.Option(
            None, "--out", help="Directory for optimum.json and the plots (signals, one period, Pareto front)."
        ),
        verbose: bool = typer.Option(False, "--verbose", help="Progress per block (stderr)."),
    ) -> None:
        """Optimise the actuation for least cost of transport at a required speed, verify it on the
        exact model and compare it with the best sinusoid (or travelling wave).

        The mechanism is the paper's model (its options; --a-max required), a chain (`--masses` and
        the chain options, without the wave's, which is what is optimised; --a-max required) or a
        mechanism FILE (--a-max defaults to the amplitude of its sinusoid or travelling wave; a file
        of bodies and links needs it). A chain or a mechanism of bodies and links is screened, then
        refined on the exact model, or on the smoothed one with --method smoothed (its --outer,
        --inner, --eps), and verified on its steady gaits (--harmonics default 3 for a chain, 2 for
        bodies and links, or --shape spline with --knots; the travelling-wave screen's --amplitudes,
        --frequencies, --phases, --zoom-levels, --zoom-points (a chain: --screen-speed), and --local,
        --max-iter, --local-method, --margin, --transient, --dt, --search-dt, --omega, --direction
        apply)."""
        import locomotion_jax as lj

        from ..optimisation import _optimise, _pareto
        from ..optimisation._optimum import ExactSettings, Settings, start_waveform

        try:
            if method not in ("exact", "smoothed"):
                raise ValueError(f"--method must be 'exact' or 'smoothed', got {method!r}.")
            built = build(mech, file, wave=False)
            if a_max is None and file is None:
                raise ValueError("--a-max is required (without a mechanism file, whose amplitude it defaults to).")
            if built.kind != "mechanism" and a_max is None:
                a_max = amplitude(built)
            steps: dict[str, Any] = {name: v for name, v in (("dt", dt), ("search_dt", search_dt)) if v is not None}
            tension: dict[str, Any] = {} if tension_periods is None else {"tension_periods": tension_periods}
            if built.kind != "paper":
                from ._files import given

                screen: dict[str, Any] = dict(amplitudes=amplitudes, frequencies=frequencies, phases=phases,
                                              zoom_levels=zoom_levels, zoom_points=zoom_points, local=local,
                                              screen_speed=screen_speed, margin=margin, verbose=verbose)  # fmt: skip
                screen |= {"max_iter": max_iter} if given(["max_iter"]) else {}  # else the optimiser's default
                screen |= {"local_method": local_method}
                screen |= {name: v for name, v in (("shape", shape), ("knots", knots)) if given([name])}
                screen |= {"transient": int(transient)} if transient is not None else {}
                screen |= steps
                screen |= tension
                if method == "smoothed":  # the smoothed local stage's own options (its rollout's lengths the defaults')
                    screen |= dict(smoothed=Settings(outer=outer, inner=inner, eps_schedule=_eps_schedule(eps),
                                                     verbose=verbose))  # fmt: skip
                chain_settings = lj.ChainOptimiseSettings(**screen)
                return _optimise_bodies(built, v_min, a_max, direction, omega, harmonics, chain_settings, out, json_out,
                                        _start(start), method, _screen(reuse_screen))  # fmt: skip
            params = built.mechanism
            assert a_max is not None  # the paper's model: given, or its amplitude
            settings: ExactSettings | Settings
            if method == "exact":
                settings = ExactSettings(
                    shape=shape, knots=knots, local=local, max_iter=max_iter, local_method=local_method,
                    margin=margin, seed=seed, verbose=verbose, **steps, **tension,
                )  # fmt: skip
            else:
                if steps or tension:
                    raise ValueError("--dt, --search-dt and --tension-periods: the exact method's (--method exact).")
                settings = Settings(
                    starts=starts,
                    outer=outer,
                    inner=inner,
                    eps_schedule=_eps_schedule(eps),
                    margin=margin,
                    seed=seed,
                    verbose=verbose,
                    transient=12.0 if transient is None else transient,
                    measured=measured,
                    corrections=corrections,
                )
            n_harm = harmonics if harmonics is not None else (16 if method == "exact" else 3)
            # Validate before the (long) sinusoid sweep.
            from ..optimisation._constraints import check_inputs

            check_inputs(params, v_min, a_max, direction, n_harm, omega, margin)
            given = _start(start)
            start_waveform(given)  # refused before the sinusoid sweep
            log = (lambda msg: print(msg, file=sys.stderr, flush=True)) if verbose or not json_out else (lambda m: None)
            if reuse_screen is not None:
                try:
                    sweep = _pareto.sweep_of(_screen(reuse_screen))
                except TypeError as err:
                    raise ValueError(f"--reuse-screen: {reuse_screen}: {err}") from None
                log(f"the sinusoid sweep of {reuse_screen}: {sweep.a.size} sinusoids, not solved again")
            else:
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
                start=given,
            )
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(code=2) from None
        if out is not None:
            _save(result, params, sweep, Path(out), json_out)
        if json_out:
            typer.echo(result.to_json())
        else:
            typer.echo(result.summary())


def amplitude(built: Built) -> float:
    """The default `--a-max` of `optimize FILE`: the amplitude of the file's sinusoid or travelling wave."""
    from ..model._waveform import Sinusoid
    from ._files import travelling_wave

    wave = built.extra.get("waveform")
    if built.kind == "chain" and built.file is not None:
        tw = travelling_wave(built.file)
        if tw is not None:
            return abs(tw["a"])
    elif built.kind == "paper" and wave is None:
        return float(built.mechanism.a)
    elif isinstance(wave, Sinusoid):
        return abs(float(wave.a))
    raise ValueError(f"--a-max: {built.file}'s waveform has no single amplitude to default to; give --a-max.")


def _save(opt: Any, params: Any, sweep: Any, out: Path, json_out: bool) -> None:
    """`--out DIR`: the optimum's whole JSON (`optimum.json`, candidates and history included; what
    `--start` reads back) and its figures (`optimisation._plots.save_all`: the signals, one period
    of motion, the cost of transport against speed of the baseline signals; it creates `out`)."""
    from ..optimisation._plots import save_all

    figures = save_all(opt, params, sweep, out)
    (out / "optimum.json").write_text(opt.to_json(full=True, indent=1))
    paths = [out / "optimum.json", *figures]
    if not json_out:
        typer.echo("wrote " + ", ".join(str(p) for p in paths), err=True)


def _screen(path: Path | None) -> Any:
    """`--reuse-screen`: the `screen` of an earlier optimum's JSON (`optimise`'s `sweep=` checks it).

    **Raises:** `ValueError` naming `--reuse-screen` and the file where it holds no screen."""
    if path is None:
        return None
    record = _read(path, "--reuse-screen")
    if not isinstance(record, dict) or not isinstance(record.get("screen"), dict):
        raise ValueError(f"--reuse-screen: {path} holds no screen; optimize --out DIR writes one in "
                         "DIR/optimum.json.")  # fmt: skip
    return record["screen"]


def _read(path: Path, option: str) -> Any:
    """The JSON of an earlier optimum, for `option`.

    **Raises:** `ValueError` naming `option` and the file where it cannot be read."""
    import json

    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"{option}: cannot read {path} as the JSON of an earlier optimize --json ({err}).") from None


def _start(path: Path | None) -> Any:
    """`--start`: the earlier result read from its JSON (`optimise`'s `start=` checks its kind).

    **Raises:** `ValueError` naming `--start` and the file where it holds no result."""
    if path is None:
        return None
    record = _read(path, "--start")
    if not isinstance(record, dict) or not {"cos", "sin", "control", "omega"} <= set(record):
        raise ValueError(f"--start: {path} holds no optimum (cos, sin, control, omega); optimize --json writes one.")
    return record


def _optimise_bodies(built: Built, v_min: float, a_max: float | None, direction: int | None, omega: float | None,
                     harmonics: int | None, settings: Any, out: Path | None, json_out: bool,
                     start: Any = None, method: str = "exact", sweep: Any = None) -> None:  # fmt: skip
    """`optimize` of a chain or a mechanism of bodies and links: `lj.optimise` (from `start`, the
    fields of an earlier result, where given), printed; with `out` also saved and plotted (`_save`)."""
    import locomotion_jax as lj

    from .._json import dumps

    if a_max is None:
        raise ValueError(f"--a-max is required for {built.file} (a mechanism of bodies and links): the bound on "
                         "every actuated signal's excursion about its mean.")  # fmt: skip
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    default = None if settings.shape == "spline" else 3 if built.kind == "chain" else 2
    opt = lj.optimise(built.mechanism, v_min, a_max, direction=1 if direction is None else direction, omega=omega,
                      harmonics=default if harmonics is None else harmonics, settings=settings,
                      start=start, method=method, sweep=sweep)  # fmt: skip
    if out is not None:
        _save(opt, None, None, out, json_out)
    typer.echo(dumps({**opt.to_dict(), **built.record}) if json_out else opt.summary())
