"""Shared pieces of the figure reproductions: the sweep call, verdicts, small analyses.

The figures' grids run through [`locomotion_jax.sweep`][] (one `xarray.Dataset`,
one dimension per swept parameter, one variable per `Measurement` field).
"""

import dataclasses
from collections.abc import Mapping
from typing import Any, TypedDict

import numpy as np
import xarray as xr

from .._custom_types import Contact, Start
from ..dynamics._exact_dynamics import Exact
from ..maps._sweep import sweep
from ..model._params import DEFAULTS, Params


class Reading(TypedDict):
    """The `contact` and `start` arguments of [`simulate`][], [`measure`][] and [`sweep`][]."""

    contact: Contact
    start: Start


PAPER: Reading = {"contact": "paper", "start": "paper"}
"""Every reproduction uses the paper's $n_i = |N_i|$ reading (lift-off flagged, not
stopped) and the paper's initial condition, eq. (14) (SPEC §1)."""


@dataclasses.dataclass
class Verdict:
    """What a figure's data says about the paper's claim.

    - `holds`: `"yes"`, `"partly"` or `"no"`.
    - `lines`: the evidence, one short sentence with numbers each.
    - `differences`: where and why we differ from the paper.
    - `facts`: named booleans behind `holds` (used by the tests).
    """

    holds: str
    lines: list[str]
    differences: list[str] = dataclasses.field(default_factory=list)
    facts: dict[str, bool] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_facts(cls, facts: Mapping[str, Any], lines, differences=()) -> "Verdict":
        n_ok = sum(bool(v) for v in facts.values())
        holds = "yes" if n_ok == len(facts) else ("no" if n_ok == 0 else "partly")
        return cls(holds, list(lines), list(differences), {k: bool(v) for k, v in facts.items()})

    @property
    def summary(self) -> str:
        return f"{self.holds}: " + "; ".join(self.lines)


def yes(flag: Any) -> str:
    return "yes" if bool(flag) else "no"


# -- sweeps ------------------------------------------------------------------------


def run_sweep(
    axes: Mapping[str, Any],
    *,
    fixed: Mapping[str, float] | None = None,
    z: float = 5.0,
    horizon: float = 2000.0,
    window: float = 25.0,
    dt: float = 0.01,
    max_steps: int | None = None,
    chunk_size: int = 4096,
    progress: bool = False,
) -> xr.Dataset:
    """Measure a grid of configurations under the paper's reading (`PAPER`).

    Runs [`locomotion_jax.sweep`][] in chunks of `chunk_size` configurations.
    `max_steps` overrides the engine's step cap (`None`: its default from the horizon).
    """
    axes = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in axes.items()}
    kwargs: dict[str, Any] = dict(
        fixed=dict(fixed or {}),
        z=z,
        horizon=horizon,
        window=window,
        dynamics=Exact(dt, max_steps),
        chunk_size=chunk_size,
        **PAPER,
    )
    ds = sweep(axes, **kwargs, path=None, progress=progress)
    ds.attrs["engine"] = "locomotion_jax.sweep"
    ds.attrs.update(dynamics="exact", dt=float(dt), z=float(z), horizon=float(horizon), window=float(window), **PAPER)
    return ds


def steady_liftoff(
    ds: xr.Dataset,
    fixed: Mapping[str, float] | None = None,
    *,
    dt: float = 0.01,
    window: float = 5.0,
    n_save: int = 201,
    chunk: int = 256,
    stride: int = 1,
) -> xr.Dataset:
    """Add `min_normal` and `liftoff_steady` to a sweep dataset.

    `liftoff` flags any zero crossing of a normal force, and with the pre-stretched
    start of eq. (14) most of them happen in the first time unit (SPEC §1). For each
    flagged configuration this re-simulates the paper-reading trajectory and takes the
    lowest signed normal force (eq. 5) over `[t_s, t_s + window]` (`t_s` the largest
    `t_start` of the batch; saved every `window / (n_save - 1)`): `liftoff_steady` is
    True where it is <= 0, i.e. where the steady motion itself leaves the ground.

    `stride > 1` re-simulates only every `stride`-th configuration along each axis and
    gives every flagged configuration the verdict of its nearest re-simulated one
    (each re-simulation runs its configuration again from $t = 0$).
    """
    from ..run._simulate import simulate

    dims = list(ds.liftoff.dims)
    lift = np.asarray(ds.liftoff.values, bool)
    coarse = np.zeros_like(lift)
    coarse[tuple(slice(None, None, stride) for _ in dims)] = True
    min_n = np.full(lift.shape, np.nan)
    idx = np.argwhere(lift & coarse)
    if idx.size:
        values: dict[str, Any] = {d: ds[d].values[idx[:, k]] for k, d in enumerate(dims)}
        fixed_values: dict[str, Any] = dict(fixed or {})
        params = Params(**values, **fixed_values)
        t = float(np.max(np.asarray(params.t_start))) + np.linspace(0.0, window, n_save)
        n, out = len(idx), []
        for lo in range(0, n, chunk):
            # Every call has `chunk` rows, NaN past the configurations (flagged invalid and not run):
            # one compiled program for every figure and batch.
            rows = np.arange(lo, lo + chunk)
            part = {k: np.where(rows < n, v[np.minimum(rows, n - 1)], np.nan) for k, v in values.items()}
            tr = simulate(Params(**part, **fixed_values, check=False), float(t[-1]), t, dynamics=Exact(dt), **PAPER)
            low = np.minimum(np.asarray(tr.N1), np.asarray(tr.N2)).min(axis=-1)
            out.append(low[: min(chunk, n - lo)])
        min_n[tuple(idx.T)] = np.concatenate(out)
    steady = np.nan_to_num(min_n, nan=1.0) <= 0
    if stride > 1:  # nearest re-simulated neighbour
        near = tuple(
            np.minimum((np.rint(np.arange(s) / stride) * stride).astype(int), (s - 1) // stride * stride)
            for s in lift.shape
        )
        steady = lift & steady[np.ix_(*near)]
    ds["min_normal"] = (
        dims,
        min_n,
        {
            "description": f"lowest normal force over [t_s, t_s + {window:g}] "
            "(re-simulated lift-off configurations only)"
        },
    )
    ds["liftoff_steady"] = (dims, steady)
    ds.attrs["steady_check"] = (
        f"lowest normal force over [t_s, t_s + {window:g}] sampled every "
        f"{window / (n_save - 1):.3g}"
        + (f", every {stride}th configuration per axis (nearest neighbour)" if stride > 1 else "")
    )
    return ds


def liftoff_summary(ds: xr.Dataset) -> str:
    """`'N of M configurations lift off; K of them only in the start transient'`."""
    lift = np.asarray(ds.liftoff.values, bool)
    if "liftoff_steady" not in ds:
        return f"{lift.sum()} of {lift.size} configurations lift off"
    steady = np.asarray(ds.liftoff_steady.values, bool)
    return (
        f"{lift.sum()} of {lift.size} configurations lift off, {(lift & ~steady).sum()} of them only in the "
        f"start transient (the steady motion keeps contact)"
    )


def describe_params(fixed: Mapping[str, float], swept: Any = ()) -> str:
    """`k=50, c=0.01, ...`: the parameters held fixed (paper defaults unless given)."""
    values = {**DEFAULTS, **fixed}
    return ", ".join(f"{k}={values[k]:g}" for k in DEFAULTS if k not in swept)


def describe_axis(name: str, values: np.ndarray) -> str:
    values = np.asarray(values)
    if values.size <= 6:
        return f"{name} in {{{', '.join(f'{v:g}' for v in values)}}}"
    return f"{name}: {values.size} values in [{values.min():g}, {values.max():g}]"


# -- small analyses -----------------------------------------------------------------


def local_minima(y: np.ndarray, depth: float = 0.0) -> np.ndarray:
    """Indices of interior local minima of `y` (non-finite values never qualify).

    With `depth > 0` a minimum must lie at least that fraction below the highest
    value between it and the nearest lower point on each side (a simple prominence).
    """
    y = np.asarray(y, dtype=float)
    out = []
    for i in range(1, y.size - 1):
        if not (np.isfinite(y[i]) and y[i] <= y[i - 1] and y[i] < y[i + 1]):
            continue
        if depth > 0:
            rises = []
            for side in (y[i - 1 :: -1], y[i + 1 :]):
                lower = np.flatnonzero(side < y[i])
                seg = side[: lower[0]] if lower.size else side
                seg = np.where(np.isfinite(seg), seg, np.inf)
                rises.append(seg.max() if seg.size else y[i])
            if min(rises) < y[i] * (1 + depth):
                continue
        out.append(i)
    return np.asarray(out, dtype=int)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive index ranges `(i, j)` of the True runs of a 1-D mask."""
    mask = np.asarray(mask, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[False], mask, [False]]).astype(int)))
    return [(int(i), int(j) - 1) for i, j in zip(edges[::2], edges[1::2])]


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation of the finite pairs (no scipy needed)."""
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return float("nan")
    rx, ry = np.argsort(np.argsort(x[ok])), np.argsort(np.argsort(y[ok]))
    return float(np.corrcoef(rx, ry)[0, 1])
