"""Exact-model figures of merit, the sinusoid baseline and Pareto fronts (SPEC §7).

Everything here is judged on the **steady gait** of the exact hybrid engine
([`steady_gait`][]: strict contact, from the relaxed spring, a transient and then
Newton's method on the period map), so optimised waveforms and sinusoids share one
yardstick, and every figure is an average over whole gait periods:

- mean speed $\\bar v = \\Delta X / T_\\text{gait}$ (eq. 4),
- cost of transport $e_d / |\\Delta X|$ (eq. 15 over the same period),
- feasible (`ok`) only when the orbit converged, is stable (all Floquet multipliers
  inside the unit circle) and no normal force reaches zero (eq. 5).
"""

from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..dynamics._exact_dynamics import Exact
from ..gaits._gait import Gait, GaitStatus, paper_gait, steady_gait
from ..gaits._orbit import PATIENCE
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ._optimum import along


class ExactFigures(NamedTuple):
    """Per-configuration exact figures (numpy arrays of the batch shape).

    `speed` is the signed mean speed, `cost` the cost of transport (`nan` unless `ok`),
    `ok` is True for a converged, stable steady gait without lift-off, `status` the
    [`GaitStatus`][] code, `liftoff` and `stable` as in [`Gait`][].
    """

    speed: np.ndarray
    cost: np.ndarray
    ok: np.ndarray
    status: np.ndarray
    liftoff: np.ndarray
    stable: np.ndarray


def gait_figures(gait: Gait) -> ExactFigures:
    """[`ExactFigures`][] of solved steady gaits."""
    status = np.asarray(gait.status)
    stable = np.asarray(gait.stable)
    liftoff = np.asarray(gait.liftoff)
    ok = (status == GaitStatus.CONVERGED) & stable & ~liftoff
    speed = np.asarray(gait.mean_speed, dtype=float)
    cost = np.asarray(gait.cost_of_transport, dtype=float)
    return ExactFigures(
        speed=np.where(ok, speed, np.nan),
        cost=np.where(ok, cost, np.nan),
        ok=ok,
        status=status,
        liftoff=liftoff,
        stable=stable,
    )


def exact_figures(
    params: Params, waveform: AbstractWaveform | None, *, dt: float = 0.01, transient: int = 30
) -> ExactFigures:
    """Mean speed and cost of transport of the steady gait on the exact dynamics (module docstring).

    `params` may be batched; a `waveform` whose `omega` has the batch shape is batched
    with it (as in [`steady_gait`][]); `None` means the sinusoid of eq. (13).
    `transient`: actuation periods before the Newton iteration.
    """
    params = with_waveform_frequency(params, waveform)
    gait = steady_gait(
        params, waveform=waveform, dynamics=Exact(dt=dt), contact="strict", start="relaxed", transient=transient
    )
    return gait_figures(gait)


def with_waveform_frequency(params: Params, waveform: AbstractWaveform | None) -> Params:
    """`params` broadcast to the waveform's batch shape, with `omega` set to its base frequency.

    The waveform alone defines the actuation. The broadcast makes the engines batch the
    waveform with the parameters (a waveform whose `omega` has the params' batch shape
    is batched with them), and `params.omega` then reports the frequency actually used.
    """
    if waveform is None:
        return params
    omega = jnp.asarray(waveform.omega, params.dtype)
    shape = np.broadcast_shapes(params.batch_shape, omega.shape)
    values = {k: jnp.broadcast_to(v, shape) for k, v in params.broadcast().as_dict().items()}
    values["omega"] = jnp.broadcast_to(omega, shape)
    return Params(**values, check=False)


class SinusoidSweep(NamedTuple):
    """Exact figures of the sinusoids $a\\sin(\\omega t) + \\bar\\ell$ on a grid (flattened)."""

    a: np.ndarray
    omega: np.ndarray
    speed: np.ndarray
    cost: np.ndarray
    ok: np.ndarray


def sweep_of(given: Any) -> SinusoidSweep:
    """A [`SinusoidSweep`][], or one from its record (the paper's model's optimum's `screen`, read back
    from JSON: NaN as `None`).

    **Raises:** `TypeError` naming `sweep` for anything else (a chain's or a mechanism's screen has
    other fields)."""
    if isinstance(given, SinusoidSweep):
        return given
    if not isinstance(given, Mapping) or set(given) != set(SinusoidSweep._fields):
        got = f"a dict of {', '.join(map(str, given))}" if isinstance(given, Mapping) else type(given).__name__
        raise TypeError(f"sweep: the paper's model takes a sinusoid_sweep(...) result or its optimum's screen (a dict "
                        f"of {', '.join(SinusoidSweep._fields)}), got {got}.")  # fmt: skip
    rows = {key: np.array(given[key], dtype=bool if key == "ok" else np.float64) for key in SinusoidSweep._fields}
    if len({v.shape for v in rows.values()}) != 1 or rows["a"].ndim != 1:
        raise TypeError("sweep: an optimum's screen has one row per sinusoid in each of its fields.")
    return SinusoidSweep(**rows)


def default_omegas(params: Params, n: int = 32) -> np.ndarray:
    """Log-spaced frequencies from $0.07\\,\\omega_{n,\\min}$ to $2.5\\,\\omega_{n1}$ (0.5 to 25 for the defaults)."""
    wmin = float(jnp.minimum(jnp.minimum(params.wn1, params.wn2), params.wn3))
    return np.geomspace(0.07 * wmin, 2.5 * float(params.wn1), n)


def sinusoid_sweep(
    params: Params,
    a_max: float,
    *,
    omegas: np.ndarray | None = None,
    amplitudes: int | np.ndarray = 6,
    dt: float = 0.01,
    transient: int = 30,
) -> SinusoidSweep:
    """Batched exact sweep over $(a \\le a_\\max, \\omega)$: the steady gait of each sinusoid.

    `amplitudes`: a count (equally spaced in $(0, a_\\max]$) or the values; `dt`,
    `transient`: as in [`exact_figures`][].
    """
    omegas = default_omegas(params) if omegas is None else np.asarray(omegas, float)
    if np.ndim(amplitudes) == 0:
        amps = a_max * np.arange(1, int(amplitudes) + 1) / int(amplitudes)
    else:
        amps = np.asarray(amplitudes, float)
    a, w = (x.ravel() for x in np.meshgrid(amps, omegas, indexing="ij"))
    fig = _sinusoid_figures(params, a, w, dt, transient)
    return SinusoidSweep(a=a, omega=w, speed=fig.speed, cost=fig.cost, ok=fig.ok)


def bucket(n: int) -> int:
    """The batch size that `n` sinusoids are padded to: the next power of two (at least 8), so that
    the sweep's 192 and the refinement's 243 with the defaults run the same compiled programs."""
    return max(8, 1 << (int(n) - 1).bit_length())


def _sinusoid_figures(params: Params, a: np.ndarray, omega: np.ndarray, dt: float, transient: int) -> ExactFigures:
    """[`exact_figures`][] of the sinusoids `(a, omega)` (flat arrays), the batch padded to
    [`bucket`][locomotion_jax.optimisation._pareto.bucket] rows with copies of the last (each row's
    gait is solved on its own; the padding is dropped). Newton's method runs on quarter-size
    batches (`steady_gait`'s solver with `compact=True`): the first gait period on all of them in
    the order of the sinusoids' periods, so that a fast sinusoid does not wait for a slow one's
    long period, and the later periods on the few sinusoids still open: the same gaits. A
    sinusoid whose Newton iterations stop halving their residual is given up at a gait period after
    [`PATIENCE`][locomotion_jax.gaits._orbit.PATIENCE] of them (it cycles: no gait of that period
    near its start) instead of holding its batch to the iteration limit."""
    n = len(a)
    pad = bucket(n) - n
    values: dict[str, Any] = {k: v for k, v in params.as_dict().items() if k not in ("a", "omega")}
    batch = Params(
        a=jnp.asarray(np.pad(a, (0, pad), mode="edge"), params.dtype),
        omega=jnp.asarray(np.pad(omega, (0, pad), mode="edge"), params.dtype),
        **values,
    )
    gait = paper_gait(batch, dynamics=Exact(dt=dt), transient=transient, start="relaxed", compact=True,
                      patience=PATIENCE)  # fmt: skip
    assert isinstance(gait, Gait)  # the strict reading: the two-mass solver's own result
    return ExactFigures(*(np.asarray(f)[:n] for f in gait_figures(gait)))


def best_sinusoid(sweep: SinusoidSweep, v_min: float, direction: int) -> dict | None:
    """The feasible sinusoid (no lift-off, $\\sigma\\bar v \\ge v_\\min$) of least cost; `None` if none."""
    feasible = sweep.ok & (along(sweep.speed, direction) >= v_min)
    if not feasible.any():
        return None
    i = int(np.argmin(np.where(feasible, sweep.cost, np.inf)))
    return {
        "a": float(sweep.a[i]),
        "omega": float(sweep.omega[i]),
        "mean_speed": float(sweep.speed[i]),
        "cost_of_transport": float(sweep.cost[i]),
    }


def refine_sinusoid(
    params: Params,
    a_max: float,
    v_min: float,
    direction: int,
    sweep: SinusoidSweep,
    *,
    top: int = 3,
    points: int = 9,
    levels: int = 3,
    dt: float = 0.01,
    transient: int = 30,
) -> dict | None:
    """The best sinusoid of a coarse sweep, refined by a zooming local grid search.

    Level 1 lays a `points` x `points` grid around each of the `top` cheapest
    feasible sinusoids of `sweep`, one coarse grid step either side: in $a$
    linearly (the window kept inside $(0, a_\\max]$), in $\\omega$ logarithmically.
    Each further level zooms on the `top` cheapest feasible sinusoids found so far,
    its half-width one step of the previous level's grid, so every level is
    $(\\text{points} - 1)/2$ times finer. All candidates of a level run in one
    batched exact call of fixed size, padded as the sweep's (`bucket`: one compilation for the
    sweep and all levels).

    With the defaults (9 points, 3 levels) the final step is 1/64 of the coarse
    one: for `default_omegas(params, 32)` and 6 amplitudes up to `a_max = 0.05`,
    0.2 % in $\\omega$ and $1.3 \\times 10^{-4}$ in $a$.
    Feasible means as in [`best_sinusoid`][]: no lift-off, $\\sigma \\bar v \\ge v_\\min$,
    and $a \\le a_\\max$ by construction.

    **Returns:** the cheapest feasible sinusoid of the coarse and all fine grids
    (a dict as from [`best_sinusoid`][]), `None` if the coarse sweep has none.
    """
    found = [sweep]
    if best_sinusoid(sweep, v_min, direction) is None:
        return None
    a_steps = np.diff(np.unique(sweep.a))
    w_steps = np.diff(np.log(np.unique(sweep.omega)))
    half_a = float(a_steps.max()) if a_steps.size else 0.5 * float(sweep.a.max())
    half_w = float(w_steps.max()) if w_steps.size else 0.1
    shrink = 2.0 / (points - 1)
    for _ in range(levels):
        every = SinusoidSweep(*(np.concatenate(x) for x in zip(*found)))
        feasible = every.ok & (along(every.speed, direction) >= v_min)
        ranked = np.argsort(np.where(feasible, every.cost, np.inf))[: min(top, int(feasible.sum()))]
        centres = [(every.a[i], every.omega[i]) for i in ranked]
        centres += centres[:1] * (top - len(centres))  # a fixed batch size: one compilation
        a, w = [], []
        for ac, wc in centres:
            lo, hi = max(ac - half_a, 0.5 * ac), min(ac + half_a, a_max)
            ga, gw = np.meshgrid(np.linspace(lo, hi, points), wc * np.exp(np.linspace(-half_w, half_w, points)))
            a.append(ga.ravel())
            w.append(gw.ravel())
        a, w = np.concatenate(a), np.concatenate(w)
        fig = _sinusoid_figures(params, a, w, dt, transient)
        found.append(SinusoidSweep(a=a, omega=w, speed=fig.speed, cost=fig.cost, ok=fig.ok))
        half_a, half_w = shrink * half_a, shrink * half_w
    every = SinusoidSweep(*(np.concatenate(x) for x in zip(*found)))
    return best_sinusoid(every, v_min, direction)


def pareto_front(speed: np.ndarray, cost: np.ndarray, ok: np.ndarray, direction: int = 1) -> np.ndarray:
    """Indices of the non-dominated points (faster *and* cheaper is better), by increasing speed."""
    v = direction * np.asarray(speed, float)
    good = np.flatnonzero(np.asarray(ok) & np.isfinite(v) & np.isfinite(cost) & (v > 0))
    order = good[np.argsort(-v[good])]
    front, best = [], np.inf
    for i in order:  # from the fastest down: keep a point if it is cheaper than every faster one
        if cost[i] < best:
            front.append(i)
            best = cost[i]
    return np.asarray(front[::-1], dtype=int)


def stack_waveforms(waves: list) -> AbstractWaveform:
    """Stack waveforms of one type along a new leading axis (for batched exact runs)."""
    return jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *waves)
