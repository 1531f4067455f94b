"""`lj.sweep(axes, mechanism=build)` maps a `Mechanism` (SPEC §9) as it maps a chain: the map equals
`lj.measure` on the same batch, whatever the chunking, and its attributes name the bodies' laws and links."""

import math
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


def capsules(omega, F0):
    wave = lj.Sinusoid(a=jnp.asarray(F0), omega=jnp.asarray(omega), lbar=0.0)
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None],
                        carried_by=[None, 0], links=[lj.Spring(0, 1, k=10.0), lj.Force(0, 1, wave)])  # fmt: skip


def test_sweep_maps_a_mechanism_as_measure_does():
    omega, F0 = np.array([2.0, 3.0, 5.5]), np.array([0.5, 1.5])
    settings: dict[str, Any] = dict(z=1e6, horizon=4 * math.pi, window=4 * math.pi, t_start=20.0)
    ds = lj.sweep({"omega": omega, "F0": F0}, mechanism=capsules, chunk_size=4, progress=False, **settings)
    W, F = (q.ravel() for q in np.meshgrid(omega, F0, indexing="ij"))
    m = lj.measure(capsules(W, F), **settings)
    assert ds["mean_speed"].shape == (3, 2) and (np.asarray(ds["status"]) == lj.Status.OK).all()
    np.testing.assert_allclose(np.asarray(ds["mean_speed"]).ravel(), np.asarray(m.mean_speed), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.asarray(ds["e_d"]).ravel(), np.asarray(m.e_d), rtol=1e-12)
    assert ds.attrs["kind"] == "mechanism" and ds.attrs["friction"] == "AnisotropicCoulomb, none"
    assert ds.attrs["links"] == "Spring(0, 1), Force(0, 1)" and float(np.asarray(ds["mean_speed"]).min()) < -0.01


def test_sweep_flags_an_invalid_mechanism_and_runs_the_others():
    """A map over the internal spring's stiffness with one k <= 0 (built with `check=False`):
    `on_invalid="flag"` marks that capsule INVALID (NaN figures) and the others equal `lj.measure` of
    each alone; `on_invalid="raise"` names the configuration, the link and the valid range."""

    def build(k, omega):
        wave = lj.Sinusoid(a=1.5, omega=jnp.asarray(omega), lbar=0.0)
        return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None],
                            carried_by=[None, 0], links=[lj.Spring(0, 1, k=jnp.asarray(k)), lj.Force(0, 1, wave)],
                            check=False)  # fmt: skip

    k, omega = np.array([10.0, -2.0, 4.0]), np.array([3.0])
    settings: dict[str, Any] = dict(z=1e6, horizon=4 * math.pi, window=4 * math.pi, t_start=20.0)
    ds = lj.sweep({"k": k, "omega": omega}, mechanism=build, chunk_size=2, on_invalid="flag", progress=False,
                  **settings)  # fmt: skip
    status = np.asarray(ds["status"])[:, 0]
    assert status.tolist() == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert np.isnan(float(ds["mean_speed"][1, 0])) and np.isnan(float(ds["e_d"][1, 0]))
    for i in (0, 2):
        alone = lj.measure(build(k[i : i + 1], omega), **settings)
        assert float(ds["mean_speed"][i, 0]) == float(alone.mean_speed[0])
        assert float(ds["e_d"][i, 0]) == float(alone.e_d[0])
    with pytest.raises(ValueError, match=r"grid index \(1, 0\) \(k=.*'k' of links\[0\] Spring\(0, 1\).*k > 0"):
        lj.sweep({"k": k, "omega": omega}, mechanism=build, progress=False, **settings)
