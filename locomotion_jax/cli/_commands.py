"""`locomotion-jax measure`, `simulate` and `sweep`, each over any mechanism (`_mechanism.build`).

`register(app)` adds the three subcommands. Each is written once: the mechanism (the paper's model,
a chain or a mechanism file) is built from the options, and the command calls the library's front
end on it (`lj.measure`, `lj.simulate`, `lj.sweep`). With `--json`, stdout is one JSON object whose
non-finite numbers are `null` (`_json.py`).
"""

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import typer

from .._json import dumps
from ._errors import friendly
from ._files import context, echo_fields, plain
from ._mechanism import build, Built, KIND_NAMES, kind_of_options, mechanism_options, ORDER, to_chain, wave_text
from ._options import expand, run_options, Values


File = Annotated[
    Path | None,
    typer.Argument(help="A mechanism file (TOML), instead of the mechanism options: examples/worm.toml."),
]
Json = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of the report.")]
TStart = Annotated[
    float | None, typer.Option(help="Measurement start (default: 80 periods of the lowest natural frequency).")
]
MEASURE_SETTINGS: tuple[str, ...] = ("z", "horizon", "window", "contact", "start", "dt")


def exact(run: Values) -> dict[str, Any]:
    """The engine and the contact reading and start of the run settings `run`, as keyword arguments."""
    import locomotion_jax as lj

    return dict(dynamics=lj.Exact(dt=run["dt"]), contact=run["contact"], start=run["start"])


def report(built: Built, fields: dict[str, Any], settings: dict[str, Any], as_json: bool) -> None:
    """Print `fields` (and the mechanism and `settings`): one JSON object, or the report."""
    if as_json:
        typer.echo(dumps({**built.record, **settings, **fields}))  # a field named as a setting: the measured value
        return
    typer.echo(built.head)
    typer.echo("settings: " + ", ".join(f"{n}={v}" for n, v in settings.items() if v is not None))
    echo_fields(fields)


def _positions(traj: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and stuck flags over the bodies (a trailing body axis) of a trajectory."""
    return np.asarray(traj.x), np.asarray(traj.v), np.asarray(traj.stuck)


def _plot(traj: Any, path: Path, title: str) -> None:
    """Displacements, velocities, stuck intervals of every body, and the centre of mass vs time."""
    from matplotlib.figure import Figure  # no pyplot: no global backend state

    fig = Figure(figsize=(8, 8), layout="constrained")
    ax = fig.subplots(4, 1, sharex=True)
    ok = np.asarray(traj.valid)
    t = np.asarray(traj.t)[ok]
    x, v, stuck = (a[ok] for a in _positions(traj))
    for i in range(x.shape[-1]):
        ax[0].plot(t, x[:, i] - x[0, i], label=f"x{i} - x{i}(0)")
        ax[1].plot(t, v[:, i], label=f"v{i}")
        ax[2].fill_between(t, i - 0.4 * stuck[:, i], i + 0.4 * stuck[:, i], step="post", lw=0)
    X = np.asarray(traj.X)[ok]
    ax[3].plot(t, X - X[0], color="k")
    for a, name in zip(ax, ("displacement", "velocity", "stuck (per body)", "centre of mass")):
        a.set_ylabel(name)
    ax[2].set_yticks(range(x.shape[-1]))
    ax[3].set_xlabel("t (dimensionless)")
    for a in ax[:2]:
        a.legend(loc="upper left", fontsize="small", ncol=min(x.shape[-1], 4))
    t_lift = float(np.asarray(traj.t_liftoff))
    if math.isfinite(t_lift):
        for a in ax:
            a.axvline(t_lift, color="red", ls="--", lw=1)
        title += f"  [lift-off at t = {t_lift:.4g}]"
    fig.suptitle(title)
    fig.savefig(path, dpi=120)


def parse_axis(name: str, text: str, option: str | None = None) -> float | np.ndarray:
    """Read `--NAME` of `sweep`: `start:stop:count` (linspace), `v1,v2,...`, or one fixed value.

    **Raises:** `ValueError` naming the option (`option`, else `--NAME`) for unreadable text or an empty range.
    """
    opt = option or "--" + name.replace("_", "-")
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


def _sweep_plan(
    mech: Values, file: Path | None, on_invalid: str, vary: list[str] | None = None
) -> tuple[dict[str, Any], Any]:
    """`sweep`'s swept names (in the order given), each with its text (or, for `--vary`, its values),
    and the `mechanism` argument of `lj.sweep` (`None`: the paper's model, whose parameters are the names)."""
    import locomotion_jax as lj

    from ._files import load, refuse_options

    order = context().meta.get(ORDER, []) if context() is not None else []
    check = on_invalid == "raise"
    loaded = None if file is None else load(file)[0]
    kind = None if loaded is None else loaded.kind
    if vary and kind not in ("mechanism", "chain"):
        what = "the paper's model" if loaded is None and mech["masses"] is None else "a chain"
        what = f"{file} holds {KIND_NAMES[kind]}" if kind is not None else f"the options give {what}"
        raise ValueError(f"--vary names the numbers of a mechanism file (a chain, or bodies and links); {what}: "
                         "sweep its options instead (--omega, --a, ...; see sweep --help).")  # fmt: skip
    if kind == "mechanism" or (kind == "chain" and vary):
        assert file is not None
        from ._files import given

        named = given(mech)
        e_g = "links.1.waveform.a=0.2:1:5" if kind == "mechanism" else "chain.k=20:80:4"
        if named:
            options = ", ".join("--" + n.replace("_", "-") for n in named)
            what = "describes the mechanism (bodies and links)" if kind == "mechanism" else "is swept with --vary"
            raise ValueError(f"{options}: {file} {what}; name the numbers of it to sweep with --vary PATH=VALUES, "
                             f"e.g. --vary {e_g}.")  # fmt: skip
        if not vary:
            raise ValueError(f"nothing to sweep: name the numbers of {file} to map with --vary PATH=VALUES, e.g. "
                             "--vary links.1.k=5:20:4 (`locomotion-jax sweep --help`).")  # fmt: skip
        from ._vary import plan

        return plan(file, vary)
    if file is None and mech["masses"] is None:  # the paper's model: its parameters given
        kind_of_options(mech)
        names = [n for n in order if n in PAPER_AXES and mech.get(n) is not None]
        names += [n for n in PAPER_AXES if mech.get(n) is not None and n not in names]
        return {n: mech[n] for n in names}, None
    wave = ("a", "omega", "phi")
    if file is None:
        kind_of_options(mech)
        to_chain(mech)  # the mechanism's options checked before any computation
        texts = {n: wave_text(mech, n) for n in wave}

        def build_options(**v: Any) -> Any:
            return to_chain(mech, lj.TravellingWave(v["a"], v["omega"], v["phi"]), check=check)

        chain_build = build_options
    else:
        loaded, waveform = load(file)  # read again: the paper's [waveform] with it
        if loaded.kind == "paper":
            if waveform is not None:
                raise ValueError(f"{file}: sweep maps the paper's sinusoid (eq. 13); its [waveform] table cannot be "
                                 "swept.")  # fmt: skip
            given = {n: mech[n] for n in order if n in PAPER_AXES and mech.get(n) is not None}
            refuse_options(file, [n for n in mech if n not in PAPER_AXES])
            values = {n: repr(float(v)) for n, v in loaded.as_dict().items()}
            if "omega_over_wn1" in given:
                values.pop("omega")
            return {**given, **{n: v for n, v in values.items() if n not in given}}, None
        refuse_options(file, [n for n in mech if n not in wave])
        from ._files import travelling_wave

        tw = travelling_wave(file)
        missing = [n for n in wave if mech.get(n) is None]
        if missing and tw is None:
            options = ", ".join("--" + n for n in missing)
            raise ValueError(f"{options}: {file} has no [waveform] of type TravellingWave to take them from; give "
                             "them.")  # fmt: skip
        texts = {n: mech[n] if mech.get(n) is not None else repr(tw[n]) for n in wave}  # type: ignore[index]

        def build_file(**v: Any) -> Any:
            from ._files import with_wave

            return with_wave(loaded, lj.TravellingWave(v["a"], v["omega"], v["phi"]), check)

        chain_build = build_file
    first = [n for n in order if n in wave]
    return {n: texts[n] for n in [*first, *(n for n in wave if n not in first)]}, chain_build


PAPER_AXES: tuple[str, ...] = ("omega", "omega_over_wn1", "a", "d", "mhat", "mu_s", "mu_k", "k", "c", "lbar")


def register(app: typer.Typer) -> None:
    """Add `measure`, `simulate` and `sweep` to `app`."""

    @app.command("measure")
    @friendly
    @expand(mech=mechanism_options(), run=run_options())
    def measure(file: File = None, *, mech: Values, run: Values, t_start: TStart = None, as_json: Json = False) -> None:
        """Measure one mechanism: time and energy to travel z, speed, regime, stick fractions.

        The mechanism is the paper's model (its options, by default), a chain (`--masses 1,1,1` and the
        chain options) or a mechanism FILE (`locomotion-jax measure examples/worm.toml`). With --json,
        stdout is one JSON object: every measurement field (per-body fields as lists), `regime_name`,
        `status_name`, the mechanism (`params`, the chain's options or the file, and `kind`) and the
        settings; non-finite numbers are null (inf: tau_z and e_z when z is not reached, t_liftoff
        without lift-off; `reached` and `liftoff` say which).
        """
        import locomotion_jax as lj

        built = build(mech, file)
        m = lj.measure(built.mechanism, run["z"], horizon=run["horizon"], window=run["window"], t_start=t_start,
                       **exact(run), **built.extra)  # fmt: skip
        fields = {name: plain(v) for name, v in m.to_numpy().items()}
        fields["regime_name"] = lj.Regime(int(m.regime)).name
        fields["status_name"] = lj.Status(int(m.status)).name
        report(built, fields, {n: run[n] for n in MEASURE_SETTINGS} | {"t_start": t_start}, as_json)

    @app.command("simulate")
    @friendly
    @expand(mech=mechanism_options(), run=run_options(("contact", "start", "dt")))
    def simulate(
        file: File = None,
        *,
        mech: Values,
        t_end: Annotated[float, typer.Option(help="End time of the trajectory.")] = 20.0,
        saves: Annotated[int, typer.Option(help="Saved states, equally spaced over [0, t-end].")] = 401,
        run: Values,
        out: Annotated[
            Path | None, typer.Option(help="Directory for the PNG plot; without it nothing is written.")
        ] = None,
        plot: Annotated[bool, typer.Option(help="With --out, save the plot of the trajectory.")] = True,
        as_json: Json = False,
    ) -> None:
        """Simulate one mechanism from t = 0 to --t-end: its trajectory, summarised (or in full with --json).

        The report: displacement and mean velocity of the centre of mass, dissipated energy, actuator
        work, switches, status and lift-off. With --json, stdout is one JSON object: the summary, every
        per-time field of the trajectory (`t`, `X`, `e_d`, `w`, ...; per-body fields as lists of
        lists), the mechanism and the settings, and `plot`. With --out, a PNG of every body's
        displacement, velocity and stuck intervals and of the centre of mass.
        """
        import locomotion_jax as lj

        if not (math.isfinite(t_end) and t_end > 0):
            raise ValueError(f"--t-end must be a finite number > 0, got {t_end!r}.")
        if saves < 2:
            raise ValueError(f"--saves must be >= 2, got {saves!r}.")
        built = build(mech, file)
        plot_dir = out if plot else None
        if plot_dir is not None:
            try:
                plot_dir.mkdir(parents=True, exist_ok=True)
            except OSError as err:
                raise ValueError(f"--out {out}: cannot create the directory ({err.strerror or err}).") from None
        traj = lj.simulate(built.mechanism, t_end, np.linspace(0.0, t_end, saves), **exact(run), **built.extra)
        png = None
        if plot_dir is not None:
            png = plot_dir / f"simulate_{built.kind if file is None else file.stem}_t{t_end:g}.png"
            _plot(traj, png, built.head)
        X = np.asarray(traj.X)
        summary = dict(displacement=float(X[-1] - X[0]), mean_velocity=float((X[-1] - X[0]) / t_end),
                       e_d=float(np.asarray(traj.e_d)[-1]), w=float(np.asarray(traj.w)[-1]),
                       n_switch=int(traj.n_switch), status_name=lj.Status(int(traj.status)).name,
                       liftoff=bool(traj.liftoff), t_liftoff=float(traj.t_liftoff))  # fmt: skip
        settings = {"t_end": t_end, "saves": saves, **run}
        if as_json:
            series = {name: plain(v) for name, v in traj.to_numpy().items() if np.ndim(v)}
            typer.echo(
                dumps({**summary, **series, **built.record, **settings, "plot": None if png is None else str(png)})
            )
            return
        report(built, summary, settings, False)
        if png is not None:
            typer.echo(f"plot: {png}")

    @app.command("sweep")
    @friendly
    @expand(mech=mechanism_options(sweep=True), run=run_options())
    def sweep(
        file: File = None,
        *,
        out: Annotated[
            Path,
            typer.Option(
                help="Output: a NetCDF file (.nc), or a Zarr store (.zarr) that several processes can fill at "
                "once (jax.distributed). Either is resumable: rerun with the same path."
            ),
        ],  # fmt: skip
        mech: Values,
        vary: Annotated[
            list[str] | None,
            typer.Option(
                metavar="PATH=VALUES",
                help='A mechanism FILE of bodies and links (kind = "mechanism") or of a chain: a number of the file '
                "to map, named by its tables, indices (from 0) and field, with its values: --vary "
                "bodies.0.mass=0.5,1,2, --vary links.1.waveform.a=0.2:1:5, --vary links.2.waveform.cos.1=0.1; "
                "a chain's: --vary chain.k=20:80:4, --vary friction.mu_s_bwd=0.6:1:5. Repeat it for more "
                "dimensions; several paths joined by commas take the same values (one dimension).",
            ),
        ] = None,
        mode: Annotated[
            Literal["grid", "list"], typer.Option(help="'grid' (outer product) or 'list' (zip axes of equal length).")
        ] = "grid",
        chunk_size: Annotated[int, typer.Option(help="Configurations per compiled chunk.")] = 4096,
        run: Values,
        t_start: TStart = None,
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
        """Map the measurements over a grid of parameters into an xarray/NetCDF file or a Zarr store.

        The paper's model: any of its parameters, e.g. `locomotion-jax sweep --omega 1:25:256 --a
        0.01:0.1:256 --out maps/ssl.nc`. A chain (`--masses`, or a chain's FILE): the travelling wave's
        a, omega and phi (its other options fixed; a file's wave gives the values not given). A paper
        FILE: the parameters not given take the file's values. A FILE of bodies and links (kind =
        "mechanism"), or a chain's FILE: any of its numbers, named with --vary PATH=VALUES (`locomotion-jax sweep
        examples/capsule.toml --vary links.1.waveform.a=0.2:1:5 --vary bodies.0.mass=0.5,1 --out
        capsule.nc`; the dimensions are named by the paths). Each option is a range start:stop:count,
        a list v1,v2,... or one value; the dimensions follow the order of the options on the command
        line. An interrupted sweep (into a NetCDF file or a Zarr store) resumes from its finished
        chunks when rerun with the same arguments; a finished one is read back.
        """
        import locomotion_jax as lj

        texts, chain_build = _sweep_plan(mech, file, on_invalid, vary)
        parsed = {n: parse_axis(n, text) if isinstance(text, str) else text for n, text in texts.items()}
        axes = {n: v for n, v in parsed.items() if isinstance(v, np.ndarray)}
        fixed = {n: v for n, v in parsed.items() if not isinstance(v, np.ndarray)}
        if not axes:
            e_g = "--vary links.1.k=5:20:4" if vary else "--omega 1:25:256"
            raise ValueError(f"nothing to sweep: give at least one range or list, e.g. {e_g}.")
        how: dict[str, Any] = dict(mode=mode, z=run["z"], horizon=run["horizon"], window=run["window"], **exact(run),
                   chunk_size=chunk_size, path=out, progress=progress, on_invalid=on_invalid)  # fmt: skip
        if chain_build is None:
            if t_start is not None:
                raise ValueError("--t-start: a sweep of the paper's model starts each measurement at its own t_start.")
            ds = lj.sweep(axes, fixed=fixed, overwrite=overwrite, order=order, **how)
        else:
            ds = lj.sweep(axes, fixed=fixed, mechanism=chain_build, t_start=t_start, overwrite=overwrite, order=order,
                          **how)  # fmt: skip
        typer.echo(f"wrote {out}: " + " x ".join(f"{n}[{s}]" for n, s in ds.sizes.items() if n != "mass"))
        status = np.asarray(ds.status).ravel()
        regime = np.asarray(ds.regime).ravel()
        typer.echo("status: " + ", ".join(f"{s.name} {int((status == s).sum())}" for s in lj.Status
                                          if (status == s).any()))  # fmt: skip
        typer.echo("regime: " + ", ".join(f"{r.name} {int((regime == r).sum())}" for r in lj.Regime
                                          if (regime == r).any()))  # fmt: skip
        speed = np.asarray(ds.mean_speed)
        if np.isfinite(speed).any():
            i = np.unravel_index(int(np.nanargmax(np.abs(speed))), speed.shape)  # forward or backward
            index = dict(zip(axes, i)) if mode == "grid" else dict.fromkeys(axes, i[0])
            at = ", ".join(f"{n}={float(v[index[n]]):.4g}" for n, v in axes.items())
            typer.echo(f"fastest: mean speed {float(speed[i]):.4g} at {at}")
