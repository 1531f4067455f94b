"""`locomotion-jax animate`: a GIF of the two masses and the tilted spring.

`register(app)` adds the subcommand to a `typer.Typer` app (the main CLI in
`_main.py` calls it; the global `--x64` flag is handled there, before any JAX
array exists). Example: `locomotion-jax animate --omega 2 --t-from 30 --t-end 36 --out ssl.gif`.
"""

import math
from pathlib import Path
from typing import Any

import typer

from ._errors import friendly
from ._mechanism import build, mechanism_options
from ._options import expand, run_options, Values


def register(app: typer.Typer) -> None:
    """Add the `animate` subcommand to `app`."""

    @app.command("animate")
    @friendly
    @expand(mech=mechanism_options(), run=run_options(("contact", "start", "dt")))
    def animate(
        file: Path | None = typer.Argument(None, help="A mechanism file (TOML), instead of the mechanism options."),
        *,
        mech: Values,
        t_from: float | None = typer.Option(
            None, "--t-from", help="First animated time (default: two actuation periods before --t-end)."
        ),
        t_end: float = typer.Option(40.0, "--t-end", help="Last animated time (the simulation runs from t = 0)."),
        frames: int = typer.Option(60, "--frames", help="Number of frames (states saved evenly in the span)."),
        fps: float = typer.Option(12.0, "--fps", help="Frames per second of the GIF."),
        dpi: float = typer.Option(60.0, "--dpi", help="Resolution of the GIF."),
        trace: bool = typer.Option(True, "--trace/--no-trace", help="Add the panel of displacements vs time."),
        run: Values,
        out: Path = typer.Option(Path("animation.gif"), "--out", help="Output GIF file."),
    ) -> None:
        """Simulate one configuration on the exact model and write an animated GIF of it.

        Stuck masses are drawn red with an anchor under them, slipping ones blue. The mechanism is
        the paper's model (its options, or a FILE with its waveform if it has one), a chain
        (`--masses`) or a mechanism FILE; a chain or a mechanism of bodies and links is drawn as its
        bodies (carried ones grey, inside their carrier's row) and springs, and the command prints
        how many frames each body is stuck in.
        """

        import numpy as np

        from ..dynamics._exact_dynamics import Exact
        from ..run._animation import animate as animate_fn, save_gif, stuck_masks
        from ..run._simulate import simulate

        try:
            built = build(mech, file)
            params, wave = built.mechanism, built.extra.get("waveform")
            if built.kind != "paper":
                return _animate_bodies(built, t_from, t_end, frames, fps, dpi, trace, run, out)
            w = float(params.omega if wave is None else wave.omega)
            t_from = _check_span(w, t_from, t_end, frames, fps, dpi, out)
            traj = simulate(
                params,
                t_end,
                np.linspace(t_from, t_end, frames),
                dynamics=Exact(dt=run["dt"]),
                contact=run["contact"],
                start=run["start"],
                **({} if wave is None else {"waveform": wave}),
            )
            if not np.asarray(traj.valid).any():
                raise ValueError(
                    f"lift-off at t = {float(np.asarray(traj.t_liftoff)):.4g}, before the animated span "
                    f"({t_from:.4g}..{t_end:.4g}): the model stops applying there (a normal force reached zero). "
                    "Animate an earlier span (--t-from, --t-end), or use --contact paper to integrate through it."
                )
            a, d, mhat = (float(getattr(params, n)) for n in ("a", "d", "mhat"))
            shape = f"a = {a:g}" if wave is None else f"{type(wave).__name__} waveform"
            title = f"omega = {w:.4g} ({w / float(params.wn1):.3g} wn1), {shape}, d = {d:g}, mhat = {mhat:g}"
            anim = animate_fn(traj, params, max_frames=frames, interval=1000.0 / fps, trace=trace, title=title)
            path = save_gif(anim, out, fps=fps, dpi=dpi)
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(code=2) from None
        valid = np.asarray(traj.valid)
        s1, s2 = (s[valid] for s in stuck_masks(traj.mode))
        typer.echo(
            f"wrote {path} ({int(valid.sum())} frames, t = {t_from:.4g}..{t_end:.4g}); "
            f"m1 stuck in {int(s1.sum())} frames, m2 stuck in {int(s2.sum())} frames"
        )
        if bool(np.asarray(traj.liftoff)):
            typer.echo(
                f"warning: lift-off at t = {float(np.asarray(traj.t_liftoff)):.4g} (the model no longer "
                "applies; frames after it are not drawn)",
                err=True,
            )


def _animate_bodies(built: Any, t_from: float | None, t_end: float, frames: int, fps: float, dpi: float,
                    trace: bool, run: Values, out: Path) -> None:  # fmt: skip
    """`animate` of a chain or a mechanism of bodies and links: `lj.simulate` at the frame times,
    drawn by `lj.animate` (the bodies on their line)."""

    import numpy as np

    from ..dynamics._exact_dynamics import Exact
    from ..run._animation import animate, save_gif
    from ..run._simulate import simulate

    mech = built.mechanism
    try:
        w = float(built.omega)
        t_from = _check_span(w, t_from, t_end, frames, fps, dpi, out)
        traj = simulate(mech, t_end, np.linspace(t_from, t_end, frames), dynamics=Exact(dt=run["dt"]),
                        contact=run["contact"], start=run["start"])  # fmt: skip
        if not np.asarray(traj.valid).any():
            raise ValueError(f"the run stopped (status {int(np.asarray(traj.status))}) before the animated span.")
        what = built.head if built.file is None else f"{built.file.name}: {np.shape(traj.x)[-1]} bodies"
        title = f"{what}, omega = {w:.4g}" if built.file is not None else what
        anim = animate(traj, mech, max_frames=frames, interval=1000.0 / fps, trace=trace, title=title)
        path = save_gif(anim, out, fps=fps, dpi=dpi)
    except ValueError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(code=2) from None
    valid = np.asarray(traj.valid, bool)
    stuck = np.asarray(traj.stuck, bool)[valid]
    counts = ", ".join(f"body {i} stuck in {int(stuck[:, i].sum())}" for i in range(stuck.shape[-1]))
    typer.echo(f"wrote {path} ({int(valid.sum())} frames, t = {t_from:.4g}..{t_end:.4g}); {counts} frames")


def _check_span(w: float, t_from: float | None, t_end: float, frames: int, fps: float, dpi: float, out: Path) -> float:
    """Check the animation's options; return `t_from` (default: the last two periods of frequency `w`)."""
    if not (math.isfinite(t_end) and t_end > 0):
        raise ValueError(f"--t-end must be a finite number > 0, got {t_end!r}.")
    if t_from is None:
        t_from = max(0.0, t_end - 2 * (2 * math.pi / w)) if w > 0 else 0.0
    if not (0 <= t_from < t_end):
        raise ValueError(f"--t-from must satisfy 0 <= t_from < t_end, got {t_from!r} (t_end = {t_end!r}).")
    if frames < 2:
        raise ValueError(f"--frames must be >= 2, got {frames}.")
    if not (math.isfinite(fps) and fps > 0 and math.isfinite(dpi) and dpi > 0):
        raise ValueError(f"--fps and --dpi must be finite numbers > 0, got {fps!r} and {dpi!r}.")
    if out.suffix.lower() != ".gif":
        raise ValueError(f"--out must name a .gif file, got {str(out)!r}.")
    return t_from
