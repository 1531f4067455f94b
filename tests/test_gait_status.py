"""`GaitStatus` is an `enum.IntEnum` like `Status`: an integer code from a result names itself."""

import enum

import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.gaits import _select


def test_gait_status_is_an_int_enum_like_status():
    assert issubclass(lj.GaitStatus, enum.IntEnum) and issubclass(lj.Status, enum.IntEnum)
    for member in lj.GaitStatus:
        assert lj.GaitStatus(int(member)) is member
        assert lj.GaitStatus[member.name] is member
    # One enum: the solvers' codes are its members.
    assert _select.GaitStatus is lj.GaitStatus
    assert [int(m) for m in lj.GaitStatus] == [0, 1, 2, 3, 4, 5]
    with pytest.raises(ValueError):
        lj.GaitStatus(99)


def test_gait_status_names_the_codes_of_a_result():
    """One converged gait and one invalid configuration (nothing integrated) in a batch."""
    params = lj.Params(omega=np.array([2.0, 2.0]), mu_s=np.array([0.5, 0.3]), check=False)
    g = lj.steady_gait(params, periods=1)
    names = [lj.GaitStatus(int(s)).name for s in np.asarray(g.status)]
    assert names == ["CONVERGED", "INVALID"]
    assert lj.GaitStatus(int(g.status[0])) == lj.GaitStatus.CONVERGED == 0
