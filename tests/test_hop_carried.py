"""Hopping with carried bodies (SPEC §9 and §10): a capsule robot thrown or dropped flies, falls and
lands with its internal mass, against the independent reference (`tests/reference_mechanism.py`,
`run(..., hop=True)`), which shares no code with the package."""

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from reference_mechanism import Body, run, Sig, System


ANISO = (0.5, 0.2, 0.4, 0.15)
"""The shell's anisotropic Coulomb law: `(mu_s_fwd, mu_s_bwd, mu_k_fwd, mu_k_bwd)`."""

# Per configuration: the shell's initial height, vertical velocity and restitution. The first is thrown
# up and bounces (14 landings to t = 8), the second dropped and lands plastically. The third body, on
# isotropic Coulomb friction and tied to the shell by a spring, bounces with e = 0.5 from w0 = 0.37.
CASES = [(0.3, 0.45, 0.6), (0.2, 0.0, 0.0)]
T_END = 8.0
SAVE = np.linspace(0.0, T_END, 161)  # no landing falls on a save time


def _mechanism(layout: str = "auto") -> lj.Mechanism:
    """Both configurations as one batch: a shell (body 0) carrying an internal mass (body 1) on a spring,
    driven by 0.6 sin(3 t) between them, and a third body on the ground tied to the shell."""
    y0, w0, e = (np.asarray(q) for q in zip(*CASES))
    zero = np.zeros_like(y0)
    links = [lj.Spring(0, 1, k=10.0, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0)),
             lj.Spring(0, 2, k=5.0, rest=1.0)]  # fmt: skip
    return lj.Mechanism(
        masses=[1.0, 0.5, 0.8], friction=[lj.AnisotropicCoulomb(*ANISO), None, lj.Coulomb(0.6, 0.5)],
        carried_by=[None, 0, None], links=links, x0=[0.0, 0.0, 1.0], v0=[0.3, 0.0, 0.0],
        y0=np.stack([y0, zero, zero], -1), w0=np.stack([w0, zero, zero + 0.37], -1),
        restitution=np.stack([e, zero, zero + 0.5], -1), layout=layout,
    )  # fmt: skip


def _reference(y0: float, w0: float, e: float) -> dict:
    bodies = [Body(1.0, ANISO, v0=0.3, y0=y0, w0=w0, e=e), Body(0.5, None, carrier=0),
              Body(0.8, (0.6, 0.6, 0.5, 0.5), x0=1.0, w0=0.37, e=0.5)]  # fmt: skip
    system = System(
        bodies, springs=[(0, 1, 10.0, 0.0), (0, 2, 5.0, 1.0)], forces=[(0, 1, Sig(0.0, (0.0,), (0.6,), 3.0))]
    )
    return run(system, T_END, SAVE, hop=True)


@pytest.fixture(scope="module")
def refs() -> list[dict]:
    return [_reference(*case) for case in CASES]


def _errors(tr: lj.Trajectory, ref: dict, i: int) -> dict[str, float]:
    pairs = {"x": (tr.x, "x"), "v": (tr.v, "v"), "y": (tr.y, "y"), "vy": (tr.vy, "vy"), "e_d": (tr.e_d, "ed"),
             "w": (tr.w, "w"), "e": (tr.e, "e")}  # fmt: skip
    return {k: float(np.abs(np.asarray(a[i]) - ref[r]).max()) for k, (a, r) in pairs.items()}  # type: ignore[index]


def test_a_hopping_capsule_against_the_reference(refs):
    """Positions, velocities, heights, vertical velocities, e_d, w and e at 161 saves within 1e-8 of the
    reference at dt = 1/400 (measured 2.2e-9 at most), fourth-order convergence from dt = 1/100
    (positions 1.7e-7 there); the same landings (a carried body's counted once, with its carrier's);
    the internal mass's height and vertical velocity the shell's, bit for bit; w = e_d + Delta e to 1e-7
    at dt = 1/100 and 1e-10 at 1/400 (measured 9.5e-9 and 9.5e-12)."""
    errs = {}
    for dt in (1 / 100, 1 / 400):
        tr = lj.simulate(_mechanism(), T_END, SAVE, contact="hop", dynamics=lj.Exact(dt=dt))
        assert tr.y is not None and tr.vy is not None and tr.n_land is not None
        assert np.all(np.asarray(tr.status) == lj.Status.OK)
        for i, ref in enumerate(refs):
            errs[dt, i] = _errors(tr, ref, i)
            print(dt, i, "landings", int(tr.n_land[i]), ref["n_landings"], errs[dt, i])
            assert int(tr.n_land[i]) == int(ref["n_landings"].sum())
            np.testing.assert_array_equal(np.asarray(tr.y[i, :, 1]), np.asarray(tr.y[i, :, 0]))
            np.testing.assert_array_equal(np.asarray(tr.vy[i, :, 1]), np.asarray(tr.vy[i, :, 0]))
            bal = np.abs(np.asarray(tr.w[i] - tr.e_d[i] - (tr.e[i] - tr.e[i, 0]))).max()
            print(dt, i, "balance", bal)
            assert bal < (1e-7 if dt == 1 / 100 else 1e-10)
    assert [int(r["n_landings"][0]) for r in refs] == [14, 1] and all(int(r["n_landings"][2]) == 9 for r in refs)
    for i in range(len(CASES)):
        fine, coarse = errs[1 / 400, i], errs[1 / 100, i]
        assert max(fine.values()) < 1e-8, fine
        assert coarse["x"] / fine["x"] > 64, (coarse["x"], fine["x"])  # fourth order: 256


def test_a_hopping_capsule_in_the_array_layout_against_the_reference(refs):
    """The same capsule in the array layout (its three bodies one entry, their laws of two classes and
    none one `MixedFriction`): within 1e-8 of the reference at dt = 1/400 (measured 2.2e-9), the same
    landings, the internal mass's height the shell's, bit for bit; in float32 at dt = 1/100 within 1e-4
    (positions, heights, e_d), the same landings."""
    for dt, dtype, tol in ((1 / 400, jnp.float64, 1e-8), (1 / 100, jnp.float32, 1e-4)):
        tr = lj.simulate(_mechanism("array"), T_END, SAVE, contact="hop", dynamics=lj.Exact(dt=dt), dtype=dtype)
        assert tr.y is not None and tr.vy is not None and tr.n_land is not None and tr.x.dtype == dtype
        assert np.all(np.asarray(tr.status) == lj.Status.OK)
        for i, ref in enumerate(refs):
            err = _errors(tr, ref, i)
            print("array", dtype.__name__, i, "landings", int(tr.n_land[i]), err)
            assert int(tr.n_land[i]) == int(ref["n_landings"].sum())
            worst = max(err["x"], err["y"], err["e_d"]) if dtype == jnp.float32 else max(err.values())
            assert worst < tol, err
            np.testing.assert_array_equal(np.asarray(tr.y[i, :, 1]), np.asarray(tr.y[i, :, 0]))


def test_a_carried_body_rides_and_lands_with_its_carrier_in_float32(refs):
    """float32: the thrown capsule within 1e-4 of the reference (positions, heights, e_d), the same
    landings."""
    tr = lj.simulate(_mechanism(), T_END, SAVE, contact="hop", dynamics=lj.Exact(dt=1 / 100), dtype=jnp.float32)
    assert tr.y is not None and tr.n_land is not None and tr.x.dtype == jnp.float32
    for i, ref in enumerate(refs):
        err = _errors(tr, ref, i)
        print("float32", i, err)
        assert int(tr.n_land[i]) == int(ref["n_landings"].sum())
        assert max(err["x"], err["y"], err["e_d"]) < 1e-4, err
