"""The hopping reading `contact="hop"` (issue 27, SPEC §10) in the N-body exact engine: a body
dropped on the ground against the closed form of its bounces (landing times, rebound heights
$e^{2k} h$, the Zeno rule's last landing), the impact law for a body landing while sliding, the
energy balance with flight and impacts, and `"hop"` equal to `"strict"` where nothing flies."""

import math

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest


def _ball(**kw) -> lj.Mechanism:
    args = dict(masses=[1.0], friction=lj.Coulomb(0.5, 0.5), c=0.0, x0=[0.0], v0=[0.0], y0=[1.0], restitution=0.5)
    args.update(kw)
    return lj.Mechanism(**args)  # type: ignore[arg-type]


def _bounces(h: float, e: float, zeno: float, t: np.ndarray) -> tuple[np.ndarray, int]:
    """Closed form of a body dropped from rest at height `h` (unit gravity): the height at times
    `t` and the number of landings by `t[-1]` (a rebound slower than `zeno` is plastic)."""
    y = np.zeros_like(t)
    t_land, w = math.sqrt(2 * h), math.sqrt(2 * h)  # first landing, impact speed
    y = np.where(t < t_land, h - 0.5 * t * t, 0.0)
    n = int(t_land <= t[-1])
    while True:
        w_up = e * w
        if w_up < zeno:
            break
        s = t - t_land
        t_next = t_land + 2 * w_up
        y = np.where((s >= 0) & (t < t_next), w_up * s - 0.5 * s * s, y)
        if t_next > t[-1]:
            break
        t_land, w, n = t_next, w_up, n + 1
    return y, n


@pytest.mark.parametrize("t_end", [4.0, 6.0])
def test_dropped_body_bounces_as_the_closed_form(t_end):
    """Landing times and rebound heights $e^{2k} h$ to 1e-10; at `t_end = 6` the Zeno rule has
    ended the sequence (11 landings: $e^{11}\\sqrt{2} < 10^{-3}$) and the body rests."""
    ts = np.linspace(0.0, t_end, 601)
    traj = lj.simulate(_ball(), t_end=t_end, save_at=ts, contact="hop")
    assert traj.y is not None and traj.vy is not None and traj.n_land is not None
    assert traj.y.shape == (len(ts), 1) and traj.vy.shape == (len(ts), 1)
    y_exact, n_exact = _bounces(1.0, 0.5, 1e-3, ts)
    err = np.abs(np.asarray(traj.y[:, 0]) - y_exact).max()
    print("dropped body: max |y - closed form|", err, "landings", int(traj.n_land), "expected", n_exact)
    assert err < 1e-10
    assert int(traj.n_land) == n_exact and int(traj.status) == lj.Status.OK
    if t_end == 6.0:
        assert n_exact == 11
        assert np.all(np.asarray(traj.y)[ts > 4.25] == 0) and np.all(np.asarray(traj.vy)[ts > 4.25] == 0)
    # Energy: e = m y + m w^2 / 2 falls by the impacts' losses, which e_d counts (no work done).
    bal = np.asarray(traj.e_d + traj.e - traj.e[0])
    assert np.abs(bal).max() < 1e-12 and float(traj.e_d[-1]) > 0.74


def test_rebound_heights():
    """Apexes between landings $k$ and $k+1$ at $e^{2k} h$ (sampled at the closed form's apex times)."""
    e, h = 0.5, 1.0
    t_land = [math.sqrt(2 * h)]
    for k in range(1, 5):
        t_land.append(t_land[-1] + 2 * math.sqrt(2 * h) * e**k)
    apex = np.array([t + math.sqrt(2 * h) * e ** (k + 1) for k, t in enumerate(t_land)])
    traj = lj.simulate(_ball(), t_end=5.0, save_at=apex, contact="hop")
    assert traj.y is not None
    got = np.asarray(traj.y[:, 0])
    want = h * e ** (2 * np.arange(1, 6))
    print("apex heights", got, "expected", want)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10)


def test_landing_times_as_the_closed_form():
    """Landing times $t_1 = \\sqrt{2h}$, then every $2 e^k \\sqrt{2h}$, to 1e-10: each landing time is
    read off the height a time $s$ after the closed form's landing (the rebound at $w_k = e^k\\sqrt{2h}$
    has reached $y = w_k \\tau - \\tau^2/2$ a time $\\tau$ after the landing), for the first 8 landings."""
    h, e, s = 1.0, 0.5, 1e-3
    w = math.sqrt(2 * h) * e ** np.arange(9)  # w[k]: the speed after the k-th landing (w[0]: the first impact)
    t_land = math.sqrt(2 * h) + np.concatenate([[0.0], np.cumsum(2 * w[1:8])])  # landings 1 to 8
    ts = t_land + s
    traj = lj.simulate(_ball(), t_end=4.5, save_at=ts, contact="hop")
    assert traj.y is not None
    y = np.asarray(traj.y[:, 0])
    rebound = w[1:9]
    tau = rebound - np.sqrt(rebound * rebound - 2 * y)  # the root of w tau - tau^2 / 2 = y before the apex
    err = np.abs(ts - tau - t_land).max()
    print("landing times", ts - tau, "closed form", t_land, "max error", err)
    assert err < 1e-10


def test_landing_while_sliding_follows_the_impulse_law():
    """A body thrown sideways lands with $v^- = 1$, $w^- = -\\sqrt 2$: $P_n = m(1+e)|w^-|$,
    $P_t = \\min(m|v^-|, \\mu_k P_n)$ against $v^-$; no friction in flight, so $x$ is linear
    between landings. Checked through the second flight to rounding."""
    mu_k, e, m = 0.2, 0.5, 2.0
    M = _ball(masses=[m], friction=lj.Coulomb(0.3, mu_k), v0=[1.0], restitution=e)
    t1 = math.sqrt(2.0)
    w1 = math.sqrt(2.0)
    v1 = 1.0 - mu_k * (1 + e) * w1  # P_t / m, smaller than v-: still sliding
    t2 = t1 + 2 * e * w1
    v2 = v1 - mu_k * (1 + e) * e * w1
    ts = np.array([0.5 * t1, t1 + 0.3, t2 - 0.1, t2 + 0.2])
    traj = lj.simulate(M, t_end=3.5, save_at=ts, contact="hop")
    x_exact = np.array([0.5 * t1, t1 + 0.3 * v1, t1 + (t2 - 0.1 - t1) * v1, t1 + (t2 - t1) * v1 + 0.2 * v2])
    v_exact = np.array([1.0, v1, v1, v2])
    print("sliding landing: x", np.asarray(traj.x[:, 0]), "expected", x_exact)
    np.testing.assert_allclose(np.asarray(traj.x[:, 0]), x_exact, rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(traj.v[:, 0]), v_exact, rtol=0, atol=1e-12)
    # The losses: vertical m (w-^2 - w+^2)/2 and horizontal m (v-^2 - v+^2)/2 at each landing.
    lost = 0.5 * m * (w1**2 * (1 - e**2) + 1 - v1**2) + 0.5 * m * ((e * w1) ** 2 * (1 - e**2) + v1**2 - v2**2)
    assert abs(float(traj.e_d[-1]) - lost) < 1e-12


def test_landing_stops_a_slow_slide():
    """$\\mu_k P_n \\ge m|v^-|$: the body stops at the landing (plastic, e = 0) and sticks."""
    M = _ball(v0=[0.5], restitution=0.0)
    traj = lj.simulate(M, t_end=3.0, save_at=np.array([1.0, 2.0, 3.0]), contact="hop")
    x_land = 0.5 * math.sqrt(2.0)
    np.testing.assert_allclose(np.asarray(traj.x[1:, 0]), x_land, rtol=0, atol=1e-12)
    assert np.asarray(traj.stuck)[1:, 0].all() and np.asarray(traj.v)[1:, 0].tolist() == [0.0, 0.0]


def _driven(**kw) -> lj.Mechanism:
    wave = lj.Sinusoid(a=0.3, omega=2.0, lbar=1.0)
    return lj.Mechanism(
        masses=[1.0, 0.8], friction=[lj.Coulomb(0.5, 0.3), lj.AnisotropicCoulomb(0.6, 0.4, 0.5, 0.3)],
        links=[lj.Spring(0, 1, k=4.0, rest=wave), lj.ExternalForce(1, lj.Sinusoid(0.2, 2.0, 0.0))],
        c=[0.05, 0.02], x0=[0.0, 1.0], **kw,
    )  # fmt: skip


def test_hop_equals_strict_where_nothing_flies():
    """Bodies that stay on the ground (a mechanism's springs are horizontal: $N_i = m_i$): the
    hopping reading runs the same motion as the strict one."""
    ts = np.linspace(0.0, 20.0, 201)
    a = lj.simulate(_driven(), t_end=20.0, save_at=ts, contact="strict")
    b = lj.simulate(_driven(), t_end=20.0, save_at=ts, contact="hop")
    assert b.y is not None and np.all(np.asarray(b.y) == 0) and int(b.n_land) == 0  # type: ignore[arg-type]
    for k in ("x", "v", "e_d", "w", "e"):
        d = np.abs(np.asarray(getattr(a, k)) - np.asarray(getattr(b, k))).max()
        print("hop vs strict", k, d)
        assert d <= 1e-12
    assert (np.asarray(a.stuck) == np.asarray(b.stuck)).all() and int(a.n_switch) == int(b.n_switch)


def test_energy_balance_with_flight_and_impacts():
    """$w = e_d + \\Delta e$ at every save with an actuated spring, damping and an external force
    while body 0 flies and lands (partly elastic) and body 1 slides."""
    M = _driven(y0=[0.4, 0.0], w0=[0.5, 0.0], restitution=[0.6, 0.3])
    ts = np.linspace(0.0, 20.0, 401)
    traj = lj.simulate(M, t_end=20.0, save_at=ts, contact="hop")
    assert int(traj.status) == lj.Status.OK and int(traj.n_land) >= 3  # type: ignore[arg-type]
    bal = np.asarray(traj.w - traj.e_d - (traj.e - traj.e[0]))
    print("hop energy balance", np.abs(bal).max(), "landings", int(traj.n_land))  # type: ignore[arg-type]
    assert np.abs(bal).max() < 1e-6 * max(1.0, float(traj.e_d[-1]))


def test_batch_of_restitutions():
    """One compiled run for a batch: each configuration bounces as its own closed form."""
    es = np.array([0.0, 0.3, 0.5, 0.8])
    ts = np.linspace(0.0, 4.0, 201)
    traj = lj.simulate(_ball(restitution=jnp.asarray(es)[:, None]), t_end=4.0, save_at=ts, contact="hop")
    assert traj.y is not None and traj.y.shape == (4, len(ts), 1)
    for i, e in enumerate(es):
        y, n = _bounces(1.0, float(e), 1e-3, ts)
        assert np.abs(np.asarray(traj.y[i, :, 0]) - y).max() < 1e-10
        assert int(traj.n_land[i]) == n  # type: ignore[index]


def test_float32():
    ts = np.linspace(0.0, 4.0, 201)
    traj = lj.simulate(_ball(), t_end=4.0, save_at=ts, contact="hop", dtype=jnp.float32)
    assert traj.y is not None and traj.y.dtype == jnp.float32
    y, n = _bounces(1.0, 0.5, 1e-3, ts)
    err = np.abs(np.asarray(traj.y[:, 0], float) - y).max()
    print("float32 dropped body: max error", err)
    assert err < 1e-5 and int(traj.n_land) == n  # type: ignore[arg-type]


def test_paths_without_hop_refuse_clearly():
    ts = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"heights y_0..y_N-1 >= 0.*shape \(11,\), got shape \(5,\)"):
        lj.steady_gait(lj.Chain(masses=[1.0, 1.0, 1.0]), contact="hop", start=np.asarray([3.0, 3.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="got shape \\(11,\\), a height < 0"):
        low = np.r_[3.0, 3.0, np.zeros(4), -0.1, np.zeros(4)]  # gaps, velocities, heights (one < 0), w
        lj.steady_gait(lj.Chain(masses=[1.0, 1.0, 1.0]), contact="hop", start=low)
    with pytest.raises(NotImplementedError, match="Exact"):
        lj.simulate(_ball(), t_end=1.0, save_at=ts, contact="hop", dynamics=lj.Smoothed())


def test_jvp_through_a_landing_matches_finite_differences():
    """d/dh of the height and position after a sliding landing (the landing time moves with h):
    forward mode through the located event agrees with central differences."""
    ts = np.array([1.0, 2.0])

    def f(h):
        b = _ball(friction=lj.Coulomb(0.5, 0.2), v0=[1.0], y0=jnp.stack([h]), check=False)
        tr = lj.simulate(b, t_end=2.0, save_at=ts, contact="hop")
        assert tr.y is not None
        return jnp.concatenate([tr.y[:, 0], tr.x[:, 0]])

    h = jnp.asarray(1.0)
    _, d = jax.jvp(f, (h,), (jnp.ones_like(h),))
    fd = (f(h + 1e-6) - f(h - 1e-6)) / 2e-6
    print("jvp through a landing", np.asarray(d), "finite differences", np.asarray(fd))
    assert abs(float(d[1])) > 0.1 and abs(float(d[3])) > 0.1  # the landing moved both
    np.testing.assert_allclose(np.asarray(d), np.asarray(fd), rtol=0, atol=1e-7)
