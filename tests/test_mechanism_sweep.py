"""`lj.sweep(axes, mechanism=build)` maps a `Mechanism` (SPEC §9) as it maps a chain: the map equals
`lj.measure` on the same batch, whatever the chunking, and its attributes name the bodies' laws and links."""

import math
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np


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
