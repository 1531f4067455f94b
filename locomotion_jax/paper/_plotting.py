"""Matplotlib helpers shared by the figure reproductions (Agg canvas, no pyplot state).

One visual language for every figure: SSL ranges shaded light blue, lift-off
configurations (outside the model's validity, SPEC §1) hatched or drawn as grey
crosses, "z not reached within the horizon" as triangles on the top edge, and
natural frequencies as dotted lines.
"""

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.transforms import blended_transform_factory

from ._figtools import runs


SSL_COLOR = "#cfe3f7"
LIFTOFF_COLOR = "0.45"
TRANSIENT_COLOR = "0.7"  # lift-off only in the start transient (steady motion keeps contact)
WN_STYLE: dict[str, Any] = dict(color="0.25", linestyle=":", linewidth=1.0)


def new_figure(nrows: int = 1, ncols: int = 1, *, size=(6.4, 4.0), **kwargs) -> tuple[Figure, np.ndarray]:
    """A `Figure` on the Agg canvas and its axes as a 2-D array."""
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    return fig, axes


def save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=130)
    return path


def _edges(x: np.ndarray, i: int, j: int) -> tuple[float, float]:
    """Span of samples i..j extended half a spacing on each side."""
    lo = x[i] - (x[i] - x[i - 1]) / 2 if i > 0 else x[i]
    hi = x[j] + (x[j + 1] - x[j]) / 2 if j < x.size - 1 else x[j]
    return lo, hi


def shade_ssl(ax: Axes, x: np.ndarray, ssl: np.ndarray) -> None:
    """Light-blue bands over the x ranges classified SSL (paper's window rule)."""
    x = np.asarray(x)
    for i, j in runs(ssl):
        ax.axvspan(*_edges(x, i, j), color=SSL_COLOR, zorder=0, linewidth=0)


def hatch_liftoff(ax: Axes, x: np.ndarray, liftoff: np.ndarray, steady: np.ndarray | None = None) -> None:
    """Hatched bands over the x ranges where a normal force reached zero: `///` where the
    steady motion loses contact (or always, without `steady`), `...` where only the start
    transient does."""
    x = np.asarray(x)
    liftoff = np.asarray(liftoff, bool)
    steady = liftoff if steady is None else np.asarray(steady, bool) & liftoff
    for mask, hatch, color in ((steady, "///", LIFTOFF_COLOR), (liftoff & ~steady, "...", TRANSIENT_COLOR)):
        for i, j in runs(mask):
            ax.axvspan(*_edges(x, i, j), facecolor="none", edgecolor=color, hatch=hatch, linewidth=0, zorder=0.5)


def mark_liftoff(
    ax: Axes, x: np.ndarray, y: np.ndarray, liftoff: np.ndarray, steady: np.ndarray | None = None, size: float = 6
) -> None:
    """Grey crosses on configurations whose steady motion loses contact (all lift-offs
    without `steady`), light-grey pluses where only the start transient does."""
    x, y, liftoff = np.asarray(x), np.asarray(y), np.asarray(liftoff, bool)
    steady = liftoff if steady is None else np.asarray(steady, bool) & liftoff
    for mask, marker, color in ((steady, "x", LIFTOFF_COLOR), (liftoff & ~steady, "+", TRANSIENT_COLOR)):
        m = mask & np.isfinite(y)
        if m.any():
            ax.plot(x[m], y[m], marker, color=color, markersize=size, zorder=5)


def mark_unreached(ax: Axes, x: np.ndarray, reached: np.ndarray, color="k") -> None:
    """Triangles on the top edge where `z` was not reached within the horizon."""
    m = ~np.asarray(reached, bool)
    if m.any():
        tr = blended_transform_factory(ax.transData, ax.transAxes)
        ax.plot(
            np.asarray(x)[m],
            np.full(m.sum(), 0.985),
            "v",
            color=color,
            markersize=4,
            transform=tr,
            clip_on=False,
            zorder=6,
        )


def vlines(ax: Axes, where: dict[str, float], *, text=True) -> None:
    """Dotted vertical lines labelled at the top (natural frequencies, thresholds)."""
    tr = blended_transform_factory(ax.transData, ax.transAxes)
    for label, x in where.items():
        ax.axvline(x, **WN_STYLE, zorder=1)
        if text:
            ax.text(x, 1.01, label, transform=tr, ha="center", va="bottom", fontsize=8)


def legend_extras(ssl=True, liftoff=True, unreached=True, hatched=False) -> list:
    """Proxy artists for the shared markings, to append to a legend."""
    from matplotlib.lines import Line2D

    items = []
    if ssl:
        items.append(Patch(color=SSL_COLOR, label="SSL (a mass sticks)"))
    if liftoff:
        if hatched:
            items.append(
                Patch(
                    facecolor="none",
                    edgecolor=LIFTOFF_COLOR,
                    hatch="///",
                    label="lift-off, steady motion (invalid; grey curve)",
                )
            )
            items.append(
                Patch(
                    facecolor="none",
                    edgecolor=TRANSIENT_COLOR,
                    hatch="...",
                    label="lift-off in start transient only (invalid)",
                )
            )
        else:
            items.append(
                Line2D([], [], marker="x", linestyle="", color=LIFTOFF_COLOR, label="lift-off, steady motion (invalid)")
            )
            items.append(
                Line2D(
                    [],
                    [],
                    marker="+",
                    linestyle="",
                    color=TRANSIENT_COLOR,
                    label="lift-off, start transient only (invalid)",
                )
            )
    if unreached:
        items.append(Line2D([], [], marker="v", linestyle="", color="k", markersize=4, label="z not reached"))
    return items


def finite_or_nan(y: np.ndarray) -> np.ndarray:
    y = np.asarray(y, dtype=float)
    return np.where(np.isfinite(y), y, np.nan)
