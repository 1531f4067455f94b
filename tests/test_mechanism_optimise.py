"""`lj.optimise` of a `lj.Mechanism` (`optimisation._mechanism`, `lj.MechanismOptimiseSettings`).

1. A capsule whose internal mass sits on a spring and a damper, driven by an internal force, on
   anisotropic ground, backwards: the optimum's gait is checked by a direct `simulate` and by the
   independent reference (`tests/reference_mechanism.py`, with the optimum's Fourier force; within the
   step's truncation error, which shrinks with the step), and it beats the best sinusoid of a small
   batched sweep of the test's own.
2. The capsule of `experiments/capsule.py` on isotropic Coulomb ground at a fixed frequency, forward,
   under a force bound the optimum does not reach: its cost of transport is the physical floor
   mu_k (M + m) g (a body that never slides backward dissipates exactly mu_k N per distance;
   any backward slide costs more), checked by a direct simulation from rest (`lj.measure`), and no
   sinusoid under the same bound is as fast (a batched sweep of amplitudes and phases).

3. The same capsule with splines (`MechanismOptimiseSettings(shape="spline")`) under a force bound at
   which no sinusoid of the screen moves it: the optimum's control values are within the bound, its
   exact stroke matches a dense sampling, its cost is at or above the physical floor, and its gait
   from rest agrees with the independent reference (which has its own B-spline).
4. float32: the optimiser keeps the mechanism's dtype, and the float32 optimum's gait agrees with
   the float64 reference to float32's resolution.

Slow (about 2 to 5 minutes each)."""

from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from reference_mechanism import Body, run, Sig, System


MU = (0.5, 0.4, 0.4, 0.3)
K, C, V_MIN, A_MAX = 10.0, 0.5, 0.005, 0.8


def _capsule(force=None, check=True):
    force = lj.Sinusoid(a=0.6, omega=3.0, lbar=0.0) if force is None else force
    links = [lj.Spring(0, 1, k=K, rest=0.0), lj.Damper(0, 1, c=C), lj.Force(0, 1, force)]
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*MU), None], carried_by=[None, 0],
                        links=links, check=check)  # fmt: skip


@pytest.fixture(scope="module")
def optimum():
    s = lj.MechanismOptimiseSettings(
        amplitudes=4, frequencies=8, local=2, max_iter=15, transient=20, dt=0.01, omega_min=0.15, omega_max=2.0
    )
    return lj.optimise(_capsule(), v_min=V_MIN, a_max=A_MAX, direction=-1, settings=s)


@pytest.mark.slow
def test_mechanism_optimum_verified_by_simulate_and_the_reference(optimum):
    opt = optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.feasible_exact and opt.stable_exact and opt.elements == [2]
    assert -opt.mean_speed_exact >= V_MIN and float(np.max(opt.stroke_exact)) <= A_MAX * (1 + 1e-12)
    g = lj.steady_gait(opt.mechanism, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.01))
    assert int(g.status) == lj.GaitStatus.CONVERGED
    assert abs(float(g.cost_of_transport) - opt.cost_of_transport_exact) < 1e-9
    u, v = float(g.state[0]), np.asarray(g.state[1:], float)
    T = float(g.period)
    # A direct simulation from the orbit's section state, over one gait period.
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*MU), None], carried_by=[None, 0],
                     links=opt.mechanism.links, x0=[0.0, u], v0=v)  # fmt: skip
    traj = lj.simulate(M, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.01))
    dX = float(traj.X[-1] - traj.X[0])
    speed, cost = dX / T, float(traj.e_d[-1]) / abs(dX)
    # The independent reference with the optimum's force, s(t) = sum A_n cos(n w t) + B_n sin(n w t).
    H = opt.cos.shape[-1]
    force = Sig(0.0, tuple(opt.cos[0]), tuple(opt.sin[0]), opt.omega)
    S = System([Body(1.0, MU, x0=0.0, v0=v[0]), Body(0.5, None, carrier=0, x0=u, v0=v[1])],
               springs=[(0, 1, K, 0.0)], forces=[(0, 1, force)], dampers=[(0, 1, C)])  # fmt: skip
    ref = run(S, T, np.array([0.0, T]))
    r_dX = ref["com"][1] - ref["com"][0]
    r_speed, r_cost = r_dX / T, ref["ed"][1] / abs(r_dX)
    print(f"optimum ({H} harmonics): speed {opt.mean_speed_exact:.10f}, simulate {speed:.10f}, reference "
          f"{r_speed:.10f}; cost {opt.cost_of_transport_exact:.10f}, simulate {cost:.10f}, reference {r_cost:.10f}; "
          f"simulated from its start: {opt.simulation_agreement:.1e}")  # fmt: skip
    assert abs(speed / opt.mean_speed_exact - 1) < 1e-8 and abs(cost / opt.cost_of_transport_exact - 1) < 1e-8
    assert opt.simulation_agreement < 1e-6
    # Against the reference the difference is the engine's truncation error at the optimiser's step
    # (dt = 0.01 against a period of the second harmonic of 0.29): it shrinks with the step.
    fine = lj.simulate(M, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.0025))
    f_dX = float(fine.X[-1] - fine.X[0])
    f_speed, f_cost = f_dX / T, float(fine.e_d[-1]) / abs(f_dX)
    err = max(abs(r_speed / speed - 1), abs(r_cost / cost - 1))
    err_fine = max(abs(r_speed / f_speed - 1), abs(r_cost / f_cost - 1))
    print(f"against the reference: {err:.1e} at dt = 0.01, {err_fine:.1e} at dt = 0.0025")
    assert err < 2e-5 and err_fine < err / 8


@pytest.mark.slow
def test_mechanism_optimum_beats_the_best_sinusoid_of_a_sweep(optimum):
    """A batched sweep of 4 x 8 sinusoids a sin(w t) (a up to a_max, w over the optimiser's range):
    the cheapest one fast enough costs more than the optimum."""
    a = np.array([0.2, 0.4, 0.6, 0.8])
    w = np.geomspace(1.0, 10.0, 8)
    A, W = (x.ravel() for x in np.meshgrid(a, w, indexing="ij"))
    batch = _capsule(lj.Sinusoid(a=jnp.asarray(A), omega=jnp.asarray(W), lbar=0.0))
    g = lj.steady_gait(batch, periods=(1, 2), transient=20, dynamics=lj.Exact(dt=0.01))
    ok = np.asarray(g.converged) & np.asarray(g.stable) & (-np.asarray(g.mean_speed) >= V_MIN)
    best = float(np.min(np.where(ok, np.asarray(g.cost_of_transport), np.inf)))
    print(f"best sinusoid of the sweep: {best:.6f} ({int(ok.sum())} of {ok.size} fast enough); optimum "
          f"{optimum.cost_of_transport_exact:.6f}; the optimiser's own screen: {optimum.sinusoid}")  # fmt: skip
    assert ok.any() and optimum.cost_of_transport_exact < best


ISO = lj.Coulomb(0.5, 0.4)
M_BODY, M_IN, K_ISO = 1.0, 0.5, 10.0
OMEGA, F_MAX, V_ISO = 3.0, 2.0, 0.05
FLOOR = 0.4 * (M_BODY + M_IN)  # mu_k (M + m) g, g = 1


def _iso_capsule(cos, sin):
    """The capsule of experiments/capsule.py driven by a Fourier force of omega = 3 (rows: a batch)."""
    wave = lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), OMEGA, 0.0)
    return lj.Mechanism(masses=[M_BODY, M_IN], friction=[ISO, None], carried_by=[None, 0],
                        links=[lj.Spring(0, 1, k=K_ISO, rest=0.0), lj.Force(0, 1, wave)])  # fmt: skip


def _measured(mech, settle=100, periods=40):
    T = 2 * np.pi / OMEGA
    res = lj.measure(mech, z=1e6, horizon=periods * T, window=periods * T, t_start=settle * T)
    v, ed = np.asarray(res.mean_speed), np.asarray(res.e_d)
    return np.asarray(res.status), v, np.where(v > 0, ed / np.where(v > 0, v * periods * T, 1.0), np.inf)


@pytest.fixture(scope="module")
def iso_optimum():
    s = lj.MechanismOptimiseSettings(amplitudes=4, phases=4, local=2, max_iter=30)
    return lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA, harmonics=3,
                       settings=s)  # fmt: skip


@pytest.mark.slow
def test_isotropic_capsule_optimum_sits_on_the_physical_floor(iso_optimum):
    opt = iso_optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.feasible_exact and opt.stable_exact and opt.elements == [1] and opt.omega == pytest.approx(OMEGA)
    assert opt.mean_speed_exact >= V_ISO
    # Interior in the force: the bound does not bind (the speed constraint and the floor do).
    peak = float(np.max(opt.stroke_exact))
    assert peak < 0.75 * F_MAX
    # The floor: e_d >= mu_k N |distance|, equal only if the body never slides backward.
    assert FLOOR * (1 - 1e-9) <= opt.cost_of_transport_exact <= FLOOR * (1 + 1e-6)
    # A direct simulation from rest with the optimum's force: the same speed and cost.
    status, v, cost = _measured(opt.mechanism)
    print(f"optimum: speed {opt.mean_speed_exact:.10f}, measured {float(v):.10f}; cost "
          f"{opt.cost_of_transport_exact:.12f}, measured {float(cost):.12f}; peak force {peak:.4f}")  # fmt: skip
    assert int(status) == lj.Status.OK
    assert abs(float(v) / opt.mean_speed_exact - 1) < 1e-8 and abs(float(cost) / opt.cost_of_transport_exact - 1) < 1e-8
    T = 2 * np.pi / OMEGA
    traj = lj.simulate(opt.mechanism, t_end=110 * T, save_at=jnp.linspace(100 * T, 110 * T, 2001))
    assert float(np.min(np.asarray(traj.v)[:, 0])) >= -1e-12  # the body never slides backward
    assert float(np.max(np.asarray(traj.v)[:, 0])) > 0.1


@pytest.mark.slow
def test_isotropic_capsule_no_sinusoid_under_the_bound_is_as_good(iso_optimum):
    """Sinusoids A sin(omega t + phi), 25 amplitudes up to the bound times 12 phases, one batched
    `lj.simulate` over 10 periods after 20: none meets the speed at a lower cost, and every one pays
    at least the floor on its body's own displacement, e_d >= mu_k (M + m) g |x_0(t1) - x_0(t0)| (the
    centre of mass also carries the internal mass's free oscillation, which need not be periodic)."""
    U, PHI = (q.ravel() for q in np.meshgrid(np.linspace(0.04, 1.0, 25), np.linspace(0, 2 * np.pi, 12, endpoint=False)))
    cos, sin = np.zeros((U.size, 3)), np.zeros((U.size, 3))
    cos[:, 0], sin[:, 0] = F_MAX * U * np.sin(PHI), F_MAX * U * np.cos(PHI)
    T = 2 * np.pi / OMEGA
    traj = lj.simulate(_iso_capsule(cos, sin), t_end=30 * T, save_at=jnp.array([20 * T, 30 * T]))
    assert (np.asarray(traj.status) == lj.Status.OK).all()
    x, ed = np.asarray(traj.x), np.asarray(traj.e_d)
    body = x[:, 1, 0] - x[:, 0, 0]
    com = (M_BODY * body + M_IN * (x[:, 1, 1] - x[:, 0, 1])) / (M_BODY + M_IN)
    e_d = ed[:, 1] - ed[:, 0]
    v = com / (10 * T)
    slides = np.abs(body) > 1e-9
    print(f"sinusoids: {int(slides.sum())} of {U.size} displace the body, the fastest forward {v.max():.4f}, "
          f"{int((v >= V_ISO).sum())} meet v_min")  # fmt: skip
    assert slides.any() and (e_d >= FLOOR * np.abs(body) * (1 - 1e-9) - 1e-12).all()
    fast = v >= V_ISO
    cost = np.where(fast, e_d / np.where(fast, com, 1.0), np.inf)
    assert not (cost < iso_optimum.cost_of_transport_exact * (1 - 1e-9)).any()


def test_mechanism_optimise_settings():
    """The settings' checks name the field; a ChainOptimiseSettings is taken field for field (one phase)."""
    from locomotion_jax.optimisation._mechanism import MechanismOptimiseSettings

    with pytest.raises(ValueError, match="MechanismOptimiseSettings.phases must be an int >= 1, got 0"):
        lj.MechanismOptimiseSettings(phases=0)
    with pytest.raises(ValueError, match="need 0 < omega_min < omega_max"):
        lj.MechanismOptimiseSettings(omega_min=2.0, omega_max=1.0)
    with pytest.raises(ValueError, match="dt, trust_radius, newton_tol and check_tol must be > 0"):
        lj.MechanismOptimiseSettings(dt=0.0)
    s = MechanismOptimiseSettings.from_chain(lj.ChainOptimiseSettings(local=3, max_iter=7, omega_max=1.5))
    assert (s.local, s.max_iter, s.omega_max, s.phases) == (3, 7, 1.5, 1)
    with pytest.raises(TypeError, match="must be a MechanismOptimiseSettings, got ExactSettings"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, settings=lj.ExactOptimiseSettings())
    with pytest.raises(ValueError, match="shape must be 'fourier' or 'spline', got 'square'"):
        lj.MechanismOptimiseSettings(shape="square")
    with pytest.raises(ValueError, match="knots must be an int >= 4, got 3"):
        lj.MechanismOptimiseSettings(knots=3)
    with pytest.raises(ValueError, match=r"harmonics applies to Fourier series.*got harmonics=3"):
        lj.optimise(
            _capsule(), v_min=0.01, a_max=0.5, harmonics=3, settings=lj.MechanismOptimiseSettings(shape="spline")
        )


def test_mechanism_optimise_bad_input():
    with pytest.raises(ValueError, match="no element driven by a waveform"):
        lj.optimise(_capsule(force=0.3), v_min=0.01, a_max=0.5)
    with pytest.raises(ValueError, match="a_max must be a finite bound > 0"):
        lj.optimise(_capsule(), v_min=0.01, a_max=-1.0)
    with pytest.raises(ValueError, match="single configuration"):
        lj.optimise(_capsule(lj.Sinusoid(a=jnp.array([0.3, 0.4]), omega=3.0, lbar=0.0)), v_min=0.01, a_max=0.5)
    with pytest.raises(ValueError, match="exact method only"):
        lj.optimise(_capsule(), v_min=0.01, a_max=0.5, method="smoothed")


def _reference_gait(opt):
    """Mean speed and cost of transport of the optimum's isotropic capsule from rest in the
    independent reference, over 10 periods of its force once the slowest Floquet mode has decayed
    to 1e-9 of its start (at least 30 periods)."""
    w = float(opt.omega)
    start = int(np.clip(np.ceil(np.log(1e-9) / np.log(opt.spectral_radius_exact)), 30, 400))
    periods = (start, start + 10)
    if opt.shape == "spline":
        force = Sig(0.0, w=w, control=tuple(float(c) for c in opt.control[0]))
    else:
        force = Sig(0.0, tuple(float(c) for c in opt.cos[0]), tuple(float(c) for c in opt.sin[0]), w)
    S = System([Body(M_BODY, (0.5, 0.5, 0.4, 0.4)), Body(M_IN, None, carrier=0)], springs=[(0, 1, K_ISO, 0.0)],
               forces=[(0, 1, force)])  # fmt: skip
    t = np.array(periods, float) * 2 * np.pi / w
    ref = run(S, float(t[1]), t)
    dX = ref["com"][1] - ref["com"][0]
    return dX / (t[1] - t[0]), (ref["ed"][1] - ref["ed"][0]) / abs(dX)


def test_reference_spline_is_the_packages_spline():
    """The reference's B-spline signal (its own formula) equals `lj.Spline` and its rate."""
    c = np.random.default_rng(3).normal(size=7)
    wave = lj.Spline(jnp.asarray(c), 2.3, 0.4)
    t = np.linspace(-3.0, 9.0, 501)
    val, rate = (np.asarray(q) for q in wave(jnp.asarray(t)))
    ref = np.array([Sig(0.4, w=2.3, control=tuple(c)).at(x) for x in t])
    assert np.abs(ref[:, 0] - val).max() < 1e-12 and np.abs(ref[:, 1] - rate).max() < 1e-11


SPLINE: dict[str, Any] = dict(amplitudes=3, phases=2, local=1, max_iter=8, transient=15, shape="spline", knots=8)


@pytest.fixture(scope="module")
def spline_optimum():
    s = lj.MechanismOptimiseSettings(**SPLINE)
    return lj.optimise(_iso_capsule(np.zeros(1), np.zeros(1)), v_min=V_ISO, a_max=F_MAX, omega=OMEGA, settings=s)


@pytest.mark.slow
def test_spline_optimum_of_the_isotropic_capsule(spline_optimum):
    opt = spline_optimum
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)}, opt.candidates)
    assert opt.shape == "spline" and opt.harmonics == 0 and opt.cos.shape == (1, 0)
    assert opt.control is not None and opt.control.shape == (1, 8)
    wave = opt.mechanism.links[1].waveform
    assert isinstance(wave, lj.Spline) and np.array_equal(np.asarray(wave.control), opt.control[0])
    # The bound: a box on the control values; the exact stroke against a dense sampling of the force.
    T = 2 * np.pi / OMEGA
    sampled = float(np.abs(np.asarray(wave(jnp.linspace(0.0, T, 40001))[0])).max())
    stroke = float(opt.stroke_exact[0])
    assert np.abs(opt.control).max() <= F_MAX and stroke <= F_MAX * (1 + 1e-12)
    assert sampled <= stroke + 1e-12 and stroke - sampled < 1e-6
    # No sinusoid of the screen under the bound moves the capsule at v_min; the spline does.
    assert opt.sinusoid is None and opt.candidates[0]["feasible_exact"] is False
    assert opt.feasible_exact and opt.stable_exact and opt.mean_speed_exact >= V_ISO
    # The floor e_d >= mu_k (M + m) g |distance| holds; a direct simulation agrees.
    assert opt.cost_of_transport_exact >= FLOOR * (1 - 1e-9)
    assert opt.simulation_agreement < 1e-6
    # The independent reference from rest, once the transient has decayed.
    speed, cost = _reference_gait(opt)
    err = max(abs(speed / opt.mean_speed_exact - 1), abs(cost / opt.cost_of_transport_exact - 1))
    print(f"spline optimum: speed {opt.mean_speed_exact:.10f} (reference {speed:.10f}), cost "
          f"{opt.cost_of_transport_exact:.10f} (reference {cost:.10f}, floor {FLOOR}); diff {err:.1e}")  # fmt: skip
    assert err < 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("shape", ["fourier", "spline"])
def test_mechanism_optimise_float32(shape):
    """The isotropic capsule in float32 (Fourier series of 2 harmonics, or splines of 8 knots): the
    optimiser keeps the dtype, meets the requirement and the floor, and its optimum's gait agrees
    with the float64 reference within 1e-3 (float32's resolution of the orbit, Newton tolerance 1e-5)."""
    mech = _iso_capsule(np.zeros(1), np.zeros(1)).astype(jnp.float32)
    s = lj.MechanismOptimiseSettings(**(SPLINE | dict(shape=shape)))
    opt = lj.optimise(mech, v_min=V_ISO, a_max=F_MAX, omega=OMEGA, harmonics=2 if shape == "fourier" else None,
                      settings=s)  # fmt: skip
    print({k: v for k, v in opt.to_dict().items() if k not in ("candidates",)})
    assert opt.mechanism.dtype == jnp.float32 and opt.shape == shape
    assert all(x.dtype == jnp.float32 for x in jax.tree_util.tree_leaves(opt.mechanism))
    assert opt.feasible_exact and opt.stable_exact and opt.mean_speed_exact >= V_ISO
    assert opt.cost_of_transport_exact >= FLOOR * (1 - 1e-6) and float(np.max(opt.stroke_exact)) <= F_MAX * (1 + 1e-6)
    speed, cost = _reference_gait(opt)
    err = max(abs(speed / opt.mean_speed_exact - 1), abs(cost / opt.cost_of_transport_exact - 1))
    print(f"float32 {shape} optimum: speed {opt.mean_speed_exact:.8f} (reference {speed:.8f}), cost "
          f"{opt.cost_of_transport_exact:.8f} (reference {cost:.8f}); relative difference {err:.1e}")  # fmt: skip
    assert err < 1e-3
