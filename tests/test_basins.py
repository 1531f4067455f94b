"""Basins of coexisting gaits: at omega = 4.9 (paper defaults) a stick-slip and a slip gait are both
stable (between the SSL/SL corner and the fold of test_continuation); starts are told apart, and
each start's label agrees with a long run of the independent reference from the same start."""

import locomotion_jax as lj
import numpy as np
import pytest
from reference import reference_simulate


pytestmark = pytest.mark.xdist_group("gait")  # two starts: the gait tests' compiled batch of two

OMEGA = 4.9
STARTS = np.array([[2.90, 0.08, -0.08], [2.98, 0.08, -0.08]])


def test_two_coexisting_gaits_and_the_reference():
    b = lj.basins(lj.Params(omega=OMEGA), STARTS)
    assert list(np.asarray(b.count)) == [1, 1]
    assert list(np.asarray(b.gaits.regime)) == [lj.Regime.SL, lj.Regime.SSL]  # by increasing speed
    assert bool(np.all(np.asarray(b.gaits.stable))) and list(np.asarray(b.gaits.k)) == [1, 1]
    label = np.asarray(b.label)
    assert list(label) == [1, 0]
    # A long run from each start under the reference (60 periods): it ends on the labelled gait,
    # sticking in the last period exactly for the stick-slip one.
    T = 2 * np.pi / OMEGA
    for start, lab in zip(STARTS, label):
        r = reference_simulate(dict(omega=OMEGA), 60 * T, save_at=[59 * T, 60 * T],
                               start=(0.0, start[1], start[0], start[2]))  # fmt: skip
        speed = (r["X"][1] - r["X"][0]) / T
        assert speed == pytest.approx(float(b.gaits.mean_speed[lab]), rel=1e-3)
        other = 1 - lab
        end = np.array([r["x2"][1] - r["x1"][1], r["v1"][1], r["v2"][1]])
        g = b.gaits
        assert isinstance(g, lj.Gait) and g.names == "paper"  # the paper's model's gaits, under its names
        u, v1, v2 = np.asarray(g.u), np.asarray(g.v1), np.asarray(g.v2)
        gait = lambda i: np.array([u[i], v1[i], v2[i]])
        assert np.linalg.norm(end - gait(lab)) < 0.1 * np.linalg.norm(end - gait(other))
        sticks = any("slip->stick" in kind and t > 59 * T for t, kind in r["events"])
        assert sticks == (int(b.gaits.regime[lab]) == lj.Regime.SSL)


def test_bad_input():
    with pytest.raises(ValueError, match="one configuration"):
        lj.basins(lj.Params(omega=np.array([1.0, 2.0])), STARTS)
    with pytest.raises(ValueError, match="starts"):
        lj.basins(lj.Params(omega=OMEGA), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="start"):
        lj.steady_gait(lj.Params(omega=np.array([1.0, 2.0])), start=np.zeros((3, 3)))
