"""Margins to a change of switching structure, and the `smooth` flag built on them.

A measured quantity is only piecewise smooth in the parameters. The engines record how
close each run came to a change of its switching structure (`_engine` module docstring,
"Margins"); these tests check that the margins vanish where the structure changes, that
the flag is down where the reference's own finite differences are inconsistent, and up
(with the derivative matching the reference) where they agree.
"""

import functools
import os
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax._results import SMOOTH_MARGIN, SMOOTH_MARGIN_Z


sys.path.insert(0, str(Path(__file__).parent))
from reference import DEFAULTS, reference_measure  # noqa: E402


FULL_REFERENCE = os.environ.get("LOCOMOTION_JAX_FULL_REFERENCE") == "1"
pytestmark = pytest.mark.xdist_group("gradients")


BATCH = 25  # both batches below have this size: one compiled program serves them
W_STAR = 4.0431  # where the transversality of the omega scan closes (fitted in the test)
D = 4e-4


@functools.cache
def _run(z: float, t_start: float | None, omega: tuple) -> tuple:
    """`measure` and d tau_z / d omega (forward mode) on a batch padded to `BATCH`."""
    w = np.concatenate([omega, np.full(BATCH - len(omega), omega[0])])
    ts = None if t_start is None else np.full(BATCH, t_start)
    run = lambda w: lj.measure(lj.Params(omega=w), z=z, t_start=ts, horizon=300.0)
    m, dm = jax.jvp(run, (jnp.asarray(w),), (jnp.ones(BATCH),))
    return m, np.asarray(dm.tau_z)


def _scan():
    """omega in [4.00, 4.04] (z = 1 from t = 30), where a stick-or-reverse decision closes
    in, and pairs of steps across W_STAR and across 4.0."""
    omega = np.concatenate([np.linspace(4.0, 4.04, 21), [W_STAR - D, W_STAR + D, 4.0 - D, 4.0 + D]])
    return (omega, *_run(1.0, 30.0, tuple(omega)))


def test_transversality_vanishes_where_the_result_jumps():
    omega, m, dtau = _scan()
    tr = np.asarray(m.transversality)[:21]
    # The margin closes linearly (a decision's phase margin moves with the parameter) ...
    slope, icpt = np.polyfit(omega[:21], tr, 1)
    assert np.max(np.abs(np.polyval([slope, icpt], omega[:21]) - tr)) < 2e-3 and slope < 0
    assert abs(-icpt / slope - W_STAR) < 3e-4
    assert bool(m.smooth[0]) and not bool(m.smooth[20])
    # ... and where it reaches zero tau_z jumps; across an equal step where the margin
    # is wide it moves by its derivative.
    t = np.asarray(m.tau_z)[21:]
    assert abs(t[3] - t[2] - 2 * D * dtau[0]) < 2e-3
    assert abs(t[1] - t[0] - 2 * D * dtau[0]) > 0.05


def test_chain_margins_equal_the_two_mass_engines():
    # The N-mass engine computes its margins from its own loads and their rates; at N = 2
    # on the scan above (a stick-or-reverse decision closing in) they are the two-mass
    # engine's, and the margin closes at the same omega.
    omega, m, _ = _scan()
    ts = np.full(BATCH, 30.0)
    mc = lj.measure(lj.Chain.from_params(lj.Params(omega=omega)), z=1.0, t_start=ts, horizon=300.0)
    for field in ("transversality", "near_miss", "margin_z"):
        np.testing.assert_allclose(getattr(mc, field)[:21], getattr(m, field)[:21], rtol=1e-8, err_msg=field)
    slope, icpt = np.polyfit(omega[:21], np.asarray(mc.transversality)[:21], 1)
    assert abs(-icpt / slope - W_STAR) < 3e-4
    assert bool(mc.smooth[0]) and not bool(mc.smooth[20])


def _tau5():
    """tau_5 at omega = 2 from the paper's t_start, around it (relative steps 1e-4 and 1e-5),
    and on both sides of where a switch crosses t_5."""
    omega = 2.0 + np.array([0.0, -2e-4, 2e-4, -2e-5, 2e-5, -1.2e-4, -0.8e-4])
    return (omega, *_run(5.0, None, tuple(omega)))


def test_tau5_at_omega_2_is_flagged():
    # The example: a switch (mass 1 sticking) falls 0.0085 time units from t_5
    # (4e-5 of tau_5), and crosses it at omega = 2 - 1e-4 (a relative change of 5e-5).
    # tau_5 stays differentiable there (the velocities are continuous), but its curvature
    # changes: the flag is down.
    omega, m, _ = _tau5()
    assert float(m.margin_z[0]) < SMOOTH_MARGIN_Z and not bool(m.smooth[0])
    assert 2e-5 < float(m.margin_z[0]) < 1e-4
    assert min(float(m.transversality[0]), float(m.near_miss[0])) > SMOOTH_MARGIN  # no grazing
    # The margin closes where the switch count at t_5 changes.
    assert int(m.n_switch[5]) != int(m.n_switch[6])
    assert float(m.margin_z[5]) < 1e-5 and float(m.margin_z[6]) < 1e-5


def test_tau5_at_omega_2_reference_differences_disagree():
    # The reference's central differences with steps 1e-4 and 1e-5 (relative) disagree
    # there, as the flag says; the package's own are the same within its dt error (1e-3),
    # and its forward-mode derivative is their limit.
    omega, m, dtau = _tau5()
    tau = {w: reference_measure({**DEFAULTS, "omega": w}, z=5.0, horizon=300.0)["tau_z"] for w in omega[1:5]}
    fd = [(tau[omega[2 * i + 2]] - tau[omega[2 * i + 1]]) / (omega[2 * i + 2] - omega[2 * i + 1]) for i in (0, 1)]
    assert abs(fd[0] - fd[1]) > 2e-3 * abs(fd[1]), fd
    t = np.asarray(m.tau_z)
    own = [(t[2] - t[1]) / 4e-4, (t[4] - t[3]) / 4e-5]
    np.testing.assert_allclose(own, fd, rtol=1e-3)
    np.testing.assert_allclose(dtau[0], fd[1], rtol=1e-3)


def test_trajectory_margins_are_running_minima():
    tr = lj.simulate(lj.Params(omega=jnp.array([2.0, 6.0])), t_end=12.0, save_at=np.linspace(1.0, 12.0, 12))
    for field in (tr.transversality, tr.near_miss):
        f = np.asarray(field)
        assert np.all(np.diff(f, axis=-1) <= 0) and np.all(f > 0)
    assert np.all(np.asarray(tr.switch_gap) >= 0)
    # omega = 6: early in the transient, mass 1 stops where its spring force is within
    # 0.002 rad of drive phase of the static limit (stick or reverse): flagged.
    assert float(tr.transversality[1, -1]) < SMOOTH_MARGIN and not np.any(np.asarray(tr.smooth[1]))


@pytest.mark.skipif(not FULL_REFERENCE, reason="LOCOMOTION_JAX_FULL_REFERENCE=1 runs the a and e_5 cases")
def test_tau5_and_e5_in_a_reference_differences_disagree_where_flagged():
    a = 0.05 * (1 + np.array([-1e-4, 1e-4, -1e-5, 1e-5]))
    runs = [reference_measure({**DEFAULTS, "omega": 2.0, "a": v}, z=5.0, horizon=300.0) for v in a]
    for key in ("tau_z", "e_z"):
        fd = [(runs[2 * i + 1][key] - runs[2 * i][key]) / (a[2 * i + 1] - a[2 * i]) for i in (0, 1)]
        assert abs(fd[0] - fd[1]) > 2e-3 * abs(fd[1]), (key, fd)
    assert not bool(lj.measure(lj.Params(omega=2.0), z=5.0, horizon=300.0).smooth)
