"""The exact engine against the independent float64 event-driven scipy solver in
`tests/reference.py` (which shares no code with the package).

The cases cover both contact readings (the paper's through the lift-off band of Fig. 8,
where `n_i = |N_i|` has a kink at each sign change, and the strict one, which must stop at
the lift-off), both starts, `d = 0` with equal and unequal masses, other `k`, `c`, `lbar`,
`mu_k`, `mu_s` and `mhat`, a regime window short enough that its placement decides the
regime, the step cap, and the work queue of lanes.

Each reference run is a test of its own and runs once per process (`functools.cache`);
the package measures every case of a group in one batched call. The tests of a group share
a pytest-xdist group (`--dist loadgroup`, set in pyproject.toml), so that each group's
package call is compiled and run by one worker only, while the groups spread over workers.

The reference's tolerance (DOP853 at rtol 1e-10) does not set its cost: its step is capped
at 1/16 of the fastest period so that no event is missed, and that cap binds (rtol 1e-8
costs the same and changes `tau_5` by 1e-10 relative).

`LJ_REFERENCE_CACHE=<dir>` keeps the reference's results on disk between runs (for
`tests/mutations.py`, which runs these tests once per mutation of the package; the
reference does not change with the package). The suite itself runs it live.
"""

import functools
import hashlib
import math
import os
import pickle
from pathlib import Path
from typing import Any, NamedTuple

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.dynamics import _paper
from locomotion_jax.dynamics._runs import default_max_steps, horizon_bound
from locomotion_jax.run._batch import prepare
from reference import reference_measure, reference_natural_frequencies, reference_simulate


class Group(NamedTuple):
    """How a group of cases is measured (one batched package call per group)."""

    contact: str
    start: str
    z: float
    horizon: float
    window: float
    lanes: int | None = None  # run through the work queue with this many lanes (else `lj.measure`)


GROUPS = {
    # Steady motion over the paper's measurement, and strict lift-off in the first period.
    "steady": Group("strict", "paper", 5.0, 1200.0, 25.0),
    # Other parameters, d = 0; a window (0.5) shorter than a period, so the regime depends on it.
    "short": Group("strict", "paper", 1.0, 60.0, 0.5),
    # The paper's reading through the lift-off band of Fig. 8 (0.8 <= omega/wn1 <= 1.4).
    "paper": Group("paper", "paper", 5.0, 1200.0, 25.0),
    # The relaxed start, lift-off after many switches, and the work queue (2 lanes, 7 cases).
    "relaxed": Group("strict", "relaxed", 2.0, 150.0, 25.0, lanes=2),
    # d = 0, m1 = m2 over 200 time units: both masses switch at the same instants, and losing
    # one of two simultaneous switches makes the pair crawl (mean speed ~1e-5 instead of 0).
    "symmetric": Group("strict", "paper", 1.0, 200.0, 25.0),
}

# (group, parameters, what the reference must find: "SSL", "SL", "liftoff" or "still")
CASES: list[tuple[str, dict[str, Any], str | None]] = [
    ("steady", dict(omega=1.0, a=0.08), "SSL"),
    ("steady", dict(omega=2.0), "SSL"),
    ("steady", dict(omega=2.0, a=0.07), "SSL"),
    ("steady", dict(omega=2.5, mu_s=0.6), "SSL"),
    ("steady", dict(omega=4.0, a=0.04), "SSL"),
    ("steady", dict(omega=5.0, d=0.3), "SSL"),
    ("steady", dict(omega=6.0), "SL"),
    ("steady", dict(omega=6.0, d=-0.5), "SL"),
    ("steady", dict(omega=7.0, a=0.03), "SL"),
    ("steady", dict(omega=12.0, a=0.03), "SL"),
    ("steady", dict(omega=16.0), "SL"),
    ("steady", dict(omega=8.0), "liftoff"),
    ("steady", dict(omega=10.0), "liftoff"),
    ("steady", dict(omega=12.0), "liftoff"),
    ("steady", dict(omega=14.0), "liftoff"),
    ("steady", dict(omega=23.0, a=0.08), "liftoff"),
    ("short", dict(omega=3.0, d=0.0), "still"),
    ("short", dict(omega=16.0, d=0.0), "still"),
    ("short", dict(omega=3.0, d=0.0, mhat=0.4), "SSL"),
    ("short", dict(omega=16.0, d=0.0, mhat=0.6), "SL"),
    ("short", dict(omega=1.5, d=0.0, mhat=0.3, a=0.08), "SSL"),
    ("short", dict(omega=3.0, k=30.0), "SSL"),
    ("short", dict(omega=6.0, k=80.0), "SL"),
    ("short", dict(omega=4.0, c=0.1), "SSL"),
    ("short", dict(omega=4.0, lbar=2.0), "SSL"),
    ("short", dict(omega=3.0, mu_k=0.3, mu_s=0.5), "SSL"),
    ("short", dict(omega=16.0, mu_k=0.6, mu_s=0.8), "SL"),
    ("short", dict(omega=5.0, k=40.0, c=0.05, lbar=2.5, mu_k=0.4, mu_s=0.6, mhat=0.45, d=0.4), "SL"),
    ("short", dict(omega=0.7, a=0.08), "SSL"),
    ("short", dict(omega=2.25, a=0.08), "SL"),  # no stick in its first 0.5 after t_start; SSL over 1 or 25
    ("paper", dict(omega=8.0), "SL"),
    ("paper", dict(omega=9.0), "SL"),
    ("paper", dict(omega=10.0), "SL"),
    ("paper", dict(omega=12.0), "SL"),
    ("relaxed", dict(omega=9.8, a=0.014), "liftoff"),
    ("relaxed", dict(omega=10.0, a=0.016), "liftoff"),
    ("relaxed", dict(omega=10.0), "liftoff"),
    ("relaxed", dict(omega=23.0, a=0.07), "SL"),
    ("relaxed", dict(omega=6.0), "SL"),
    ("relaxed", dict(omega=2.0), "SSL"),
    ("relaxed", dict(omega=1.0, a=0.08, d=-0.4), "SSL"),
    ("symmetric", dict(omega=2.0, d=0.0), "still"),
    ("symmetric", dict(omega=5.0, d=0.0), "still"),
]
BATCH = 32
"""Groups measured by `lj.measure` are padded to this batch size, so that those sharing
`contact` and `start` share a compilation."""

RTOL = 5e-5
"""tau_z, e_z and the mean speed (float64, dt = 0.01; measured 1e-7 to 2.4e-5)."""


def _case_id(case) -> str:
    group, params, _ = case
    return group + "-" + ",".join(f"{k}={v:g}" for k, v in params.items())


def _key(params: dict) -> tuple:
    return tuple(sorted(params.items()))


@functools.cache
def _reference(group: str, key: tuple) -> dict:
    g = GROUPS[group]
    kw: dict[str, Any] = dict(
        z=g.z, horizon=g.horizon, window=g.window, contact=g.contact, start=g.start, rtol=1e-10, atol=1e-12
    )
    cache = os.environ.get("LJ_REFERENCE_CACHE")
    name = hashlib.sha1(repr((group, g, key)).encode()).hexdigest()[:16]
    path = Path(cache) / f"{name}.pkl" if cache else None
    if path is not None and path.exists():
        stored_key, out = pickle.loads(path.read_bytes())
        if stored_key == (group, g, key):
            return out
    out = reference_measure(dict(key), **kw)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(((group, g, key), out)))
    return out


@functools.cache
def _package(group: str, dtype=jnp.float64) -> dict:
    """The package's measurements of every case of `group` (name -> dict of scalars)."""
    g = GROUPS[group]
    cases = [params for grp, params, _ in CASES if grp == group]
    padded = cases + [cases[-1]] * (BATCH - len(cases)) if g.lanes is None else cases
    p = lj.Params.stack([lj.Params(**c) for c in padded]).astype(dtype)
    if g.lanes is None:
        m = lj.measure(p, z=g.z, horizon=g.horizon, window=g.window, contact=g.contact, start=g.start).to_numpy()
    else:
        flat, wave, axes, _ = prepare(p, None, None)
        max_steps = default_max_steps(horizon_bound(flat, g.horizon), 0.01)
        values = (jnp.asarray(v, flat.dtype) for v in (g.z, g.horizon, g.window))
        args = (flat, wave, axes, *values, g.contact, g.start, 0.01, jnp.asarray(max_steps, jnp.int32))
        m = {k: np.asarray(v) for k, v in _paper._measure_batch(*args, lanes=g.lanes).items()}
        sf = m.pop("stick_fraction")  # per mass on the last axis, as `to_numpy` names them
        m["stick_fraction1"], m["stick_fraction2"] = sf[..., 0], sf[..., 1]
    return {_key(c): {k: v[i] for k, v in m.items()} for i, c in enumerate(cases)}


@pytest.mark.parametrize("case", [pytest.param(c, id=_case_id(c), marks=pytest.mark.xdist_group(c[0])) for c in CASES])
def test_measurement_matches_reference(case):
    group, params, expect = case
    g = GROUPS[group]
    ref = _reference(group, _key(params))
    got = _package(group)[_key(params)]
    # What the case is meant to cover holds in the reference.
    if expect == "liftoff":
        assert ref["liftoff"]
    elif expect == "still":
        assert ref["regime"] != -1 and abs(ref["mean_speed"]) < 1e-12
    else:
        assert ref["regime"] == (1 if expect == "SSL" else 0)
    if g.contact == "paper":
        assert ref["liftoff"], "the paper-reading cases must lift off"

    np.testing.assert_allclose(got["t_start"], ref["t_start"], rtol=1e-12)
    # Lift-off: located (its time), and under the strict reading the run stops there.
    assert bool(got["liftoff"]) == ref["liftoff"]
    if ref["liftoff"]:
        np.testing.assert_allclose(got["t_liftoff"], ref["t_liftoff"], rtol=1e-5)
    stopped = ref["liftoff"] and g.contact == "strict"
    assert int(got["status"]) == (lj.Status.LIFTOFF if stopped else lj.Status.OK)

    assert bool(got["reached"]) == ref["reached"]
    if ref["reached"]:
        np.testing.assert_allclose(got["tau_z"], ref["tau_z"], rtol=RTOL)
        np.testing.assert_allclose(got["e_z"], ref["e_z"], rtol=RTOL)
    else:
        assert math.isinf(got["tau_z"]) and math.isinf(got["e_z"])
    if math.isnan(ref["mean_speed"]):
        assert math.isnan(got["mean_speed"])
    else:  # also up to a strict lift-off during the measurement
        np.testing.assert_allclose(got["mean_speed"], ref["mean_speed"], rtol=RTOL, atol=1e-10)
    assert int(got["regime"]) == ref["regime"]
    for name in ("stick_fraction1", "stick_fraction2"):
        np.testing.assert_allclose(got[name], ref[name], atol=2e-5)
    # The energy balance (eq. 16) of the package's own run (measured up to 7e-6).
    if not math.isnan(got["balance"]):
        assert abs(got["balance"]) < 2e-5 * max(1.0, abs(got["e_d"]))


@pytest.mark.xdist_group("steady")
def test_float32_close_to_float64():
    # float32: round-off in t and X over 1e5 steps; the README quotes these figures.
    # (The float64 results are the ones checked against the reference above.)
    m64, m32 = _package("steady"), _package("steady", jnp.float32)
    ok = [k for k, v in m64.items() if v["reached"]]
    assert len(ok) >= 10
    for name in ("tau_z", "e_z"):
        err = np.array([abs(float(m32[k][name]) / float(m64[k][name]) - 1) for k in ok])
        assert np.max(err) < 1e-2 and np.median(err) < 2e-4, (name, np.max(err), np.median(err))
    for k, v in m64.items():
        assert int(m32[k]["status"]) == int(v["status"]) and int(m32[k]["regime"]) == int(v["regime"])


@pytest.mark.parametrize("params", [{}, dict(k=30.0, mhat=0.3), dict(k=80.0, mhat=0.6), dict(mhat=0.05)])
def test_natural_frequencies_match_reference(params):
    p = lj.Params(**params)
    wn = reference_natural_frequencies(params)
    np.testing.assert_allclose([float(p.wn1), float(p.wn2), float(p.wn3)], wn, rtol=1e-14)


def test_fourth_order_convergence():
    # Located switches: the error falls at the integrator's order (4), not at
    # first order as it would if switches were snapped to the grid. (SSL and SL in one
    # test: they share the four compilations, one per dt.)
    T = 30.0
    dts = np.array([0.08, 0.04, 0.02, 0.01])
    for omega in (2.0, 16.0):
        ref = reference_simulate(dict(omega=omega), T, save_at=np.array([0.0, T]), rtol=1e-12, atol=1e-13)
        errs = []
        for dt in dts:
            tr = lj.simulate(lj.Params(omega=omega), T, save_at=jnp.array([0.0, T]), dynamics=lj.Exact(dt=float(dt)))
            errs.append(abs(float(tr.X[-1]) - ref["X"][-1]) + abs(float(tr.e_d[-1]) - ref["e_d"][-1]))
        slope = float(np.polyfit(np.log(dts), np.log(errs), 1)[0])  # least-squares slope of the log-log line
        assert slope > 3.5, (omega, slope, errs)


def test_trajectory_matches_reference():
    # The paper's reading; at omega = 10 = wn1 the normal forces change sign many times.
    save = np.linspace(0.0, 40.0, 401)
    for omega in (2.0, 10.0, 23.0):
        ref = reference_simulate(dict(omega=omega), 40.0, save_at=save, contact="paper")
        tr = lj.simulate(
            lj.Params(omega=omega), 40.0, save_at=jnp.asarray(save), contact="paper", dynamics=lj.Exact(dt=0.005)
        )
        for name in ("x1", "x2", "v1", "v2", "e_d", "w"):  # measured 1.4e-6 of the scale at omega = 10
            scale = max(1.0, float(np.max(np.abs(ref[name]))))
            got = np.asarray(getattr(tr, name))
            np.testing.assert_allclose(got, ref[name], rtol=0, atol=3e-6 * scale, err_msg=f"{name}, omega={omega}")
        agree = np.mean(np.asarray(tr.mode) == ref["mode"])
        assert agree > 0.99  # modes differ only at samples within ~dt of a switch
        assert bool(tr.liftoff) == ref["liftoff"] and int(tr.status) == lj.Status.OK
        if ref["liftoff"]:
            assert math.isclose(float(tr.t_liftoff), ref["t_liftoff"], rel_tol=1e-6)
            crossings = [t for t, kind in ref["events"] if "normal" in kind]
            assert len(crossings) > 10  # the kink of |N| is crossed again and again


@pytest.mark.xdist_group("simulate")
def test_liftoff_time_matches_reference():
    p: dict[str, Any] = dict(omega=23.0, a=0.08)
    ref = reference_simulate(p, 2.0, save_at=np.linspace(0, 2, 21))
    tr = lj.simulate(lj.Params(**p), 2.0, save_at=jnp.linspace(0, 2, 21))
    assert bool(tr.liftoff) and ref["liftoff"]
    assert int(tr.status) == lj.Status.LIFTOFF
    assert math.isclose(float(tr.t_liftoff), ref["t_liftoff"], rel_tol=1e-5)  # RK4 at dt = 0.01: 4e-7
    valid = np.asarray(tr.valid)
    np.testing.assert_array_equal(valid, np.asarray(tr.t) <= ref["t_liftoff"])


@pytest.mark.xdist_group("simulate")
def test_step_cap_stops_the_run_and_keeps_what_was_integrated():
    # 600 iterations at dt = 0.01 cover about 5.5 time units of the 20 asked for: the status
    # says so, and the saved states before the stop are the reference's. (21 saves, as in
    # the lift-off test: one compilation.)
    save = np.linspace(0.0, 20.0, 21)
    ref = reference_simulate(dict(omega=2.0), 20.0, save_at=save)
    tr = lj.simulate(lj.Params(omega=2.0), 20.0, save_at=jnp.asarray(save), dynamics=lj.Exact(max_steps=600))
    assert int(tr.status) == lj.Status.MAX_STEPS and not bool(tr.liftoff)
    valid = np.asarray(tr.valid)
    assert 2 <= valid.sum() <= 6 and np.all(valid[: valid.sum()])
    for name in ("x1", "x2", "v1", "v2", "e_d"):
        np.testing.assert_allclose(np.asarray(getattr(tr, name))[valid], ref[name][valid], atol=1e-6, err_msg=name)


@pytest.mark.xdist_group("steady")
def test_step_cap_in_measure():
    # The cap ends the runs before t_start: nothing is measured, and the status says why.
    # (Padded to the steady group's batch: its compilation.)
    p = lj.Params.stack([lj.Params(omega=2.0), lj.Params(omega=16.0)] * (BATCH // 2))
    m = lj.measure(p, z=5.0, horizon=1200.0, dynamics=lj.Exact(max_steps=600))
    assert np.all(np.asarray(m.status) == lj.Status.MAX_STEPS) and not np.any(np.asarray(m.liftoff))
    assert not np.any(np.asarray(m.reached)) and np.all(np.asarray(m.regime) == lj.Regime.UNDETERMINED)
    assert np.all(np.asarray(m.n_steps) == 600) and np.all(np.isnan(np.asarray(m.mean_speed)))


@pytest.mark.parametrize("start", ["paper", "relaxed"])
def test_start_from_relaxed_springs_matches_reference(start):
    # d = 0: both starts at rest with F = 0 (the stick margin's kink at t = 0). X at t_start
    # (after 1,072 switches) is the transient's record of the located breakaways: 8e-8 from the
    # reference at dt = 0.01 (1.2e-4 with the first breakaway mislocated at t = 5.5e-3, not 4.2e-3).
    p: dict[str, Any] = dict(omega=20.0, a=0.1, d=0.0, mhat=0.3)
    ref = reference_measure(p, 5.0, horizon=1.0, contact="paper", start=start)
    m = lj.measure(lj.Params(**p), z=5.0, horizon=1.0, contact="paper", start=start)
    assert float(m.t_start) == pytest.approx(ref["t_start"], rel=1e-12)
    assert abs(float(m.X_start) - ref["X_start"]) < 1e-6
