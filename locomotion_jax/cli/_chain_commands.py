"""`locomotion-jax chain-simulate`, `chain-gait` and `chain-sweep`: chains of N masses from the command line.

The counterparts of `simulate`, `gait` and `sweep` for a [`Chain`][] driven by a travelling
wave $s_j = a\\sin(\\omega t - j\\varphi)$, with the mechanism options of `chain`
(`_chain_options`). Errors end with `Error: ...` and exit code 2; `--json` prints one JSON
object whose non-finite numbers are `null`.
"""

from pathlib import Path
from typing import Annotated, Any, Literal, NoReturn

import numpy as np
import typer

from .._json import dumps
from ._chain_options import describe, mechanism_options, to_chain, wave_options
from ._errors import friendly
from ._options import expand, Values


Contact = Annotated[Literal["strict", "paper"], typer.Option(help="Contact reading.")]
Start = Annotated[Literal["paper", "relaxed"], typer.Option(help="Initial gaps: lbar_j (eq. 14) or relaxed springs.")]
Dt = Annotated[float, typer.Option(help="Step of the exact engine.")]
Json = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the report.")]


_DEFAULTS: dict[str, str] = {"a": "0.05", "omega": "2", "phi": "0"}
"""The wave of `chain-sweep` without a mechanism file."""

_ORDER = "locomotion_jax.axis_order"


def _recorder(name: str) -> Any:
    # click processes the options in the order of the command line, so the sweep's dimensions can follow it.
    def record(value: str | None) -> str | None:
        if value is not None:
            from ._files import context

            context().meta.setdefault(_ORDER, []).append(name)
        return value

    return record


def _axis(name: str, what: str, default: str) -> Any:
    return typer.Option(
        help=f"{what}: start:stop:count, v1,v2,... or a value (default: {default}, or the mechanism file's).",
        callback=_recorder(name),
    )


def _fail(err: Exception) -> NoReturn:
    typer.echo(f"Error: {err}", err=True)
    raise typer.Exit(2) from None


def _plain(v: Any) -> Any:
    v = np.asarray(v)
    return v.tolist() if v.ndim else v.item()


def _plot(traj: Any, path: Path, title: str) -> None:
    from matplotlib.figure import Figure  # no pyplot: no global backend state

    fig = Figure(figsize=(8, 8), layout="constrained")
    ax = fig.subplots(4, 1, sharex=True)
    ok = np.asarray(traj.valid)
    t = np.asarray(traj.t)[ok]
    x, v, stuck = (np.asarray(a)[ok] for a in (traj.x, traj.v, traj.stuck))
    for i in range(x.shape[-1]):
        ax[0].plot(t, x[:, i] - x[0, i], label=f"x{i} - x{i}(0)")
        ax[1].plot(t, v[:, i], label=f"v{i}")
        ax[2].fill_between(t, i - 0.4 * stuck[:, i], i + 0.4 * stuck[:, i], step="post", lw=0)
    X = np.asarray(traj.X)[ok]
    ax[3].plot(t, X - X[0], color="k")
    ax[0].set_ylabel("displacement")
    ax[1].set_ylabel("velocity")
    ax[2].set_ylabel("stuck (per mass)")
    ax[2].set_yticks(range(x.shape[-1]))
    ax[3].set_ylabel("centre of mass")
    ax[3].set_xlabel("t (dimensionless)")
    for a in ax[:2]:
        a.legend(loc="upper left", fontsize="small", ncol=min(x.shape[-1], 4))
    fig.suptitle(title)
    fig.savefig(path, dpi=120)


def chain_gait_report(chain: Any, ks: tuple[int, ...], transient: int, contact: str, start: str, dt: float,
                      as_json: bool, header: str, extra: dict[str, Any]) -> None:  # fmt: skip
    """Solve and print the steady gait of `chain` (`chain-gait`, `gait FILE`); `extra`: the mechanism in the JSON."""
    import locomotion_jax as lj

    from ._files import note
    from ._gait import _pairs

    note(f"solving the steady gait, periods {','.join(map(str, ks))} (compiling the solver: first call only)...")
    g = lj.steady_gait(chain, periods=ks, transient=transient, dynamics=lj.Exact(dt=dt), contact=contact, start=start)
    names = ("k", "period", "mean_speed", "cost_of_transport", "e_d", "work", "regime", "stick_fraction",
             "n_switch", "state", "stable", "residual", "n_iter", "liftoff")  # fmt: skip
    fields = {n: _plain(getattr(g, n)) for n in names}
    fields["status_name"] = lj.GaitStatus(int(g.status)).name
    fields["regime_name"] = lj.Regime(int(g.regime)).name
    fields["multipliers"] = _pairs(g.multipliers)
    if as_json:
        typer.echo(dumps({**fields, **extra, "periods": list(ks), "transient": transient, "contact": contact,
                          "start": start, "dt": dt}))  # fmt: skip
        return
    typer.echo(f"{header}: {fields['status_name']}")
    for name, v in fields.items():
        if isinstance(v, list):
            v = "[" + ", ".join(f"{x:.4g}" if isinstance(x, float) else str(x) for x in v) + "]"
        typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")


def register(app: typer.Typer) -> None:
    """Add `chain-simulate`, `chain-gait` and `chain-sweep` to `app`."""

    @app.command("chain-simulate")
    @friendly
    @expand(mech=mechanism_options(), wave=wave_options())
    def chain_simulate(
        *,
        mech: Values,
        wave: Values,
        t_end: Annotated[float, typer.Option(help="End time of the trajectory.")] = 20.0,
        saves: Annotated[int, typer.Option(help="Saved states, equally spaced over [0, t-end].")] = 401,
        contact: Contact = "strict",
        start: Start = "paper",
        dt: Dt = 0.01,
        out: Annotated[Path | None, typer.Option(help="Directory for the PNG plot.")] = None,
        as_json: Json = False,
    ) -> None:
        """Simulate one chain: its trajectory (positions, velocities, stuck masses, normal forces, energy).

        With --json, stdout is one JSON object: `t`, per-time lists `X`, `e_d`, `w`, per-mass lists
        of lists `x`, `v`, `stuck`, `N`, per-spring `l0`, `tension`, and `status_name`, `liftoff`,
        `t_liftoff` (null without lift-off), the mechanism and settings. With --out, a PNG of the
        displacements, velocities, stuck intervals and the centre of mass.
        """
        import locomotion_jax as lj

        try:
            if not (t_end > 0 and np.isfinite(t_end)):
                raise ValueError(f"--t-end must be a finite number > 0, got {t_end!r}.")
            if saves < 2:
                raise ValueError(f"--saves must be >= 2, got {saves!r}.")
            mech_obj = to_chain(mech, lj.TravellingWave(wave["a"], wave["omega"], wave["phi"]))
            if out is not None:
                try:
                    out.mkdir(parents=True, exist_ok=True)
                except OSError as err:
                    raise ValueError(f"--out {out}: cannot create the directory ({err.strerror or err}).") from None
            ts = np.linspace(0.0, t_end, saves)
            traj = lj.simulate(mech_obj, t_end, ts, dynamics=lj.Exact(dt=dt), contact=contact, start=start)
        except ValueError as err:
            _fail(err)
        png = None
        if out is not None:
            png = out / f"chain{mech_obj.n_masses}_a{wave['a']:.4g}_omega{wave['omega']:.4g}_phi{wave['phi']:.4g}.png"
            _plot(traj, png, f"{mech_obj.n_masses} masses; a = {wave['a']:.4g}, omega = {wave['omega']:.4g}, "
                  f"phi = {wave['phi']:.4g}")  # fmt: skip
        status = lj.Status(int(traj.status)).name
        X = np.asarray(traj.X)
        summary = dict(displacement=float(X[-1] - X[0]), mean_velocity=float((X[-1] - X[0]) / t_end),
                       e_d=float(np.asarray(traj.e_d)[-1]), w=float(np.asarray(traj.w)[-1]),
                       n_switch=int(traj.n_switch), status_name=status, liftoff=bool(traj.liftoff),
                       t_liftoff=float(traj.t_liftoff))  # fmt: skip
        settings = dict(**describe(mech), **wave, t_end=t_end, contact=contact, start=start, dt=dt)
        if as_json:
            series = {n: _plain(getattr(traj, n)) for n in ("t", "X", "e_d", "w", "x", "v", "stuck", "N", "l0",
                                                            "tension", "valid")}  # fmt: skip
            typer.echo(dumps({**summary, **series, **settings, "plot": None if png is None else str(png)}))
            return
        typer.echo(f"chain of {mech_obj.n_masses} masses; a={wave['a']:g}, omega={wave['omega']:g}, "
                   f"phi={wave['phi']:g}; t_end={t_end:g}")  # fmt: skip
        for name, v in summary.items():
            typer.echo(f"  {name:<14} {v:.6g}" if isinstance(v, float) else f"  {name:<14} {v}")
        if png is not None:
            typer.echo(f"plot: {png}")

    @app.command("chain-gait")
    @friendly
    @expand(mech=mechanism_options(), wave=wave_options())
    def chain_gait(
        *,
        mech: Values,
        wave: Values,
        periods: Annotated[str, typer.Option(help="Gait periods tried, in actuation periods.")] = "1,2,3,4",
        transient: Annotated[int, typer.Option(help="Actuation periods run before Newton's method.")] = 30,
        contact: Contact = "strict",
        start: Start = "relaxed",
        dt: Dt = 0.01,
        as_json: Json = False,
    ) -> None:
        """Solve the steady gait of one chain: speed, cost of transport, Floquet multipliers, stick fractions.

        Whole periods of the periodic orbit (`steady_gait`). With --json, stdout is one JSON object;
        a complex multiplier is a pair [re, im].
        """
        import locomotion_jax as lj

        from ._gait import _periods, gait_omega

        ks = _periods(periods)
        gait_omega(wave["omega"])
        mech_obj = to_chain(mech, lj.TravellingWave(wave["a"], wave["omega"], wave["phi"]))
        header = f"chain of {mech_obj.n_masses} masses; a={wave['a']:g}, omega={wave['omega']:g}, phi={wave['phi']:g}"
        chain_gait_report(mech_obj, ks, transient, contact, start, dt, as_json, header, {**describe(mech), **wave})

    @app.command("chain-sweep")
    @friendly
    @expand(mech=mechanism_options(masses_required=False))
    def chain_sweep(
        file: Annotated[
            Path | None, typer.Argument(help="A chain's mechanism file (TOML), instead of the mechanism options.")
        ] = None,
        *,
        out: Annotated[Path, typer.Option(help="Output NetCDF file (.nc).")],
        mech: Values,
        a: Annotated[str | None, _axis("a", "Wave amplitude", "0.05")] = None,
        omega: Annotated[str | None, _axis("omega", "Wave frequency", "2")] = None,
        phi: Annotated[str | None, _axis("phi", "Phase lag", "0")] = None,
        mode: Annotated[Literal["grid", "list"], typer.Option(help="'grid' (outer product) or 'list' (zip).")] = "grid",
        z: Annotated[float, typer.Option(help="Distance whose travel time and energy are measured.")] = 5.0,
        horizon: Annotated[float, typer.Option(help="Longest measured time after the start.")] = 2000.0,
        window: Annotated[float, typer.Option(help="Regime window after the start.")] = 25.0,
        t_start: Annotated[float | None, typer.Option(help="Measurement start (default: Chain.t_start).")] = None,
        contact: Contact = "strict",
        start: Start = "paper",
        dt: Dt = 0.01,
        chunk_size: Annotated[int, typer.Option(help="Configurations per compiled chunk.")] = 1024,
        on_invalid: Annotated[
            Literal["raise", "flag"], typer.Option(help="'raise': reject invalid configurations; 'flag': record them.")
        ] = "raise",
        progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    ) -> None:
        """Map a chain's measurements over the travelling wave's a, omega and phi into a NetCDF file.

        Example: `locomotion-jax chain-sweep --masses 1,1,1,1 --d 0 --friction anisotropic
        --mu-s-bwd 0.9 --mu-k-bwd 0.7 --phi -3.1:3.1:32 --omega 1,2,4 --a 0.1 --out worm.nc`.
        Dimensions follow the order of the options on the command line (those given as ranges or
        lists), as `lj.sweep` follows the order of its `axes`. With a FILE (a chain), the mechanism
        comes from the file, and the wave's values not given from its waveform table (a TravellingWave).
        """
        import locomotion_jax as lj

        from ._files import context, refuse_options
        from ._main import parse_axis

        try:
            texts = {"a": a, "omega": omega, "phi": phi}
            if file is not None:
                from ._file_commands import chain_sweep_mechanism, with_wave

                refuse_options(file, mech)
                chain, texts = chain_sweep_mechanism(file, texts)

                def build_file(**v):
                    return with_wave(chain, lj.TravellingWave(v["a"], v["omega"], v["phi"]), on_invalid == "raise")

                build = build_file
            else:
                if mech["masses"] is None:
                    raise ValueError("--masses is required (or give a chain's mechanism file).")
                texts = {n: _DEFAULTS[n] if t is None else t for n, t in texts.items()}
                to_chain(mech)  # the mechanism's options checked before any computation

                def build_options(**v):
                    return to_chain(mech, lj.TravellingWave(v["a"], v["omega"], v["phi"]), check=on_invalid == "raise")

                build = build_options

            first = context().meta.get(_ORDER, [])  # the options given, in their order
            order = [*first, *(n for n in texts if n not in first)]
            parsed = {n: parse_axis(n, texts[n]) for n in order}
            axes = {n: v for n, v in parsed.items() if isinstance(v, np.ndarray)}
            fixed = {n: v for n, v in parsed.items() if not isinstance(v, np.ndarray)}
            if not axes:
                raise ValueError("nothing to sweep: give at least one range or list, e.g. --phi -3.1:3.1:32.")

            ds = lj.sweep(
                axes, fixed=fixed, mode=mode, mechanism=build, z=z, horizon=horizon, window=window, t_start=t_start,
                contact=contact, start=start, dynamics=lj.Exact(dt=dt), chunk_size=chunk_size, path=out,
                progress=progress, on_invalid=on_invalid,
            )  # fmt: skip
        except ValueError as err:
            _fail(err)
        typer.echo(f"wrote {out}: " + " x ".join(f"{n}[{s}]" for n, s in ds.sizes.items() if n != "mass"))
        status = np.asarray(ds.status).ravel()
        regime = np.asarray(ds.regime).ravel()
        typer.echo("status: " + ", ".join(f"{s.name} {int((status == s).sum())}" for s in lj.Status
                                          if (status == s).any()))  # fmt: skip
        typer.echo("regime: " + ", ".join(f"{r.name} {int((regime == r).sum())}" for r in lj.Regime
                                          if (regime == r).any()))  # fmt: skip
        speed = np.asarray(ds.mean_speed)
        if np.isfinite(speed).any():
            i = np.unravel_index(int(np.nanargmax(speed)), speed.shape)
            index = dict(zip(axes, i)) if mode == "grid" else dict.fromkeys(axes, i[0])
            at = ", ".join(f"{n}={float(v[index[n]]):.4g}" for n, v in axes.items())
            typer.echo(f"fastest: mean speed {float(speed[i]):.4g} at {at}")
