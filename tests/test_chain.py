"""Chains of N masses: the N = 2 chain against the two-mass engine, symmetries, energy,
a user-defined friction law, float32, bad input, and the front ends under `jax.jit` (a chain built
from traced values measures and simulates as it does eagerly; an invalid or unresolved one is
flagged in its own result). (The comparison with the independent N-mass reference is in
`test_against_reference.py`.)"""

from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from docs_examples import doc_class
from locomotion_jax.dynamics._flat import FlatBatch
from locomotion_jax.run._batch import prepare_chain


T_END = 60.0
SAVE = np.linspace(0.0, T_END, 61)


def _sym_chain(n, friction, phi=2 * np.pi / 3, a=0.08, omega=3.0, d=0.0):
    return lj.Chain(masses=[1.0] * n, d=d, waveforms=lj.TravellingWave(a, omega, phi), friction=friction)


def _reversed(chain: lj.Chain, friction) -> lj.Chain:
    """The mirror image of a chain: mass order reversed, springs' signals and offsets reversed,
    and forward/backward friction swapped by the caller's `friction`."""
    w = chain.waves
    return lj.Chain(
        masses=chain.m[..., ::-1], k=chain.k[..., ::-1], d=-chain.d[..., ::-1], lbar=chain.lbar[..., ::-1],
        c=chain.c[..., ::-1], waveforms=lj.SpringFourier(w.cos[..., ::-1, :], w.sin[..., ::-1, :], w.omega),
        friction=friction,
    )  # fmt: skip


# -- the paper's model as N = 2 -------------------------------------------------------------------


@pytest.mark.parametrize("contact,start", [("strict", "paper"), ("paper", "paper"), ("strict", "relaxed")])
def test_two_mass_chain_equals_paper_engine(contact, start):
    """`Chain.from_params` on the N-mass engine gives the two-mass engine's measurements."""
    p = lj.Params.stack(
        [
            lj.Params(omega=2.0),
            lj.Params(omega=16.0),
            lj.Params(omega=6.0, d=-0.3, mhat=0.4),
            lj.Params(omega=3.0, d=0.0),
            lj.Params(omega=9.5, a=0.05),
        ]  # fmt: skip
    )
    kw: dict[str, Any] = dict(z=2.0, horizon=300.0, contact=contact, start=start)
    ref = lj.measure(p, **kw)
    got = lj.measure(lj.Chain.from_params(p), **kw)
    assert np.array_equal(np.asarray(got.status), np.asarray(ref.status))
    assert np.array_equal(np.asarray(got.regime), np.asarray(ref.regime))
    # The symmetric d = 0 case (index 3: both masses switch at once, the speed is zero) is
    # sensitive to rounding, which differs between the engines' batched kernels.
    rtol = np.array([1e-10, 1e-10, 1e-10, 1e-7, 1e-10])
    for name in ("tau_z", "e_z", "e_d", "work", "t_start"):
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(ref, name))
        with np.errstate(invalid="ignore"):  # inf - inf where z is not reached: equal by a == b
            same = (a == b) | (np.abs(a - b) <= rtol * np.abs(b)) | (np.isnan(a) & np.isnan(b))
        assert same.all(), (name, a, b)
    np.testing.assert_allclose(got.mean_speed, ref.mean_speed, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.stick_fraction, ref.stick_fraction, rtol=1e-9, atol=1e-12)


def test_two_mass_chain_trajectory_equals_paper_engine():
    p = lj.Params.stack([lj.Params(omega=2.0), lj.Params(omega=16.0, d=0.25)])
    ref = lj.simulate(p, T_END, SAVE)
    got = lj.simulate(lj.Chain.from_params(p), T_END, SAVE)
    np.testing.assert_allclose(got.x, ref.x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got.v, ref.v, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got.e_d, ref.e_d, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(got.e, ref.e, rtol=1e-10)
    np.testing.assert_allclose(got.N[..., 0], ref.N1, rtol=1e-10)
    np.testing.assert_allclose(got.X, ref.X, atol=1e-10)


def test_natural_frequencies_and_t_start():
    """Independent of the package: with one mass held a uniform chain of N masses is the
    fixed-free chain, with frequencies $2\\sqrt{k/m}\\,\\sin((2r-1)\\pi/(2(2N-1)))$ when the end mass is held."""
    k, m = 50.0, 1.0
    for n in (2, 3, 5):
        c = lj.Chain(masses=[m] * n, k=k)
        held_end = np.sort(np.asarray(c.natural_frequencies())[0])
        expect = 2 * np.sqrt(k / m) * np.sin((2 * np.arange(1, n) - 1) * np.pi / (2 * (2 * n - 1)))
        np.testing.assert_allclose(held_end, expect, rtol=1e-12)
    p = lj.Params(mhat=0.3, k=40.0)
    np.testing.assert_allclose(lj.Chain.from_params(p).t_start, 80 * 2 * np.pi / np.sqrt(40.0 / 1.4), rtol=1e-12)


# -- symmetries (SPEC §8) -----------------------------------------------------------------------------


@pytest.mark.parametrize("n", [3, 4, 5])
def test_mirror_symmetric_chain_does_not_move(n):
    """A chain equal to its mirror image (d = 0, palindromic masses and spring signals, isotropic
    friction) cannot move its centre of mass: the motion equals its own mirror image."""
    S = n - 1
    rng = np.random.default_rng(n)
    A, B = rng.normal(0, 0.03, (S, 2)), rng.normal(0, 0.03, (S, 2))
    A, B = (A + A[::-1]) / 2, (B + B[::-1]) / 2  # s_j = s_{S-1-j}
    masses = np.linspace(0.8, 1.2, n)
    masses = (masses + masses[::-1]) / 2
    chains = [
        lj.Chain(masses=masses, d=0.0, waveforms=lj.SpringFourier(A, B, 3.0), friction=lj.Coulomb(0.7, 0.5)),
        _sym_chain(n, lj.Coulomb(0.7, 0.5), phi=0.0),
    ]
    traj = lj.simulate(lj.Chain.stack(chains), T_END, SAVE)
    assert np.all(np.asarray(traj.status) == lj.Status.OK)
    drift = np.abs(np.asarray(traj.X) - np.asarray(traj.X)[..., :1]).max()
    assert drift < 1e-9, drift
    assert np.asarray(traj.n_switch).min() > 10  # it does stick and slip


def test_anisotropic_friction_moves_and_mirrors():
    """d = 0 with anisotropic friction: an in-phase sinusoid moves the chain, and swapping
    forward and backward coefficients mirrors the motion exactly."""
    fr = lj.AnisotropicCoulomb(mu_s_fwd=0.5, mu_s_bwd=0.9, mu_k_fwd=0.3, mu_k_bwd=0.7)
    fwd = _sym_chain(4, fr, phi=0.0)
    bwd = _sym_chain(4, fr.mirrored(), phi=0.0)
    a = lj.simulate(fwd, T_END, SAVE)
    b = lj.simulate(bwd, T_END, SAVE)
    moved = float(a.X[-1] - a.X[0])
    assert moved > 0.05, moved  # forward: the direction of least resistance
    np.testing.assert_allclose(b.X - b.X[0], -(a.X - a.X[0]), atol=1e-9)


@pytest.mark.parametrize("d", [0.0, 0.4])
def test_reversed_wave_gives_mirror_motion(d):
    """A travelling wave and its mirror image (reversed springs, forward/backward swapped,
    d -> -d) give mirror motions of the centre of mass."""
    fr = lj.AnisotropicCoulomb(mu_s_fwd=0.6, mu_s_bwd=0.8, mu_k_fwd=0.4, mu_k_bwd=0.6)
    chain = lj.Chain(masses=[1.0, 1.3, 0.8, 1.1], d=d, c=[0.01, 0.02, 0.01, 0.03],
                     waveforms=lj.TravellingWave(0.06, 2.5, np.pi / 2), friction=fr)  # fmt: skip
    mirror = _reversed(chain, fr.mirrored())
    a = lj.simulate(chain, T_END, SAVE)
    b = lj.simulate(mirror, T_END, SAVE)
    assert abs(float(a.X[-1] - a.X[0])) > 0.01
    np.testing.assert_allclose(b.X - b.X[0], -(a.X - a.X[0]), atol=1e-9)
    np.testing.assert_allclose(b.e_d, a.e_d, rtol=1e-9, atol=1e-12)


# -- energy, friction laws, actuators ------------------------------------------------------------------


def _kinds():
    wave = lj.TravellingWave(0.06, 2.0, np.pi / 3)
    return {
        "coulomb": lj.Chain(masses=[1.0, 0.8, 1.2], waveforms=wave),
        "anisotropic": lj.Chain(masses=[1.0] * 4, waveforms=wave, friction=lj.AnisotropicCoulomb(0.6, 0.9, 0.4, 0.7)),
        "stribeck": lj.Chain(masses=[1.0] * 3, waveforms=wave, friction=lj.Stribeck(0.7, 0.4, v_s=0.05)),
        "force": lj.Chain(
            masses=[1.0] * 3, d=0.3, waveforms=lj.TravellingWave(0.8, 2.0, np.pi / 2), actuator=lj.InternalForce()
        ),  # fmt: skip
    }


@pytest.mark.parametrize("kind", ["coulomb", "anisotropic", "stribeck", "force"])
def test_energy_balance(kind):
    """Eq. (16) generalised: the actuator's work equals e_d + the change of energy."""
    chain = _kinds()[kind]
    traj = lj.simulate(chain, T_END, SAVE)
    assert int(traj.status) == lj.Status.OK
    balance = np.asarray(traj.w - traj.e_d - (traj.e - traj.e[0]))
    scale = float(np.max(np.asarray(traj.e_d)))
    assert scale > 0.1
    assert np.abs(balance).max() < 1e-6 * scale, np.abs(balance).max()


ViscousCoulomb = doc_class("mechanisms.md", "ViscousCoulomb")  # a user's law: mu(|v|) = mu_k + b |v|


def test_user_friction_law():
    """Extension is one class: a user's law runs, and with b = 0 it is Coulomb's."""
    wave = lj.TravellingWave(0.06, 2.0, np.pi / 3)
    mk = lambda fr: lj.Chain(masses=[1.0] * 3, waveforms=wave, friction=fr)
    f = lambda b: ViscousCoulomb(jnp.asarray(0.7), jnp.asarray(0.5), jnp.asarray(b))
    user0 = lj.simulate(mk(f(0.0)), T_END, SAVE)
    coul = lj.simulate(mk(lj.Coulomb(0.7, 0.5)), T_END, SAVE)
    np.testing.assert_allclose(user0.x, coul.x, atol=1e-12)
    user = lj.simulate(mk(f(2.0)), T_END, SAVE)
    assert np.abs(np.asarray(user.x - coul.x)).max() > 1e-4  # the viscous term acts
    balance = np.asarray(user.w - user.e_d - (user.e - user.e[0]))
    assert np.abs(balance).max() < 1e-6 * float(user.e_d[-1])


class PlainRestLength(lj.AbstractActuator):
    """A user's actuator: the paper's rest length, with the defaults (it may apply a force, so
    the engine carries the force terms) and its own power written on arrays."""

    def split(self, lbar, s):
        return lbar + s, 0 * s

    def power(self, tension, dl0, f, v):
        return -jnp.sum(tension * dl0, -1) + jnp.sum(f * -jnp.diff(v, axis=-1), -1)


def test_user_actuator():
    """Extension is one class for actuators too: a user's (the engine's general paths: force
    terms carried, power on arrays and differentiated by the engine) equals `RestLength`."""
    wave = lj.TravellingWave(0.06, 2.0, np.pi / 3)
    mk = lambda act: lj.Chain(masses=[1.0, 1.2, 0.9], d=[0.5, -0.3], waveforms=wave, actuator=act)
    user = lj.simulate(mk(PlainRestLength()), T_END, SAVE)
    ref = lj.simulate(mk(lj.RestLength()), T_END, SAVE)
    np.testing.assert_allclose(user.x, ref.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(user.w, ref.w, rtol=1e-12, atol=1e-12)


def test_float32_runs_close_to_float64():
    chain = _kinds()["anisotropic"]
    a = lj.measure(chain, z=1.0, horizon=200.0)
    b = lj.measure(chain, z=1.0, horizon=200.0, dtype=jnp.float32)
    assert b.tau_z.dtype == jnp.float32
    np.testing.assert_allclose(float(b.tau_z), float(a.tau_z), rtol=5e-3)


# -- bad input -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(masses=[1.0, 1.0, 1.0], k=[50.0, 50.0, 50.0]), "'k'.*length 2"),
        (dict(masses=[1.0, 1.0, 1.0], c=[0.1, 0.1]), "'c'.*length 3"),
        (dict(masses=[1.0, 0.0, 1.0]), "'masses' of mass 1"),
        (dict(masses=[1.0, 1.0, 1.0], k=[50.0, -1.0]), "'k' of spring 1"),
        (dict(masses=[1.0, 1.0, 1.0], d=[0.5, 4.0]), "'d' of spring 1"),
        (dict(masses=[1.0, 1.0], friction=lj.AnisotropicCoulomb(0.7, 0.5, 0.5, 0.6)), "'mu_s_bwd' of mass 0"),
        (dict(masses=[1.0, 1.0], friction=lj.AnisotropicCoulomb([0.7, 0.4], 0.7, 0.5, 0.5)), "'mu_s_fwd' of mass 1"),
        (dict(masses=[1.0, 1.0], friction=lj.Coulomb(0.4, 0.5)), "'mu_s' of mass 0"),
        (dict(masses=[1.0]), "N >= 2"),
        (dict(masses=[1.0, 1.0, 1.0], waveforms=[lj.Sinusoid(0.1, 2.0, 3.0)]), "1 waveforms for 2 springs"),
        (dict(masses=[1.0] * 3, waveforms=[lj.Sinusoid(0.1, 2.0, 3.0), lj.Sinusoid(0.1, 3.0, 3.0)]), "omega"),
    ],
)
def test_bad_input_names_parameter(kwargs, match):
    with pytest.raises(ValueError, match=match):
        lj.Chain(**kwargs)


def test_invalid_configuration_flagged_in_batch():
    """With check=False one invalid configuration is flagged INVALID; the others are unchanged."""
    masses = jnp.asarray([[1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.2, 0.9, 1.0]])
    wave = lj.TravellingWave(0.06, 2.0, np.pi / 3)
    batch = lj.Chain(masses=masses, waveforms=wave, check=False)
    m = lj.measure(batch, z=1.0, horizon=100.0)
    assert list(np.asarray(m.status)) == [lj.Status.OK, lj.Status.INVALID, lj.Status.OK]
    assert not np.any(np.isnan(np.asarray(m.tau_z)))
    alone = lj.measure(lj.Chain(masses=masses[2], waveforms=wave), z=1.0, horizon=100.0)
    np.testing.assert_allclose(m.tau_z[2], alone.tau_z, rtol=1e-12)


def test_wrong_dynamics_or_waveform_for_chain():
    chain = _kinds()["coulomb"]

    # (the package's message, or the test suite's type checker's: both name the argument)
    with pytest.raises(TypeError, match="dynamics"):
        lj.measure(chain, dynamics="exact")  # pyright: ignore[reportArgumentType, reportCallIssue]
    with pytest.raises(ValueError, match="carries its own waveforms"):
        lj.simulate(chain, 10.0, waveform=lj.Sinusoid(0.1, 2.0, 3.0))


# -- maps over chains -----------------------------------------------------------------------------


def _worm(phi, omega, a=0.08):
    return lj.Chain(masses=np.ones(phi.shape + (3,)), d=0.0, waveforms=lj.TravellingWave(a, omega, phi),
                    friction=lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7), check=False)  # fmt: skip


def test_sweep_over_chains_equals_measure(tmp_path):
    """`sweep(axes, mechanism=...)`: each point of the map is `measure` of its own chain, in chunks
    (the last one padded), written to NetCDF; an invalid point is flagged, the others run."""
    phi = np.array([-np.pi / 2, 0.0, np.pi / 2])
    omega = np.array([3.0, -1.0])  # omega < 0 is invalid
    kw: dict[str, Any] = dict(z=1.0, horizon=80.0, t_start=30.0)
    ds = lj.sweep({"phi": phi, "omega": omega}, mechanism=_worm, chunk_size=4, on_invalid="flag",
                  path=tmp_path / "worm.nc", progress=False, **kw)  # fmt: skip
    P, W = np.meshgrid(phi, omega, indexing="ij")
    ref = lj.measure(_worm(P, W), **kw)
    assert ds.stick_fraction.dims == ("phi", "omega", "mass")
    for name in ("tau_z", "e_z", "mean_speed", "stick_fraction", "status", "regime", "balance"):
        np.testing.assert_allclose(ds[name].values, np.asarray(getattr(ref, name)), rtol=1e-12, err_msg=name)
    assert (ds.status.values[:, 1] == lj.Status.INVALID).all()
    assert (ds.status.values[:, 0] == lj.Status.OK).all() and ds.reached.values[:, 0].any()
    xr = pytest.importorskip("xarray")
    with xr.open_dataset(tmp_path / "worm.nc") as back:
        np.testing.assert_array_equal(back.tau_z.values, ds.tau_z.values)
    with pytest.raises(ValueError, match=r"Invalid configuration at grid index \(0, 1\).*omega"):
        lj.sweep({"phi": phi, "omega": omega}, mechanism=_worm, progress=False, **kw)
    with pytest.raises(ValueError, match="batch shape"):
        lj.sweep({"phi": phi}, fixed={"omega": 2.0}, mechanism=lambda phi, omega: _worm(phi[:1], omega),
                 progress=False, **kw)  # fmt: skip
    with pytest.raises(ValueError, match="t_start is for chain maps"):
        lj.sweep({"omega": [1.0, 2.0]}, t_start=10.0, progress=False)


def test_chain_initial_state_continues_a_run():
    """`initial=(x, v)` for a chain: the run from the state a run reached at t = 5T (T the
    drive's period, so the drive's phase is the same) continues that run, to the integrator's
    accuracy (the two runs step on different grids); `measure` takes it too."""
    worm = lj.Chain(masses=[1.0, 1.2, 0.8], k=40.0, d=0.3, lbar=3.0, c=0.02,
                    waveforms=lj.TravellingWave(a=0.08, omega=2.5, phi=1.0),
                    friction=lj.AnisotropicCoulomb(0.6, 0.9, 0.4, 0.7))  # fmt: skip
    T = 2 * np.pi / 2.5
    dyn = lj.Exact(dt=0.005)
    full = lj.simulate(worm, t_end=7 * T, save_at=np.array([5 * T, 6 * T, 7 * T]), dynamics=dyn)
    x0, v0 = np.asarray(full.x[0]), np.asarray(full.v[0])
    part = lj.simulate(worm, t_end=2 * T, save_at=np.array([T, 2 * T]), dynamics=dyn, initial=(x0, v0))
    assert part.start == "initial" and int(part.status) == lj.Status.OK
    np.testing.assert_allclose(np.asarray(part.x), np.asarray(full.x[1:]), atol=1e-7)
    np.testing.assert_allclose(np.asarray(part.v), np.asarray(full.v[1:]), atol=1e-6)
    # The energy bookkeeping restarts at zero: the work and dissipation over [5T, 7T].
    np.testing.assert_allclose(float(part.e_d[-1]), float(full.e_d[-1] - full.e_d[0]), rtol=1e-6)
    m = lj.measure(worm, z=0.2, horizon=40.0, t_start=0.0, initial=(x0, v0), dynamics=dyn)
    assert m.start == "initial" and int(m.status) == lj.Status.OK and bool(m.reached)
    # Forward mode through the initial state: the chain is invariant under a translation, so
    # shifting every initial position by s shifts every later one by s (d x / d s = 1, d v / d s = 0).
    end = lambda x: (lambda tr: (tr.x[-1], tr.v[-1]))(
        lj.simulate(worm, t_end=2 * T, save_at=np.array([2 * T]), dynamics=dyn, initial=(x, v0))
    )
    _, (dx, dv) = jax.jvp(end, (jnp.asarray(x0),), (jnp.ones(3),))
    np.testing.assert_allclose(np.asarray(dx), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(dv), 0.0, atol=1e-12)


def test_chain_initial_state_checks():
    """A chain's initial state is refused where its values are known (naming the masses out of
    order), flagged INVALID in its own result under `jit` without changing its batch-mates,
    by the exact and the smoothed dynamics."""
    worm = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(0.05, 2.0, 1.0))
    x = np.array([0.0, 3.0, 6.0])
    with pytest.raises(ValueError, match=r"x_1 < x_2 \(mass 1\)"):
        lj.simulate(worm, t_end=1.0, initial=(np.array([0.0, 3.0, 2.0]), np.zeros(3)))
    with pytest.raises(ValueError, match="finite"):
        lj.simulate(worm, t_end=1.0, initial=(x, np.array([0.0, np.nan, 0.0])))
    with pytest.raises(ValueError, match="broadcast"):
        lj.simulate(worm, t_end=1.0, initial=(x[:2], np.zeros(3)))
    # Past the front end's check (as under `jit`, where the values are not known there): the
    # dynamics flag the configuration whose positions are out of order, and only that one.
    flat, valid, _ = prepare_chain(lj.Chain.stack([worm, worm]), None)
    rows = jnp.asarray([[0.0, 3.0, 6.0, 0.0, 0.0, 0.0], [0.0, 3.0, 2.0, 0.0, 0.0, 0.0]])
    batch = FlatBatch(flat, valid, t_start=jnp.zeros(2), initial=rows)
    out = lj.Exact().measure(batch, 0.1, 5.0, 2.0, "strict", "paper")
    alone = lj.measure(worm, z=0.1, horizon=5.0, window=2.0, t_start=0.0, initial=(x, np.zeros(3)))
    assert [int(s) for s in np.asarray(out["status"])] == [lj.Status.OK, lj.Status.INVALID]
    np.testing.assert_allclose(float(out["tau_z"][0]), float(alone.tau_z), rtol=1e-12)
    smooth = lj.Smoothed(eps=1e-2)
    out = smooth.measure(batch, 0.1, 5.0, 2.0, "strict", "paper")
    alone = lj.measure(worm, z=0.1, horizon=5.0, window=2.0, t_start=0.0, initial=(x, np.zeros(3)), dynamics=smooth)
    assert [int(s) for s in np.asarray(out["status"])] == [lj.Status.OK, lj.Status.INVALID]
    np.testing.assert_allclose(float(out["tau_z"][0]), float(alone.tau_z), rtol=1e-12)


def test_chain_driven_by_splines_batches_validates_and_refuses_a_file(tmp_path):
    """A chain takes any waveform per spring (here a `Spline`, batched along its control values):
    a batch equals its configurations run alone, a stroke beyond `lbar` or a NaN control value is
    refused naming the waveform, and a file refuses to hold it. (Against the reference:
    `tests/test_against_reference.py::test_chain_driven_by_splines_against_reference`.)"""
    ctrl = np.array([[0.05, 0.08, -0.02, -0.07, 0.0, 0.03], [0.02, 0.06, 0.01, -0.05, -0.02, 0.01]])
    mk = lambda c: lj.Chain(masses=[1.0, 1.0, 1.0], d=0.0, waveforms=lj.Spline(c, 3.0, 3.0),
                            friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7))  # fmt: skip
    both = mk(ctrl)
    assert both.batch_shape == (2,)
    m = lj.measure(both, z=0.05, t_start=2.0, horizon=10.0)
    for i in range(2):
        alone = lj.measure(mk(ctrl[i]), z=0.05, t_start=2.0, horizon=10.0)
        assert int(m.status[i]) == int(alone.status) == lj.Status.OK
        np.testing.assert_allclose(np.asarray(m.e_d)[i], float(alone.e_d), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(both[i].stroke()), np.asarray(mk(ctrl[i]).stroke()))
    with pytest.raises(ValueError, match="'stroke' of Spline"):
        mk(np.array([0.5, 3.5, 0.0, 0.0]))  # stroke 3.5 >= lbar = 3
    with pytest.raises(ValueError, match="control"):
        mk(np.array([0.5, np.nan, 0.0, 0.0]))
    flagged = lj.measure(
        lj.Chain(masses=[1.0, 1.0, 1.0], d=0.0, waveforms=lj.Spline(np.array([[0.1] * 4, [3.5] * 4]), 3.0, 3.0),
                 check=False),
        z=0.05, t_start=2.0, horizon=5.0,
    )  # fmt: skip
    assert [int(s) for s in flagged.status] == [lj.Status.OK, lj.Status.INVALID]
    with pytest.raises(lj.MechanismFileError, match="Spline"):
        lj.save_mechanism(mk(ctrl[0]), tmp_path / "spline.toml")


# Under jax.jit.

SHORT: dict[str, Any] = dict(z=0.1, horizon=5.0, window=2.0)


def _chain(k, omega=2.0):
    return lj.Chain(masses=[1.0, 1.0, 1.0], k=k, waveforms=lj.TravellingWave(0.05, omega, 1.0))


def test_measure_and_simulate_of_a_traced_chain_equal_eager():
    for t_start in (1.0, None):  # an explicit start (checked on the host) and the chain's own
        run = lambda k: lj.measure(_chain(k), t_start=t_start, **SHORT).mean_speed  # noqa: B023
        np.testing.assert_allclose(jax.jit(run)(50.0), run(50.0), rtol=1e-12, atol=1e-15)
    sim = lambda k: lj.simulate(_chain(k), 2.0, np.linspace(0.0, 2.0, 5)).X
    np.testing.assert_allclose(jax.jit(sim)(50.0), sim(50.0), rtol=1e-12, atol=1e-15)


def test_traced_chain_flags_invalid_and_unresolved():
    status = jax.jit(lambda k, om: lj.measure(_chain(k, om), t_start=1.0, **SHORT).status)
    assert int(status(50.0, 2.0)) == lj.Status.OK
    assert int(status(-1.0, 2.0)) == lj.Status.INVALID
    assert int(status(50.0, 1e4)) == lj.Status.UNRESOLVED
