"""Cost-ordered scheduling of long sweeps.

Under `vmap` an integration loop runs until the slowest configuration of its batch
(or, with `shard_map`, of its device's shard) is done: a chunk that mixes a
configuration reaching $z$ after 20 time units with one needing 900 keeps every
lane busy for 900. Ordering the configurations by expected cost before cutting
the sweep into chunks groups similar durations, so each chunk's loop ends close
to when its own configurations are done.

The expected cost comes from a cheap pilot run of the exact engine: a coarse step,
a short horizon, no measurement window ([`pilot`][]). It gives each configuration's
mean speed (hence its expected $\\tau_z$) and its rate of mode switches (hence its
iterations per time unit); [`expected_cost`][] turns them into integrator
iterations and [`cost_order`][] into a permutation, which `sweep(order="cost")`
cuts its chunks from. benchmarks/NOTES.md measures the effect on the Fig. 8 sweep
and on an omega x a map.
"""

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .._status import Status
from ..dynamics._exact_dynamics import Exact
from ..model._params import PARAM_NAMES, Params


PILOT_DT = 0.05
"""Step of the pilot run (RK4 is stable up to ~0.1 here; accuracy only needs the sign of a trend)."""

PILOT_T = 30.0
"""Length of the pilot run; its speed is measured over the second half."""

ITERS_PER_SWITCH = 0.5
"""Extra iterations per mode switch (a step cut at an event; measured 0.44-0.56)."""


def pilot(
    values: Mapping[str, Any],
    *,
    contact: str = "strict",
    start: str = "paper",
    dtype: Any = None,
    t_pilot: float = PILOT_T,
    dt: float = PILOT_DT,
    chunk_size: int = 1 << 16,
) -> dict[str, np.ndarray]:
    """Run the exact engine briefly on every configuration.

    **Arguments:** `values`, one 1-D array per name of `PARAM_NAMES` (missing names
    take the defaults; NaN marks padding or invalid entries); `contact`, `start`,
    `dtype` as in [`simulate`][]; `t_pilot`, `dt` the pilot's length and step;
    `chunk_size` configurations per call: every call has this shape (the last
    one NaN-padded), so the pilot compiles once and its memory is bounded.

    **Returns:** `speed` ($|\\Delta X|/\\Delta t$ over $[t_\\text{pilot}/2, t_\\text{pilot}]$),
    `switch_rate` (mode switches per time unit), `t_liftoff` (`inf` if none) and
    `valid`, as numpy arrays.
    """
    from ..run._simulate import simulate

    n = len(next(iter(values.values())))
    fields = {k: np.asarray(values[k], dtype=np.float64) for k in PARAM_NAMES if k in values}
    valid = np.ones(n, bool)
    for v in fields.values():
        valid &= np.isfinite(v)
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}.")
    speed, rate, t_lift, ok = (np.zeros(n), np.zeros(n), np.full(n, np.inf), np.zeros(n, bool))
    size = min(n, chunk_size)
    for lo in range(0, n, size):  # equal chunks: one compilation, memory bounded by the chunk
        idx = np.arange(lo, lo + size)
        take = np.minimum(idx, n - 1)
        live = (idx < n) & valid[take]  # NaN padding is flagged invalid and costs no steps
        params = Params(**{k: np.where(live, v[take], np.nan) for k, v in fields.items()}, check=False)
        tr = simulate(
            params,
            t_pilot,
            save_at=np.asarray([0.5 * t_pilot, t_pilot]),
            dynamics=Exact(dt=dt),
            contact=contact,
            start=start,
            dtype=dtype,
        )
        m = min(size, n - lo)
        speed[lo : lo + m], rate[lo : lo + m], t_lift[lo : lo + m], ok[lo : lo + m] = _read(tr, m, t_pilot)
        ok[lo : lo + m] &= live[:m]
    return dict(speed=np.where(ok, speed, 0.0), switch_rate=rate, t_liftoff=t_lift, valid=ok)


def _read(tr: Any, m: int, t_pilot: float) -> tuple[np.ndarray, ...]:
    """The first `m` configurations of a pilot's `Trajectory` (saved at `t_pilot / 2` and `t_pilot`):
    mean speed over the second half, switches per time unit, lift-off time, and not invalid."""
    X = np.asarray(tr.X, np.float64)[:m]
    speed = np.abs(X[:, 1] - X[:, 0]) / (0.5 * t_pilot)
    rate = np.asarray(tr.n_switch)[:m] / t_pilot
    return speed, rate, np.asarray(tr.t_liftoff, np.float64)[:m], np.asarray(tr.status)[:m] != int(Status.INVALID)


def expected_cost(
    values: Mapping[str, Any],
    *,
    z: float,
    horizon: float,
    window: float,
    dt: float,
    contact: str = "strict",
    start: str = "paper",
    dtype: Any = None,
    pilot_result: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """Expected integrator iterations of [`measure`][] for each configuration.

    A configuration runs to $t_\\text{start} + \\max(\\text{window}, \\min(\\tau_z, \\text{horizon}))$
    (SPEC §5), shorter if it lifts off under the strict reading, with about
    `1/dt + ITERS_PER_SWITCH * switch_rate` iterations per time unit; $\\tau_z$ is
    estimated as $z$ over the pilot's speed. Invalid configurations cost 0.
    """
    pr = dict(pilot_result) if pilot_result is not None else pilot(values, contact=contact, start=start, dtype=dtype)
    k = np.asarray(values.get("k", 50.0), np.float64)
    mhat = np.asarray(values.get("mhat", 0.5), np.float64)
    with np.errstate(all="ignore"):
        m1, m2 = 2 * mhat, 2 * (1 - mhat)
        wmin = np.minimum(np.sqrt(k * (m1 + m2) / (m1 * m2)), np.minimum(np.sqrt(k / m1), np.sqrt(k / m2)))
        t_start = 80 * 2 * math.pi / wmin
    return iterations(pr, t_start, z=z, horizon=horizon, window=window, dt=dt, contact=contact)


def iterations(pr: Mapping[str, np.ndarray], t_start: np.ndarray, *, z: float, horizon: float, window: float,
               dt: float, contact: str) -> np.ndarray:  # fmt: skip
    """[`expected_cost`][] of any mechanism from its pilot's results `pr` (as [`pilot`][]'s) and
    each configuration's measurement start `t_start`."""
    with np.errstate(all="ignore"):
        tau = np.where(pr["speed"] > 0, z / pr["speed"], np.inf)
    t_end = t_start + np.clip(np.maximum(tau, window), 0, horizon)
    if contact == "strict":
        t_end = np.minimum(t_end, pr["t_liftoff"])
    rate = 1 / dt + ITERS_PER_SWITCH * pr["switch_rate"]
    return np.where(pr["valid"], np.nan_to_num(t_end * rate, nan=0.0, posinf=0.0), 0.0)


def cost_order(values: Mapping[str, Any], **kwargs) -> np.ndarray:
    """A permutation of the configurations by increasing [`expected_cost`][] (same arguments).

    Cut the permuted list into chunks (and each chunk into per-device shards) in
    this order, then scatter the results back with `out[order] = chunk_results`.
    """
    return np.argsort(expected_cost(values, **kwargs), kind="stable")


def mechanism_cost_order(build: Callable[[np.ndarray], Any], size: int, chunk: int, *, t_start: float | None,
                         z: float, horizon: float, window: float, dt: float, contact: str = "strict",
                         start: str = "paper", dtype: Any = None, t_pilot: float = PILOT_T,
                         pilot_dt: float = PILOT_DT) -> np.ndarray:  # fmt: skip
    """[`cost_order`][] of a map over a builder's mechanisms: `build(indices)` is the
    [`Chain`][locomotion_jax.Chain] or [`Mechanism`][locomotion_jax.Mechanism] of the configurations
    `indices` (flat, `size` in all), run by the pilot `chunk` at a time (every call of one shape,
    the last padded by repeating its last configuration: one compilation). The pilot is
    [`pilot`][]'s: the exact engine at the step `pilot_dt` to `t_pilot`, its mean speed over the
    second half; `t_start` is the measurement's start (`None`: each mechanism's own)."""
    from ..run._simulate import simulate

    speed, rate, t_lift = np.zeros(size), np.zeros(size), np.full(size, np.inf)
    ok, ts = np.zeros(size, bool), np.zeros(size)
    for lo in range(0, size, chunk):
        m = min(chunk, size - lo)
        mech = build(np.minimum(np.arange(lo, lo + chunk), size - 1))
        tr = simulate(mech, t_pilot, save_at=np.asarray([0.5 * t_pilot, t_pilot]), dynamics=Exact(dt=pilot_dt),
                      contact=contact, start=start, dtype=dtype)  # fmt: skip
        speed[lo : lo + m], rate[lo : lo + m], t_lift[lo : lo + m], ok[lo : lo + m] = _read(tr, m, t_pilot)
        ts[lo : lo + m] = np.broadcast_to(np.asarray(mech.t_start if t_start is None else t_start, np.float64),
                                          (chunk,))[:m]  # fmt: skip
    pr = dict(speed=np.where(ok, speed, 0.0), switch_rate=rate, t_liftoff=t_lift, valid=ok)
    cost = iterations(pr, ts, z=z, horizon=horizon, window=window, dt=dt, contact=contact)
    return np.argsort(cost, kind="stable")
