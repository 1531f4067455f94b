"""The physics interface: a mechanism that is not a chain, written as one short class, runs on the
N-body exact engine, and the chain's own physics is what the engine integrates a `Chain` with.

The mechanism here is the classic friction oscillator: one body of mass $m$ on a spring of
stiffness $k$ to a wall (rest length 0), with Coulomb friction and normal force $N = m$ (unit
gravity, as in the paper). Released at rest from $x_0$ with $k|x_0| > \\mu_s m$, it swings in
half-cycles of duration $\\pi/\\omega_n$, $\\omega_n = \\sqrt{k/m}$, each about the offset
$\\pm\\delta$, $\\delta = \\mu_k m/k$: the turning points are $x_n = (-1)^n (|x_0| - 2n\\delta)$,
and it stops at the first turning point with $k|x_n| \\le \\mu_s m$. The energy dissipated by
then is the drop of the spring's energy, $k(x_0^2 - x_n^2)/2$.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax._custom_types import Contact
from locomotion_jax.dynamics import _engine as engine, _measure
from locomotion_jax.model._physics import Scalars


class WallSpring(lj.AbstractPhysics):
    """One body on a spring to a wall at $x = 0$, pushed by $f_0 \\sin\\omega t$:
    $F = -kx + f_0\\sin\\omega t$, $N = m$."""

    m: Scalars
    im: Scalars
    c: Scalars
    friction: tuple[lj.AbstractFriction, ...]
    mu_f: Scalars
    mu_b: tuple
    omega: jax.Array
    one: jax.Array
    k: jax.Array
    f0: jax.Array
    x0: jax.Array

    def __init__(self, m, k, mu_s, mu_k, x0, f0=0.0, omega=1.0):
        m, k, x0, f0, omega = (jnp.asarray(v, float) for v in (m, k, x0, f0, omega))
        law = lj.Coulomb(jnp.asarray(mu_s, float), jnp.asarray(mu_k, float))
        self.m, self.im, self.c = (m,), (1 / m,), (jnp.zeros_like(m),)
        self.friction, self.mu_f, self.mu_b = (law,), (law.static_limits()[0],), (None,)
        self.omega, self.one, self.k, self.f0, self.x0 = omega, m / m, k, f0, x0

    def drive(self, c1, s1):  # the applied force and its first two rates
        return self.f0 * s1, self.f0 * self.omega * c1, -self.f0 * self.omega**2 * s1

    def loads(self, drive, x, keep=None):
        spring = -self.k * x[0]
        return lj.Loads((spring + drive[0],), self.m, spring)

    def load_rates(self, drive, loads, xd, keep=None):
        return lj.LoadRates((-self.k * xd[0] + drive[1],), (jnp.zeros_like(xd[0]),), None)

    def load_second(self, drive, loads, rates, xd, a):
        return (-self.k * a[0] + drive[2],), (jnp.zeros_like(a[0]),)

    def power(self, drive, loads, v):
        return drive[0] * v[0]

    def power_rate(self, drive, loads, rates, v, a):
        return drive[1] * v[0] + drive[0] * a[0]

    def energy(self, loads, v):
        return 0.5 * (self.m[0] * v[0] ** 2 + loads.aux**2 / self.k)

    def centre_of_mass(self, x):
        return x[0]

    def initial_positions(self, start):
        return self.x0[None]


def _run(P: lj.AbstractPhysics, t_end: float, dt: float, contact: Contact = "strict", iters: int = 4000):
    """Every step's start (time, state after the switches there, mode) of one run from rest at the physics' start."""

    @jax.jit
    def go(P):
        st = engine.init(P, contact, P.initial_positions("paper"))

        def body(s, _):
            s, info = engine.step(P, contact, dt, s, jnp.asarray(t_end))
            return s, (info.t0, info.y0.x[0], info.y0.v[0], info.y0.ed, info.y0.w, info.stuck[0], info.commit)

        return jax.lax.scan(body, st, None, length=iters)

    return go(P)


@pytest.mark.parametrize("mu_s, mu_k", [(0.5, 0.5), (0.7, 0.4)])
def test_friction_oscillator_against_its_exact_solution(mu_s, mu_k):
    m, k, x0 = 1.5, 20.0, 1.0
    P = WallSpring(m, k, mu_s, mu_k, x0)
    wn = math.sqrt(k / m)
    delta = mu_k * m / k
    # The exact turning points, up to the one where static friction holds.
    turns, n = [], 0
    while True:
        xn = (-1) ** n * (x0 - 2 * n * delta)
        turns.append(xn)
        if n > 0 and k * abs(xn) <= mu_s * m:
            break
        n += 1
    t_end = len(turns) * math.pi / wn + 1.0
    errors = []
    for dt in (0.01, 0.005):
        final, (t, x, v, ed, w, stuck, commit) = _run(P, t_end, dt, iters=int(3 * t_end / dt))
        t, x, v = (np.asarray(q) for q in (t, x, v))
        assert int(final.status) == lj.Status.OK and float(final.t) == pytest.approx(t_end)
        # The turning points the engine located: a step starts with the velocity set exactly to
        # zero (the switch of a slipping body whose velocity reached zero) after a step that moved.
        turn = np.flatnonzero((v[1:] == 0) & (v[:-1] != 0)) + 1
        assert turn.size == len(turns) - 1
        # At rest at the last turning point, stuck; no work; e_d = the drop of the spring's energy.
        assert bool(final.stuck[0]) and float(final.y.v[0]) == 0.0 and float(final.y.w) == 0.0
        e_d = 0.5 * k * (x0**2 - turns[-1] ** 2)
        errors.append(
            [
                np.abs(t[turn] - np.arange(1, len(turns)) * math.pi / wn).max(),
                np.abs(np.append(x[turn], float(final.y.x[0])) - np.append(turns[1:], turns[-1])).max(),
                abs(float(final.y.ed) - e_d) / e_d,
            ]
        )
    errors = np.array(errors)
    # At dt = 0.01 (RK4): event times within 5e-7, turning points within 5e-8, e_d within 1e-7.
    assert np.all(errors[0] < [5e-7, 5e-8, 1e-7]), errors[0]
    # Fourth order: halving the step divides each error by about 16 (at least 8 here).
    assert np.all(errors[1] < errors[0] / 8), errors


def test_forced_friction_oscillator_energy_balance_and_convergence():
    """Forced at f0 sin(omega t), the run has no closed form; the energy balance w = e_d + delta e
    holds at every committed step, and halving the step moves the end state at fourth order."""
    P = WallSpring(1.0, 10.0, 0.6, 0.4, 0.3, f0=1.0, omega=2.0)
    ends = []
    for dt in (0.02, 0.01, 0.005):
        final, (t, x, v, ed, w, stuck, commit) = _run(P, 20.0, dt, iters=8000)
        assert int(final.status) == lj.Status.OK and float(final.t) == pytest.approx(20.0)
        x, v, ed, w = (np.asarray(q) for q in (x, v, ed, w))
        e = 0.5 * (v**2 + 10.0 * x**2) - 0.5 * 10.0 * 0.3**2
        np.testing.assert_allclose(w, ed + e, atol=1e-6)
        ends.append(np.array([float(final.y.x[0]), float(final.y.v[0]), float(final.y.ed)]))
    e1, e2 = np.abs(ends[0] - ends[2]).max(), np.abs(ends[1] - ends[2]).max()
    assert e2 < e1 / 8  # fourth order: 16x for each halving, less the reference's own error


def test_chain_physics_is_what_the_engine_integrates_a_chain_with():
    """`Chain.physics()` is an `AbstractPhysics`; its loads are those of SPEC §8 (eq. 5 at N = 2)."""
    p = lj.Params(omega=2.0, d=0.5)
    P = lj.Chain.from_params(p).physics()
    assert isinstance(P, lj.AbstractPhysics) and P.n_bodies == 2
    x = (jnp.asarray(0.0), jnp.asarray(2.9))
    L = P.loads(P.drive(jnp.asarray(1.0), jnp.asarray(0.0)), x)
    u, d = 2.9, float(p.d)
    length = math.hypot(u, d)
    T = float(p.k) * (length - float(p.lbar))
    fx, fy = T * u / length, T * d / length
    np.testing.assert_allclose([float(q) for q in L.F], [fx, -fx], rtol=1e-12)
    np.testing.assert_allclose([float(q) for q in L.N], [float(p.m1) - fy, float(p.m2) + fy], rtol=1e-12)
    assert eqx.is_array(P.omega)


def _end_n_body(p, wave, contact, start, t_end, dt):
    """The N-body engine on the paper's model (`Params.physics`), the same run."""
    P = p.physics(wave)
    st = engine.init(P, contact, P.initial_positions(start))
    cond = lambda s: (s.t < t_end) & (s.status == lj.Status.OK)
    st = jax.lax.while_loop(cond, lambda s: engine.step(P, contact, dt, s, jnp.asarray(t_end))[0], st)
    y = st.y
    return jnp.stack([st.t, y.x[0], y.v[0], y.x[1], y.v[1], y.ed, y.w, st.t_liftoff]), st.status, st.n_switch


@pytest.mark.parametrize("kind", ["sinusoid", "fourier", "spline"])
@pytest.mark.parametrize("contact", ["strict", "paper"])
def test_the_papers_model_on_the_n_body_engine_against_the_reference(kind, contact):
    """`Params.physics(waveform)` on the N-body engine against the independent event-driven
    reference (`tests/reference.py`, its own eq. 13, Fourier series and periodic B-spline): the
    state at t = 40 (or at a strict lift-off, where both stop), e_d and w, and the lift-off flag,
    over SSL, SL and lift-off configurations with any waveform (a Spline included)."""
    from reference import reference_simulate

    omega = np.array([1.0, 3.0, 8.0, 12.0, 20.0, 9.0])
    a = np.array([0.05, 0.02, 0.08, 0.1, 0.03, 0.06])
    d, mhat = np.array([0.5, 0.0, 0.5, 1.0, 0.5, 0.2]), np.array([0.5, 0.3, 0.6, 0.5, 0.5, 0.4])
    p = lj.Params(omega=omega, a=a, d=d, mhat=mhat, lbar=3.0).broadcast()
    if kind == "sinusoid":
        wave, ref_wave = lj.Sinusoid(p.a, p.omega, p.lbar), [None] * omega.size
    elif kind == "fourier":
        cos, sin = np.stack([0.2 * a, -0.1 * a], -1), np.stack([a, 0.3 * a], -1)
        wave, ref_wave = lj.Fourier(cos, sin, omega, np.full(omega.shape, 3.0)), list(zip(cos, sin))
    else:
        phase = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        ctrl = a[:, None] * np.sin(phase + 0.3) ** 3
        wave, ref_wave = lj.Spline(ctrl, omega, np.full(omega.shape, 3.0)), [("spline", c) for c in ctrl]
    starts = ("paper", "relaxed") if kind == "sinusoid" else ("paper",)
    run = jax.jit(jax.vmap(_end_n_body, in_axes=(0, 0, None, None, None, None)), static_argnums=(2, 3, 4, 5))
    for start in starts:
        y, status, _ = run(p, wave, contact, start, 40.0, 0.01)
        y, status = np.asarray(y), np.asarray(status)
        for i in range(omega.size):
            cfg = dict(omega=omega[i], a=a[i], d=d[i], mhat=mhat[i], lbar=3.0)
            r = reference_simulate(cfg, 40.0, np.array([40.0]), contact=contact, start=start, wave=ref_wave[i],
                                   rtol=1e-10, atol=1e-12)  # fmt: skip
            stopped = contact == "strict" and r["liftoff"]
            assert int(status[i]) == (lj.Status.LIFTOFF if stopped else lj.Status.OK), (start, i)
            assert np.isfinite(y[i, -1]) == r["liftoff"], (start, i)
            want = np.array([r[k][-1] for k in ("x1", "v1", "x2", "v2", "e_d", "w")])
            err = np.abs(y[i, 1:7] - want) / np.maximum(np.abs(want), 1.0)
            # Past a lift-off under the paper's reading (outside the model's validity) the kink of
            # |N| makes the results converge erratically; a spline's third derivative jumps at its
            # knots, which the fixed step does not resolve (measured: 1.5e-4 past such a lift-off,
            # 4.9e-5 in w at omega = 20, 12 knots; else 7e-6).
            tol = 1e-3 if r["liftoff"] and not stopped else 1e-4 if kind == "spline" else 1e-5
            print(kind, contact, start, i, "lift-off" if r["liftoff"] else "", err.max())
            assert err.max() < tol, (start, i, err)


@pytest.mark.parametrize("contact, start", [("strict", "paper"), ("paper", "relaxed")])
def test_measure_of_the_papers_model_on_the_n_body_engine(contact, start):
    """The N-body engine's measurement loop on `Params.physics()` against `lj.measure` (the same
    engine behind the front end's batching, casting and queue): every field to 1e-10 relative
    (1e-9 past a paper-reading lift-off), the statuses, regimes and step counts equal."""
    om, a = np.meshgrid(np.linspace(0.5, 20.0, 8), np.array([0.02, 0.1]))
    p = lj.Params(omega=om.ravel(), a=a.ravel(), d=0.5).broadcast()
    ts = np.asarray(p.t_start)
    ref = lj.measure(p, z=5.0, horizon=300.0, t_start=ts, contact=contact, start=start)
    dyn = lj.Exact()
    cap = 0  # each configuration's own cap, from its own span (as `measure`)
    out = _measure.measure_batch(
        p.physics(), jnp.ones(om.size, bool), jnp.asarray(ts), 5.0, 300.0, 25.0, contact, start, dyn.dt, cap
    )
    lifted = np.isfinite(np.asarray(ref.t_liftoff))
    for name in ("status", "regime", "reached", "liftoff", "n_steps", "n_switch"):
        np.testing.assert_array_equal(np.asarray(out[name]), np.asarray(getattr(ref, name)), err_msg=name)
    fields = ["tau_z", "e_z", "mean_speed", "e_d", "work", "delta_e", "t_liftoff", "X_start"]
    for name in fields:
        x, y = np.asarray(out[name], float), np.asarray(getattr(ref, name), float)
        assert np.array_equal(np.isfinite(x), np.isfinite(y)), name
        both = np.isfinite(x) & np.isfinite(y)
        x, y = np.where(both, x, 0), np.where(both, y, 0)
        err = np.abs(x - y) / np.maximum(np.abs(y), 1)
        tol = np.where(lifted, 1e-9, 1e-10)
        if name in ("t_liftoff", "X_start") and start == "relaxed":
            # Open: from the relaxed start the first lift-off under the paper's reading (t < 1)
            # is located 4e-6 apart by the two engines (0.23524016 and 0.23523986 at
            # omega = 14.4, a = 0.1), which shifts the position (X_start: 7e-6) but not the
            # motion measured after t_start (tau_z, e_z: 1e-9). Outside the model's validity.
            tol = np.where(lifted, 1e-5, 1e-10)
        assert np.all(err < tol), (name, err.max())
    frac = np.stack([np.asarray(ref.stick_fraction1), np.asarray(ref.stick_fraction2)], -1)
    np.testing.assert_allclose(np.asarray(out["stick_fraction"]), frac, rtol=1e-10, atol=1e-12)
