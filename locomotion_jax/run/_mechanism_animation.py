"""Animation of the bodies of a [`Chain`][locomotion_jax.Chain] or a [`Mechanism`][locomotion_jax.Mechanism]
on their line (SPEC §8, §9), from a `Trajectory` of one configuration.

Each body is a block centred on $x_i$: a body in ground contact stands on the ground, a carried body
is drawn smaller inside its carrier's row, a free body above the ground. A stuck body (the
trajectory's `stuck`) is `STUCK_COLOR` with an anchor under it, a slipping one `SLIP_COLOR`, a body
without ground contact `FREE_COLOR`. Springs are zigzags between their ends (`lj.WALL`: a hatched
wall at $x = 0$). The positions are the saved states, never interpolated.

An optional panel below plots $x_i(t) - x_i(t_0)$ with a moving cursor. The artists carry `gid`s
(`"body0"`, `"body1"`, ..., `"anchor0"`, ..., `"spring0"`, ...) so that tests can read each frame.
"""

import math
from typing import Any, NamedTuple

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from ..model._bodies import Mechanism
from ..model._elements import Spring, TiltedSpring, WALL
from ._animation import SLIP_COLOR, STUCK_COLOR


FREE_COLOR = "#7f7f7f"
"""Colour of a body without ground contact (carried or free)."""


def _zigzag(xa: float, xb: float, y: float, amp: float, coils: int = 6) -> tuple[np.ndarray, np.ndarray]:
    s = np.linspace(0.0, 1.0, 2 * coils + 3)
    off = np.zeros_like(s)
    off[1:-1:2], off[2:-1:2] = amp, -amp
    off[1], off[-2] = 0.0, 0.0
    return xa + s * (xb - xa), y + off


class Drawing(NamedTuple):
    """What the animation draws of a mechanism besides its trajectory (`drawing()` of a
    [`Chain`][locomotion_jax.Chain] or a [`Mechanism`][locomotion_jax.Mechanism]): per body whether it
    touches the ground (`contact`) and whether another body carries it (`carried`), and each
    spring's two ends (body indices, or `lj.WALL`)."""

    contact: list[bool]
    carried: list[bool]
    springs: list[tuple[int | str, int | str]]


def mechanism_drawing(mechanism: Mechanism) -> Drawing:
    """A [`Mechanism`][locomotion_jax.Mechanism]'s bodies and springs (linear and tilted, drawn alike)."""
    return Drawing(
        contact=[law is not None for law in mechanism.friction],
        carried=[c is not None for c in mechanism.carried_by],
        springs=[(el.a, el.b) for el in mechanism.links if isinstance(el, (Spring, TiltedSpring))],
    )


def animate_bodies(
    traj: Any,
    mechanism: Any,
    *,
    index: tuple[int, ...] = (),
    t_range: tuple[float | int, float | int] | None = None,
    max_frames: int = 200,
    interval: float | int = 50.0,
    trace: bool = True,
    figsize: tuple[float | int, float | int] | None = None,
    title: str | None = None,
) -> FuncAnimation:
    """A matplotlib animation of one configuration of a mechanism of bodies on a line (module
    docstring): a [`Chain`][locomotion_jax.Chain] or a [`Mechanism`][locomotion_jax.Mechanism] (its
    `drawing()`).

    **Arguments:** `traj`, a `Trajectory` of `mechanism`; `index`: the configuration of a batch
    (both `traj` and `mechanism` are indexed by it); `t_range`: `(t0, t1)` of the saved times to
    draw (default all); `max_frames`: at most this many frames (a stride over the valid saved
    states); `interval`: ms between frames; `trace`: add the displacement panel; `figsize`, `title`:
    of the figure.

    **Returns:** a `FuncAnimation` on a bare `Figure` (write it with `save_gif`).

    **Raises:** `ValueError` for a batch without its `index`, an `index` that does not fit it, or
    where no saved state is valid in `t_range`.
    """
    index = tuple(index)
    shape = tuple(mechanism.batch_shape)
    if len(index) != len(shape) or any(not (-n <= i < n) for i, n in zip(index, shape)):
        raise ValueError(
            f"animate: one mechanism configuration: index={index!r} must pick one of the batch shape {shape} "
            "(() for one configuration)."
        )
    if max_frames < 1:
        raise ValueError(f"animate: max_frames must be >= 1, got {max_frames}.")
    pick = lambda a: np.asarray(a)[index]
    t, x, stuck = pick(traj.t).astype(np.float64), pick(traj.x).astype(np.float64), pick(traj.stuck).astype(bool)
    if t.ndim != 1:
        raise ValueError(f"animate: the trajectory's batch shape {np.shape(traj.t)[:-1]} is not {shape}.")
    keep = pick(traj.valid).astype(bool)
    if t_range is not None:
        keep &= (t >= t_range[0]) & (t <= t_range[1])
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        raise ValueError(
            f"animate: no valid saved state in t_range={t_range!r} (saved times {t[0]:.4g}..{t[-1]:.4g}; the run "
            "may have stopped before them)."
        )
    frames = idx[:: max(1, math.ceil(idx.size / max_frames))]
    n = x.shape[-1]
    draw_of = mechanism.drawing()
    contact = draw_of.contact
    walled = any(WALL in ends for ends in draw_of.springs)
    span = float(np.ptp(np.concatenate([x[idx].ravel(), [0.0] if walled else []])))
    width = max(0.08 * span, 0.05)
    size = [1.0 if contact[i] or not draw_of.carried[i] else 0.55 for i in range(n)]
    base = [0.0 if contact[i] else (0.2 if draw_of.carried[i] else 1.4) for i in range(n)]
    fig = Figure(figsize=figsize or (6.0, 4.2 if trace else 2.6), layout="constrained")
    ax = fig.add_subplot(2, 1, 1) if trace else fig.add_subplot(1, 1, 1)
    lo, hi = float(x[idx].min()) - 2 * width, float(x[idx].max()) + 2 * width
    if walled:
        lo, hi = min(lo, -2 * width), max(hi, 2 * width)
        ax.fill_between([-width, 0.0], -0.1, 2.0, hatch="///", facecolor="none", edgecolor="k", lw=0.0)
    ax.axhline(0.0, color="k", lw=1.0)
    ax.set_xlim(lo, hi)
    ax.set_ylim(-0.4, 2.2)
    ax.set_yticks([])
    ax.set_xlabel("x")
    if title:
        ax.set_title(title, fontsize="small")
    blocks = []
    for i in range(n):
        h = 0.5 * size[i]
        r = Rectangle((0.0, base[i]), width * size[i], h, gid=f"body{i}", zorder=3 + (not contact[i]))
        ax.add_patch(r)
        blocks.append(r)
    anchors = [ax.plot([], [], "^", color=STUCK_COLOR, ms=6, gid=f"anchor{i}")[0] for i in range(n)]
    springs: list[tuple[tuple[int | str, int | str], Line2D]] = []
    for j, ends in enumerate(draw_of.springs):
        springs.append((ends, ax.plot([], [], "-", color="k", lw=0.8, gid=f"spring{j}")[0]))
    clock = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize="small")
    cursor = None
    if trace:
        axt = fig.add_subplot(2, 1, 2)
        for i in range(n):
            axt.plot(t[idx], x[idx, i] - x[idx[0], i], lw=1.0, label=f"body {i}")
        axt.set_xlabel("t")
        axt.set_ylabel("x_i(t) - x_i(t0)")
        axt.legend(fontsize="x-small", ncol=min(n, 4), loc="upper left")
        cursor = axt.axvline(float(t[frames[0]]), color="k", lw=0.8)

    def end(e: "int | str", row: np.ndarray) -> float:
        return 0.0 if e == WALL else float(row[int(e)])

    def draw(k: int) -> list:
        s = frames[k]
        for i, r in enumerate(blocks):
            r.set_x(x[s, i] - 0.5 * r.get_width())
            r.set_facecolor(STUCK_COLOR if stuck[s, i] else (SLIP_COLOR if contact[i] else FREE_COLOR))
            anchors[i].set_data([x[s, i]] if stuck[s, i] else [], [-0.15] if stuck[s, i] else [])
        for (a, b), line in springs:
            ya = 0.15 if a == WALL else base[int(a)] + 0.12
            line.set_data(*_zigzag(end(a, x[s]), end(b, x[s]), ya, 0.06))
        clock.set_text(f"t = {t[s]:.3f}")
        if cursor is not None:
            cursor.set_xdata([t[s], t[s]])
        return [*blocks, *anchors, *(line for _, line in springs), clock]

    draw(0)
    fig.draw_without_rendering()
    fig.set_layout_engine("none")
    return FuncAnimation(fig, draw, frames=len(frames), init_func=lambda: draw(0), interval=interval, blit=False)
