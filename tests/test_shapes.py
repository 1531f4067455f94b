"""The spline stroke, the exact optimiser's shape families and its tension-wave starts."""

import math
from functools import partial

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.optimisation import _pareto, _shapes, _starts
from scipy.interpolate import BSpline


def _scipy_spline(control: np.ndarray, omega: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent evaluation: scipy's B-spline on an extended knot vector, basis i centred at i - 1."""
    m = len(control)
    bs = BSpline(np.arange(-3.0, m + 4.0), control[(np.arange(m + 3) - 1) % m], 3, extrapolate=False)
    s = (omega * t * m / (2 * math.pi)) % m
    r = omega * m / (2 * math.pi)
    return 3.0 + bs(s), r * bs(s, 1), r * r * bs(s, 2)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_spline_value_and_derivatives(dtype):
    # Value, rate and second rate against scipy's B-spline (an independent evaluation), the
    # rate also against central differences of the value; the dtype is kept.
    tol = 1e-12 if dtype == jnp.float64 else 2e-6
    rng = np.random.default_rng(0)
    control, omega = rng.uniform(-0.05, 0.05, 11), 2.3
    wave = lj.Spline(jnp.asarray(control, dtype), jnp.asarray(omega, dtype), jnp.asarray(3.0, dtype))
    t = np.linspace(0.0, 2 * 2 * math.pi / omega, 2001)
    phase = omega * t
    l0, dl0, ddl0 = wave.at_phase(jnp.asarray(np.cos(phase), dtype), jnp.asarray(np.sin(phase), dtype))
    assert l0.dtype == dl0.dtype == ddl0.dtype == dtype
    ref = _scipy_spline(control, omega, t)
    scale = np.max(np.abs(ref[1])), np.max(np.abs(ref[2]))
    np.testing.assert_allclose(np.asarray(l0, float), ref[0], atol=3 * tol * 3)
    np.testing.assert_allclose(np.asarray(dl0, float), ref[1], atol=50 * tol * scale[0] + 10 * tol)
    np.testing.assert_allclose(np.asarray(ddl0, float), ref[2], atol=50 * tol * scale[1] + 10 * tol)
    if dtype == jnp.float64:
        h = 1e-6
        fd = (np.asarray(wave(jnp.asarray(t + h))[0]) - np.asarray(wave(jnp.asarray(t - h))[0])) / (2 * h)
        np.testing.assert_allclose(np.asarray(wave(jnp.asarray(t))[1]), fd, atol=1e-8)
    # Batched control values along a leading axis, as the optimiser's lanes use them.
    batch = lj.Spline(jnp.stack([control, -control]), jnp.array([omega, omega]), jnp.array([3.0, 3.0]))
    two = batch.at_phase(jnp.full(2, math.cos(0.7)), jnp.full(2, math.sin(0.7)))[0]
    one = lj.Spline(control, omega, 3.0).at_phase(jnp.asarray(math.cos(0.7)), jnp.asarray(math.sin(0.7)))[0]
    np.testing.assert_allclose(np.asarray(two), [float(one), 6.0 - float(one)], rtol=1e-14)


def test_spline_stroke_is_bounded_by_its_control_values():
    # Convex hull: the stroke never exceeds max |c_j|; it reaches it on a plateau of three equal
    # values; spline_stroke locates the true maximum (against a dense evaluation).
    rng = np.random.default_rng(1)
    phase = np.linspace(0, 2 * math.pi, 200_001)
    for m in (5, 16, 64):
        control = rng.uniform(-1, 1, m)
        wave = lj.Spline(control, 1.0, 0.0)
        dense = np.max(np.abs(np.asarray(wave.at_phase(jnp.asarray(np.cos(phase)), jnp.asarray(np.sin(phase)))[0])))
        assert dense <= float(wave.stroke()) * (1 + 1e-12)
        assert _shapes.spline_stroke(control) == pytest.approx(dense, rel=1e-8)
    plateau = np.r_[np.ones(3), -0.5 * np.ones(5)]
    assert _shapes.spline_stroke(plateau) == pytest.approx(1.0, rel=1e-14)
    assert float(lj.Spline(plateau, 1.0, 0.0).stroke()) == 1.0


def test_shape_families_fit_project_and_constrain():
    grid = 256
    phase = np.arange(grid) * 2 * np.pi / grid
    # A Fourier series is fitted exactly, up to the time shift that makes A_1 = 0, B_1 >= 0.
    four = _shapes.FourierShape(harmonics=4)
    values = 0.5 * np.sin(phase + 0.3) + 0.2 * np.cos(3 * phase)
    theta = four.fit(values, 2.0)
    assert len(theta) == four.size and float(np.exp(theta[-1])) == pytest.approx(2.0)
    got = four.sample(four.waveform(jnp.asarray(theta), jnp.asarray(1.0), jnp.asarray(0.0)), grid)
    np.testing.assert_allclose(np.abs(np.fft.rfft(got)), np.abs(np.fft.rfft(values)), atol=1e-9)
    c, s, _ = _shapes.from_theta(theta, 1.0, 4)
    assert c[0] == 0.0 and s[0] == pytest.approx(0.5)
    # A spline interpolates the samples at its knots; the box is kept by clipping.
    spl = _shapes.SplineShape(knots=32)
    theta = spl.fit(0.8 * values, 3.0)
    got = spl.sample(spl.waveform(jnp.asarray(theta), jnp.asarray(1.0), jnp.asarray(0.0)), grid)
    np.testing.assert_allclose(got[:: grid // 32], 0.8 * values[:: grid // 32], atol=1e-12)
    big = spl.fit(3.0 * values, 3.0)
    assert np.max(np.abs(big[:-1])) == 1.0 and spl.stroke(big) <= 1.0
    assert big[-1] == pytest.approx(math.log(3.0))
    # The box constraint's Jacobian against central differences.
    x = np.r_[np.random.default_rng(2).uniform(-0.9, 0.9, 32), 0.1]
    g, jac = spl.constraint(x)
    d = np.random.default_rng(3).normal(size=x.shape)
    h = 1e-7
    np.testing.assert_allclose(
        jac @ d, (spl.constraint(x + h * d)[0] - spl.constraint(x - h * d)[0]) / (2 * h), atol=1e-7
    )
    # A shift of the time origin by whole knots is exact: l0'(phi) = l0(phi + 2 pi turns).
    turns = spl.origins[1]
    moved = spl.sample(spl.waveform(jnp.asarray(spl.shift(x, turns)), jnp.asarray(1.0), jnp.asarray(0.0)), grid)
    orig = spl.sample(spl.waveform(jnp.asarray(x), jnp.asarray(1.0), jnp.asarray(0.0)), grid)
    np.testing.assert_allclose(moved, np.roll(orig, -round(turns * grid)), atol=1e-14)
    with pytest.raises(ValueError, match="knots"):
        spl.shift(x, 0.01)
    with pytest.raises(ValueError, match="knots"):
        _shapes.SplineShape(knots=3)


@pytest.mark.slow  # a README claim at 64 knots; the starts and the spline are tested above
def test_tension_wave_start_is_fast_and_cheap():
    # The idealised inchworm whose tension alternates in sign, as a spline of 64 knots run
    # open-loop on the exact model: faster than 0.045 near the quasi-static floor (~0.922),
    # where every sinusoid of the same stroke costs more than 3 (README, Optimal actuation).
    params = lj.Params()
    starts = _starts.tension_starts(partial(_starts.tension_waves, lj.Chain.from_params(params)), 0.05, [1.4], (0.38,))
    assert len(starts) == 1
    values, omega = starts[0][0][0], starts[0][1]
    assert starts[0][2] == 0.38
    assert np.max(np.abs(values)) <= 1.0 and omega == pytest.approx(2 * math.pi / 1.4)
    shape = _shapes.SplineShape(knots=64)
    theta = shape.fit(values, omega)
    wave = shape.waveform(jnp.asarray(theta), jnp.asarray(0.05), jnp.asarray(3.0))
    fig = _pareto.exact_figures(params, wave)
    assert bool(fig.ok)
    assert float(fig.speed) > 0.045 and float(fig.cost) < 0.95


@pytest.mark.parametrize("shape", [(5,), (3, 4)])
def test_normalise_phase_moves_the_time_origin_of_every_signal(shape):
    # `(H,)` coefficients of one signal, or `(S, H)` of S signals of one gait: each new signal is
    # the old one read from the time that zeroes the first signal's A_1 (with B_1 >= 0), the same
    # time for every signal; the signals are sampled independently of the shift's formula.
    rng = np.random.default_rng(3)
    cos, sin = rng.normal(size=shape), rng.normal(size=shape)
    cos.reshape(-1, shape[-1])[0, 0] = 0.7  # A_1 > 0, B_1 < 0: a shift into the third quadrant
    sin.reshape(-1, shape[-1])[0, 0] = -0.4
    c2, s2 = _shapes.normalise_phase(cos, sin)
    assert c2.shape == cos.shape and s2.shape == sin.shape
    first_c, first_s = c2.reshape(-1, shape[-1])[0], s2.reshape(-1, shape[-1])[0]
    assert abs(first_c[0]) < 1e-15 and first_s[0] > 0

    def signal(c: np.ndarray, s: np.ndarray, phase: np.ndarray) -> np.ndarray:
        n = np.arange(1, c.shape[-1] + 1)[:, None]
        return c @ np.cos(n * phase) + s @ np.sin(n * phase)

    phase = np.linspace(0.0, 2 * math.pi, 721)
    old, new = signal(cos, sin, phase), signal(c2, s2, phase)
    # The shift, found by sampling: where the old first signal's first harmonic peaks, less a quarter turn.
    fine = np.linspace(0.0, 2 * math.pi, 2_000_001)
    first = cos.reshape(-1, shape[-1])[0, 0] * np.cos(fine) + sin.reshape(-1, shape[-1])[0, 0] * np.sin(fine)
    shift = fine[np.argmax(first)] - math.pi / 2
    # The grid's step (3e-6 rad) times the harmonics' rates bounds the difference.
    np.testing.assert_allclose(new, signal(cos, sin, phase + shift), atol=2e-4)
    assert np.abs(new - old).max() > 0.1  # a shift that moves the signals


def test_tension_waves_of_a_chain_jump_by_each_springs_tension_step_at_its_lagged_switches():
    # Three masses on bristles with tilted springs of two stiffnesses, the second spring's
    # square wave a quarter period behind the first's. The idealised gap is continuous, so the
    # rest length l0_j = l_j - T_j/k_j jumps by -(T_t + T_c)/k_j where spring j's compression
    # turns to tension (at half its period, after its lag) and back; the tensions are
    # `level` of the way between the break-away forces of the spring's two masses at rest at
    # the relaxed gaps (|f_x| = mu n with n from eq. 5, per friction direction).
    masses, k, d, lbar = np.array([1.0, 1.4, 0.8]), np.array([50.0, 30.0]), np.array([0.4, -0.3]), 3.0
    fwd, bwd = np.array([0.5, 0.6, 0.4]), np.array([0.9, 0.8, 1.0])
    chain = lj.Chain(masses=masses, k=k, d=d, lbar=lbar,
                     friction=lj.AnisotropicCoulomb(fwd, bwd, 0.6 * fwd, 0.6 * bwd))  # fmt: skip
    level, grid = 0.4, 1024
    (values,) = _starts.tension_waves(chain, np.array([2.0]), np.array([level]), lag=math.pi / 2, grid=grid)
    assert values.shape == (2, grid)
    u = np.sqrt(lbar**2 - d**2)
    length = lbar

    def between(j: int, sign: float) -> float:
        # Spring j pulls mass j towards `sign` and mass j + 1 the other way.
        mu_l, mu_r = (fwd[j], bwd[j + 1]) if sign > 0 else (bwd[j], fwd[j + 1])
        left = mu_l * masses[j] * length / (u[j] + sign * mu_l * d[j])
        right = mu_r * masses[j + 1] * length / (u[j] - sign * mu_r * d[j])
        lo, hi = sorted((left, right))
        return lo + level * (hi - lo)

    for j, shift in enumerate((0, grid // 4)):
        step = (between(j, 1.0) + between(j, -1.0)) / k[j]
        diff = np.diff(values[j])  # diff[g] = l0(g + 1) - l0(g) within the last period
        to_tension, to_compression = grid // 2 + shift - 1, shift - 1  # spring 0's second: at the period's end
        switches = [g for g in (to_tension, to_compression) if 0 < g < grid - 2]
        assert len(switches) == 2 - (shift == 0)
        smooth = np.delete(np.abs(diff), switches).max()
        assert smooth < 0.05 * step
        # The gap's own change over the sample, from the neighbouring samples', taken out.
        jump = lambda g: diff[g] - 0.5 * (diff[g - 1] + diff[g + 1])
        assert jump(to_tension) == pytest.approx(-step, rel=1e-3)
        if shift:
            assert jump(to_compression) == pytest.approx(step, rel=1e-3)


def _as_mechanism(chain: lj.Chain, tilted: bool = True) -> lj.Mechanism:
    """The chain as a `Mechanism`: its bodies at the relaxed gaps, spring j a tilted (or a linear)
    spring from body j to j + 1 with an actuated rest length."""
    c = chain.broadcast()
    k, d, lbar = (np.asarray(q, float) for q in (c.k, c.d, c.lbar))
    x0 = np.concatenate([[0.0], np.cumsum(np.sqrt(lbar**2 - d**2))])
    rest = lambda j: lj.Sinusoid(a=0.01, omega=1.0, lbar=float(lbar[j]))
    links = [
        lj.TiltedSpring(j, j + 1, k=float(k[j]), d=float(d[j]), rest=rest(j))
        if tilted
        else lj.Spring(j, j + 1, k=float(k[j]), rest=rest(j))
        for j in range(k.size)
    ]
    return lj.Mechanism(masses=np.asarray(c.m), friction=c.friction, links=links, x0=x0, c=np.asarray(c.c))


def test_tension_waves_of_a_mechanism_are_its_chains():
    # A mechanism built as a chain (its physics' loads with the actuated rest lengths set to make
    # the prescribed tensions, its break-away forces per element end) integrates the chain's
    # idealised inchworms: the paper's model, a lighter rear mass on steeper springs, three masses
    # on bristles with tilted springs of two signs, and a flat worm (linear springs) over the
    # periods where its masses keep their order (the chain's flat springs turn over where they
    # meet, a linear spring does not).
    periods, levels = np.geomspace(2.0, 10.0, 10).repeat(3), np.tile([0.3, 0.55, 0.8], 10)
    bristles = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    chains = [
        lj.Chain.from_params(lj.Params()),
        lj.Chain.from_params(lj.Params(mhat=0.3, d=0.8, mu_s=0.9, mu_k=0.3)),
        lj.Chain(masses=[1.0, 2.0, 1.5], k=[40.0, 60.0], d=[0.3, -0.2], lbar=3.0, friction=bristles),
    ]
    for chain in chains:
        want = _starts.tension_waves(chain, periods, levels, lag=0.7)
        got = _starts.mechanism_tension_waves(_as_mechanism(chain), periods, levels, lag=0.7)
        assert got is not None and np.all(np.isfinite(want))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
    flat = lj.Chain(masses=[1.0] * 3, d=0.0, friction=bristles)
    want = _starts.tension_waves(flat, periods[:9], levels[:9], lag=0.7)
    got = _starts.mechanism_tension_waves(_as_mechanism(flat, tilted=False), periods[:9], levels[:9], lag=0.7)
    assert got is not None
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_tension_waves_of_a_capsules_internal_force_alternate_by_the_capsules_break_away_force():
    # A capsule (body 0 on the ground) carries an internal mass (body 1) on a passive spring and
    # drives it with an internal force. The carried mass has no ground contact, so it slides at
    # any force; the capsule holds while the force stays below its break-away mu_s (m0 + m1)
    # (its normal load carries the internal mass's weight). The force is `level` of the way from
    # 0 to that bound: +level mu_s (m0 + m1) for half the period (the compression: f = -T
    # pushes the ends apart), -level mu_s (m0 + m1) for the other half.
    m0, m1, mu_s, level, grid = 1.0, 0.5, 0.6, 0.3, 256
    force = lj.Force(0, 1, lj.Sinusoid(a=0.1, omega=2.0, lbar=0.0))
    capsule = lj.Mechanism(masses=[m0, m1], friction=[lj.Coulomb(mu_s, 0.4), None], carried_by=[None, 0],
                           links=[lj.Spring(0, 1, k=10.0), force])  # fmt: skip
    waves = _starts.mechanism_tension_waves(capsule, np.array([3.0]), np.array([level]), grid=grid)
    assert waves is not None
    (values,) = waves
    bound = level * mu_s * (m0 + m1)
    np.testing.assert_allclose(values[0], np.where(np.arange(grid) < grid // 2, bound, -bound), rtol=1e-12)
    # An actuated spring to the wall never breaks away there: no tension is between its ends' limits.
    anchored = lj.Mechanism(masses=[1.0], links=[lj.Spring(0, lj.WALL, k=5.0, rest=lj.Sinusoid(0.1, 2.0, -1.0))],
                            x0=[1.0])  # fmt: skip
    assert not _starts.tension_starts(
        partial(_starts.mechanism_tension_waves, anchored), 0.1, np.array([3.0]), np.array([level])
    )
    pushed = lj.Mechanism(masses=[1.0], links=[lj.ExternalForce(0, lj.Sinusoid(0.1, 2.0, 0.0))])
    assert _starts.mechanism_tension_waves(pushed, np.array([3.0]), np.array([level])) is None
