"""Animation of the two masses and the tilted spring from a [`Trajectory`][], and GIF export.

The scene is drawn to scale (equal aspect): mass $i$ is a block centred on
$x_i$, the spring joins the two centres with the vertical offset $d$ of
eq. (2), so its tilt is the model's. A stuck mass (Sect. 2.2: $v_i = 0$ while
$|F_i| \\le \\mu_s n_i$, eq. 7) is drawn in `STUCK_COLOR` with an anchor under it
and the label "stuck"; a slipping mass in `SLIP_COLOR`. Positions are the saved
states, never interpolated, so a stuck mass stands exactly still in the frames.

An optional panel below the scene plots $x_i(t) - x_i(t_0)$ with a moving
cursor and the stuck intervals in `STUCK_COLOR`, so the staircase of stick-slip
motion is visible even when the steps are small against the spring's length.

[`animate`][] takes any mechanism, each drawing itself (`AbstractMechanism.animation`): this
module's scene for the paper's model, `_mechanism_animation` for the bodies of a chain or a
mechanism.

Matplotlib objects only (no pyplot state): the figure is a bare `Figure`, so a
notebook shows the animation once (`HTML(anim.to_jshtml())`), not a stray still.
The artists carry `gid`s (`"mass1"`, `"mass2"`, `"anchor1"`, `"anchor2"`,
`"spring"`) so that tests can read what each frame drew.
"""

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from .._results import Trajectory
from .._status import Mode
from ..model._params import Params
from ._batch import mechanism_arg


STUCK_COLOR = "#d62728"
"""Colour of a stuck mass (and of stuck intervals in the trace panel)."""
SLIP_COLOR = "#1f77b4"
"""Colour of a slipping mass."""

_MODE_TEXT = {
    Mode.BOTH_STICK: "both stuck",
    Mode.BOTH_SLIP: "both slip",
    Mode.M1_SLIPS: "m1 slips, m2 stuck",
    Mode.M2_SLIPS: "m1 stuck, m2 slips",
}

_HEIGHT = 1.0  # block height (the masses are points in the model; the blocks are drawn for legibility)


def stuck_masks(mode: Any) -> tuple[np.ndarray, np.ndarray]:
    """Boolean arrays `(stuck1, stuck2)` from the mode codes of Sect. 2.2 ([`Mode`][])."""
    mode = np.asarray(mode)
    stuck1 = (mode == Mode.BOTH_STICK) | (mode == Mode.M2_SLIPS)
    stuck2 = (mode == Mode.BOTH_STICK) | (mode == Mode.M1_SLIPS)
    return stuck1, stuck2


def _select(traj: Trajectory, index: tuple[int, ...]) -> dict[str, np.ndarray]:
    data = traj.to_numpy()
    batch = data["t"].shape[:-1]
    if len(index) != len(batch):
        raise ValueError(
            f"animate: the trajectory has batch shape {batch}; pass index= with {len(batch)} integer(s) "
            f"to pick one configuration (got index={index!r})."
        )
    return {k: (v[index] if np.ndim(v) >= len(batch) else v) for k, v in data.items()}


def _spring_xy(xa: float, ya: float, xb: float, yb: float, coils: int, width: float) -> tuple[np.ndarray, ...]:
    """A zig-zag from (xa, ya) to (xb, yb): straight leads, `coils` teeth of fixed `width`."""
    dx, dy = xb - xa, yb - ya
    length = math.hypot(dx, dy)
    ux, uy = dx / length, dy / length
    s = np.concatenate([[0.0, 0.15], np.linspace(0.15, 0.85, 2 * coils + 1)[1:-1], [0.85, 1.0]]) * length
    n = np.zeros_like(s)
    n[2:-2] = width * np.where(np.arange(2 * coils - 1) % 2 == 0, 1.0, -1.0)
    return xa + s * ux - n * uy, ya + s * uy + n * ux


class _Scene:
    """The artists of one animation and how frame `i` sets them."""

    def __init__(self, data: dict, params: Params, frames: np.ndarray, fig: Figure, trace: bool, title: str | None):
        p = {k: float(np.asarray(v)) for k, v in params.as_dict().items()}
        self.d = p["d"]
        m1, m2 = 2 * p["mhat"], 2 * (1 - p["mhat"])
        # Block widths grow with the square root of the mass, so mhat is visible.
        self.w1, self.w2 = 0.5 * math.sqrt(m1), 0.5 * math.sqrt(m2)
        self.h = max(_HEIGHT, abs(self.d) + 0.4)
        # Attachment heights: m2's end of the spring sits d above m1's (eq. 2; d > 0
        # lifts m1 and presses m2 down when the spring is stretched, eq. 5).
        self.y1 = self.h / 2 - self.d / 2
        self.y2 = self.h / 2 + self.d / 2
        self.t, self.x1, self.x2 = data["t"], data["x1"], data["x2"]
        self.mode = data["mode"].astype(int)
        self.stuck1, self.stuck2 = stuck_masks(self.mode)
        self.X = data["X"]
        self.frames = frames

        if trace:
            ax, axt = fig.subplots(2, 1, height_ratios=[1.7, 1])
        else:
            ax, axt = fig.subplots(1, 1), None
        self.ax, self.axt = ax, axt
        sel = frames
        lo = min(self.x1[sel].min() - self.w1, self.x2[sel].min() - self.w2) - 0.3
        hi = max(self.x1[sel].max() + self.w1, self.x2[sel].max() + self.w2) + 0.3
        ax.set_xlim(lo, hi)
        ax.set_ylim(-0.45, self.h + 0.55)
        ax.set_aspect("equal")
        ax.set_yticks([])
        ax.spines[["left", "right", "top"]].set_visible(False)
        ax.set_xlabel("x (dimensionless)", labelpad=1)
        # Ground with ticks every 0.1: steps of a few hundredths are visible against them.
        ax.add_patch(Rectangle((lo, -0.2), hi - lo, 0.2, facecolor="0.92", edgecolor="none", hatch="////", zorder=0))
        ax.axhline(0.0, color="0.3", lw=1.0, zorder=1)
        ticks = np.arange(math.floor(lo * 10), math.ceil(hi * 10) + 1) / 10
        ax.vlines(ticks, -0.06, 0.0, color="0.4", lw=0.6, zorder=1)

        self.spring = Line2D([], [], color="0.15", lw=1.4, zorder=2, gid="spring", solid_joinstyle="miter")
        ax.add_line(self.spring)
        self.box1 = Rectangle((0, 0), self.w1, self.h, ec="k", lw=1.0, zorder=3, gid="mass1")
        self.box2 = Rectangle((0, 0), self.w2, self.h, ec="k", lw=1.0, zorder=3, gid="mass2")
        ax.add_patch(self.box1)
        ax.add_patch(self.box2)
        style: dict[str, Any] = dict(marker="^", ms=9, color=STUCK_COLOR, mec="k", mew=0.8, ls="none", zorder=4)
        self.anchor1 = Line2D([], [], gid="anchor1", **style)
        self.anchor2 = Line2D([], [], gid="anchor2", **style)
        ax.add_line(self.anchor1)
        ax.add_line(self.anchor2)
        label: dict[str, Any] = dict(
            ha="center", va="bottom", fontsize=8, color=STUCK_COLOR, fontweight="bold", zorder=4
        )
        self.label1 = ax.text(0, self.h + 0.05, "stuck", gid="label1", **label)
        self.label2 = ax.text(0, self.h + 0.05, "stuck", gid="label2", **label)
        self.names = (
            ax.text(0, self.h / 2, "m1", ha="center", va="center", fontsize=8, color="w", zorder=5),
            ax.text(0, self.h / 2, "m2", ha="center", va="center", fontsize=8, color="w", zorder=5),
        )
        self.clock = ax.set_title(" ", loc="left", fontsize=8, family="monospace")
        if title:
            fig.suptitle(title, fontsize=9)

        self.cursor = None
        if axt is not None:
            self._trace(axt)

    def _trace(self, axt: Axes) -> None:
        """$x_i(t) - x_i(t_0)$ over the animated span, stuck intervals in the stuck colour."""
        f = self.frames
        t = self.t[f[0] : f[-1] + 1]
        for k, (x, stuck, name) in enumerate(((self.x1, self.stuck1, "m1"), (self.x2, self.stuck2, "m2"))):
            rel = x[f[0] : f[-1] + 1] - x[f[0]]
            axt.plot(t, rel, color="0.55" if k == 0 else "0.2", lw=1.0, label=f"$x_{k + 1} - x_{k + 1}(t_0)$")
            s = stuck[f[0] : f[-1] + 1]
            axt.plot(t, np.where(s, rel, np.nan), color=STUCK_COLOR, lw=2.2, solid_capstyle="butt")
        axt.plot([], [], color=STUCK_COLOR, lw=2.2, label="stuck")
        axt.set_xlim(t[0], t[-1])
        axt.set_xlabel("t", labelpad=1)
        axt.set_ylabel("displacement", fontsize=8)
        axt.tick_params(labelsize=7)
        axt.legend(fontsize=7, frameon=False, loc="upper left", ncols=3)
        self.cursor = axt.axvline(t[0], color="k", lw=0.8)

    def draw(self, i: int) -> list:
        j = int(self.frames[i])
        x1, x2 = float(self.x1[j]), float(self.x2[j])
        s1, s2 = bool(self.stuck1[j]), bool(self.stuck2[j])
        self.box1.set_x(x1 - self.w1 / 2)
        self.box2.set_x(x2 - self.w2 / 2)
        self.box1.set_facecolor(STUCK_COLOR if s1 else SLIP_COLOR)
        self.box2.set_facecolor(STUCK_COLOR if s2 else SLIP_COLOR)
        self.spring.set_data(*_spring_xy(x1, self.y1, x2, self.y2, coils=9, width=0.09))
        for anchor, label, x, s in ((self.anchor1, self.label1, x1, s1), (self.anchor2, self.label2, x2, s2)):
            anchor.set_data([x], [-0.12])
            anchor.set_visible(s)
            label.set_x(x)
            label.set_visible(s)
        self.names[0].set_x(x1)
        self.names[1].set_x(x2)
        self.clock.set_text(f"t = {self.t[j]:7.3f}   X = {self.X[j]:+.4f}   {_MODE_TEXT[Mode(self.mode[j])]}")
        out = [
            self.box1,
            self.box2,
            self.spring,
            self.anchor1,
            self.anchor2,
            self.label1,
            self.label2,
            *self.names,
            self.clock,
        ]
        if self.cursor is not None:
            self.cursor.set_xdata([self.t[j], self.t[j]])
            out.append(self.cursor)
        return out


def animate(
    traj: Trajectory,
    params: Any,
    *,
    index: tuple[int, ...] = (),
    t_range: tuple[float | int, float | int] | None = None,
    max_frames: int = 200,
    interval: float | int = 50.0,
    trace: bool = True,
    figsize: tuple[float | int, float | int] | None = None,
    title: str | None = None,
) -> FuncAnimation:
    """A matplotlib animation of a trajectory of any mechanism: the paper's model's two masses and
    tilted spring ([`animate_paper`][]), or the bodies and springs of a [`Chain`][] or a
    [`Mechanism`][locomotion_jax.Mechanism] on their line (`run._mechanism_animation.animate_bodies`:
    a stuck body red with an anchor under it, a slipping one blue, a body without ground contact
    grey). Each mechanism draws itself (`AbstractMechanism.animation`).

    **Arguments:** as [`animate_paper`][] (`params`: the mechanism that produced `traj`; `figsize`:
    each drawing's own where `None`).

    **Returns:** a `matplotlib.animation.FuncAnimation` on a bare `Figure` (no pyplot).

    **Raises:** `ValueError` for a batch without its `index`, an `index` that does not fit, or no
    valid saved state in `t_range`.

    !!! Example

        ```python
        worm = Chain(masses=[1.0] * 4, d=0.0, waveforms=TravellingWave(0.1, 2.0, 0.785))
        traj = simulate(worm, 30.0, save_at=np.linspace(20, 30, 100))
        save_gif(animate(traj, worm), "worm.gif", dpi=60)
        ```
    """
    options = dict(index=index, t_range=t_range, max_frames=max_frames, interval=interval, trace=trace,
                   figsize=figsize, title=title)  # fmt: skip
    return mechanism_arg(params).animation(traj, **options)


def animate_paper(
    traj: Trajectory,
    params: Params,
    *,
    index: tuple[int, ...] = (),
    t_range: tuple[float | int, float | int] | None = None,
    max_frames: int = 200,
    interval: float | int = 50.0,
    trace: bool = True,
    figsize: tuple[float | int, float | int] | None = None,
    title: str | None = None,
) -> FuncAnimation:
    """A matplotlib animation of the two masses and the tilted spring of the paper's model.

    Frame $k$ draws the saved state $k$ of `traj` (a stride is taken when there
    are more than `max_frames` saved states in `t_range`). Masses are blocks
    centred on $x_1, x_2$; the spring joins them with the vertical offset $d$
    (eq. 2); a stuck mass (modes of Sect. 2.2) is red with an anchor under it,
    a slipping one blue. Saved times after the run stopped (`traj.valid` False,
    e.g. at lift-off) are not animated.

    For a smooth animation, save the trajectory at the frame times, e.g.
    `simulate(p, t_end, save_at=np.linspace(t0, t_end, 120))`.

    **Arguments:**

    - `traj`: from [`simulate`][]; for a batch, pick one configuration with `index`.
    - `params`: the configuration that produced `traj` (for $d$ and the masses).
    - `index`: batch index of the configuration to draw (`()` for a single one).
    - `t_range`: `(t0, t1)` to animate; default all saved times.
    - `max_frames`: upper bound on the number of frames.
    - `interval`: delay between frames in ms (the GIF's and the HTML player's speed).
    - `trace`: add the panel of $x_i(t) - x_i(t_0)$ with a cursor and stuck intervals.
    - `figsize`, `title`: of the figure (`figsize` default `(5.6, 3.8)`).

    **Returns:** a `matplotlib.animation.FuncAnimation` on a bare `Figure` (no
    pyplot); show it with `IPython.display.HTML(anim.to_jshtml())` or write it with [`save_gif`][].

    **Raises:** `ValueError` if `params` is a batch, `index` does not fit the
    batch shape, or no valid saved state falls in `t_range`.

    !!! Example

        ```python
        p = Params(omega=2.0)
        traj = simulate(p, 20.0, save_at=np.linspace(10, 20, 100))
        anim = animate(traj, p)
        save_gif(anim, "ssl.gif", dpi=60)
        ```
    """
    if params.batch_shape != ():
        raise ValueError(
            f"animate: params must be one configuration, got batch shape {params.batch_shape}; "
            "pass params[index] together with index=."
        )
    if max_frames < 1:
        raise ValueError(f"animate: max_frames must be >= 1, got {max_frames}.")
    data = _select(traj, tuple(index))
    t = data["t"]
    keep = np.asarray(data["valid"], bool).copy()
    if t_range is not None:
        keep &= (t >= t_range[0]) & (t <= t_range[1])
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        valid = t[np.asarray(data["valid"], bool)]
        upto = f"valid up to t = {valid[-1]:.4g}" if valid.size else "none valid: the run stopped before them"
        raise ValueError(
            f"animate: no valid saved state in t_range={t_range!r} (saved times {t[0]:.4g}..{t[-1]:.4g}, {upto})."
        )
    stride = max(1, math.ceil(idx.size / max_frames))
    frames = idx[::stride]
    fig = Figure(figsize=figsize or (5.6, 3.8), layout="constrained")
    scene = _Scene(data, params, frames, fig, trace, title)
    scene.draw(0)
    # Lay the figure out once: the constrained layout would otherwise be solved
    # again for every frame (most of the cost of writing a GIF).
    fig.draw_without_rendering()
    fig.set_layout_engine("none")
    return FuncAnimation(
        fig, scene.draw, frames=len(frames), init_func=lambda: scene.draw(0), interval=interval, blit=False, repeat=True
    )


def save_gif(anim: FuncAnimation, path: str | os.PathLike, *, fps: float | int = 20.0, dpi: float | int = 80) -> Path:
    """Write `anim` as an animated GIF with matplotlib's `PillowWriter` (no ffmpeg needed).

    **Arguments:**

    - `anim`: from [`animate`][].
    - `path`: output file (parent directories are created).
    - `fps`: frames per second of the GIF.
    - `dpi`: resolution; 60-80 keeps a GIF of ~100 frames around a few hundred kB.

    **Returns:** the path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # matplotlib's stubs say `fps: int`; the writer takes any positive number (frame duration 1000/fps ms).
    anim.save(path, writer=PillowWriter(fps=fps), dpi=dpi)  # pyright: ignore[reportArgumentType]
    return path
