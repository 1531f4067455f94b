"""Continuation of steady gaits: points against independent solves, a period doubling and folds where
known ones lie, the SSL/SL boundary against a dense direct scan and the independent reference,
lift-off against the reference, bad input per branch, one compilation for every parameter, and
hopping branches against the independent hopping reference.

Every continuation here is a batch of two branches (one compiled corrector for the whole file)."""

from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from chain_cases import ANISO
from locomotion_jax import BranchStatus, EventKind, GaitStatus
from reference import reference_simulate
from reference_chain import chain_config
from reference_hop import paper_config, reference_hop_simulate


pytestmark = pytest.mark.xdist_group("gait")


def _events(b: lj.Branch, i: int, kind: int) -> list[dict[str, Any]]:
    e = b.events
    rows = np.flatnonzero(np.asarray(e.kind[i]) == kind)
    keys = ("lam", "lam_error", "value", "smooth", "located", "turn")
    out = [{key: np.asarray(getattr(e, key)[i, q]).item() for key in keys} for q in rows]
    for q, row in zip(rows, out):
        row["multipliers"] = np.asarray(e.multipliers[i, q])
        row["y"] = np.asarray(e.state[i, q])
    return out


def _reference_period(case: dict, y: np.ndarray, periods: int = 1, contact: str = "strict") -> dict:
    """The independent solver over `periods` actuation periods from the section state `y = (u, v1, v2)`."""
    T = 2 * np.pi / case["omega"]
    return reference_simulate(case, periods * T, save_at=[periods * T], start=(0.0, y[1], y[0], y[2]),
                              contact=contact, rtol=1e-12, atol=1e-13)  # fmt: skip


def _end(r: dict) -> np.ndarray:
    return np.array([r["x2"][0] - r["x1"][0], r["v1"][0], r["v2"][0]])


@pytest.fixture(scope="module")
def boundary() -> lj.Branch:
    """Along `a` at omega = 6 across the SSL/SL boundary (a* ~ 0.02664), from either side."""
    return lj.continuation(lj.Params(omega=6.0, a=jnp.asarray([0.05, 0.02])), "a", jnp.asarray([0.02, 0.05]))


def test_points_equal_independent_solves(boundary):
    """Continued points (an SL and an SSL one) equal `steady_gait` solves at the same parameter."""
    n = int(boundary.n_points[0])
    lam = np.asarray(boundary.lam[0, :n])
    assert boundary.names == "paper" and boundary.n_bodies == 2
    assert int(boundary.status[0]) == BranchStatus.REACHED and lam[0] == 0.05 and lam[-1] == 0.02
    regime = np.asarray(boundary.regime[0, :n])
    j = [int(np.argmin(np.abs(lam - 0.04))), int(np.argmin(np.abs(lam - 0.022)))]
    assert list(regime[j]) == [lj.Regime.SL, lj.Regime.SSL]
    g = lj.steady_gait(lj.Params(omega=6.0, a=jnp.asarray(lam[j])), periods=1)
    assert np.all(np.asarray(g.status) == GaitStatus.CONVERGED)
    for name in ("u", "v1", "v2"):
        np.testing.assert_allclose(np.asarray(getattr(boundary, name)[0, j]), np.asarray(getattr(g, name)), atol=1e-9)
    for name in ("mean_speed", "cost_of_transport", "e_d", "slip_margin"):
        np.testing.assert_allclose(np.asarray(getattr(boundary, name)[0, j]), np.asarray(getattr(g, name)), rtol=1e-8)
    np.testing.assert_allclose(
        np.abs(np.asarray(boundary.multipliers[0, j])), np.abs(np.asarray(g.multipliers)), atol=1e-8
    )


def test_ssl_sl_boundary(boundary):
    """The boundary located from both sides agrees to 1e-8; the independent reference, started on
    the orbits at a* -+ 1e-6, sticks below and not above; a dense direct scan with `measure` flips
    from SSL to SL between the two grid values that bracket a*."""
    located = [_events(boundary, i, EventKind.SSL_SL) for i in range(2)]
    assert [len(x) for x in located] == [1, 1]
    ev0, ev1 = located[0][0], located[1][0]
    for ev in (ev0, ev1):
        assert ev["located"] and ev["smooth"] and not ev["turn"] and ev["lam_error"] < 1e-9
        assert abs(ev["value"]) < 1e-8
    a_star = ev0["lam"]
    assert abs(a_star - ev1["lam"]) < 1e-8, (a_star, ev1["lam"])
    assert 0.0265 < a_star < 0.0268
    # The independent reference on the orbits just either side (the margin moves by ~35 per unit a).
    delta = 1e-6
    g = lj.steady_gait(lj.Params(omega=6.0, a=jnp.asarray([a_star - delta, a_star + delta])), periods=1)
    assert list(np.asarray(g.regime)) == [lj.Regime.SSL, lj.Regime.SL]
    for i, sticks in enumerate((True, False)):
        y = np.asarray([float(g.u[i]), float(g.v1[i]), float(g.v2[i])])
        r = _reference_period(dict(omega=6.0, a=a_star + (2 * i - 1) * delta), y)
        assert any("slip->stick" in kind for _, kind in r["events"]) == sticks
        np.testing.assert_allclose(_end(r), y, atol=1e-6)  # periodic under the reference too
    # A dense direct scan (measure from the paper's start, 80 periods of wn2 of transient).
    grid = a_star + (np.arange(-10, 10) + 0.5) * 1e-4
    m = lj.measure(lj.Params(omega=6.0, a=jnp.asarray(grid)), horizon=25.0)
    expected = np.where(grid < a_star, lj.Regime.SSL, lj.Regime.SL)
    np.testing.assert_array_equal(np.asarray(m.regime), expected)


def test_period_doubling():
    """Along d at omega = 1.5, mhat = 0.3 (where d = 0.3 has a period-1 orbit with multiplier -3.57):
    one period doubling, located from both sides to 1e-8, a multiplier at -1 there; below it
    steady_gait's attractor has period 2, above it period 1."""
    b = lj.continuation(lj.Params(omega=1.5, mhat=0.3, d=jnp.asarray([0.5, 0.3])), "d", jnp.asarray([0.3, 0.5]),
                        periods=1)  # fmt: skip
    assert list(np.asarray(b.status)) == [BranchStatus.REACHED] * 2
    found = [_events(b, i, EventKind.PERIOD_DOUBLING) for i in range(2)]
    assert [len(x) for x in found] == [1, 1]
    d_star = found[0][0]["lam"]
    assert abs(d_star - found[1][0]["lam"]) < 1e-8
    assert 0.45 < d_star < 0.5
    for ev in (found[0][0], found[1][0]):
        assert ev["located"] and ev["smooth"] and not ev["turn"]
        assert np.min(np.abs(ev["multipliers"] + 1)) < 1e-6
    n = int(b.n_points[0])
    lam, stable = np.asarray(b.lam[0, :n]), np.asarray(b.stable[0, :n])
    np.testing.assert_array_equal(stable, lam > d_star)
    g = lj.steady_gait(lj.Params(omega=1.5, mhat=0.3, d=jnp.asarray([d_star - 0.01, d_star + 0.01])))
    assert list(np.asarray(g.k)) == [2, 1] and bool(np.all(np.asarray(g.stable)))


def test_folds_and_a_corner():
    """Along omega (a = 0.05): coming down on the SL branch, the slip margin reaches zero where the
    branch turns back as an unstable SSL branch (a non-smooth fold: a corner), which turns again at
    a smooth fold (a multiplier at +1) into the stable SSL branch; going up from 4.5 the stable SSL
    branch folds at about 4.703. Between the SSL/SL corner and the fold both stable gaits coexist:
    the independent reference keeps each periodic, one sticking and one not."""
    b = lj.continuation(lj.Params(omega=jnp.asarray([5.5, 4.5])), "omega", jnp.asarray([4.5, 5.5]))
    corner = _events(b, 0, EventKind.SSL_SL)
    folds = _events(b, 0, EventKind.FOLD)
    assert len(corner) == 1 and corner[0]["turn"] and corner[0]["located"]
    assert len(folds) == 1 and folds[0]["smooth"] and folds[0]["turn"]
    w_corner, w_fold = corner[0]["lam"], folds[0]["lam"]
    assert 4.85 < w_corner < w_fold < 4.95
    assert np.min(np.abs(folds[0]["multipliers"] - 1)) < 1e-6
    up = _events(b, 1, EventKind.FOLD)
    assert len(up) == 1 and 4.69 < up[0]["lam"] < 4.72 and np.min(np.abs(up[0]["multipliers"] - 1)) < 1e-6
    # Between them: an SL point and a stable SSL point at about the same omega.
    n = int(b.n_points[0])
    lam, reg, stable = (np.asarray(x[0, :n]) for x in (b.lam, b.regime, b.stable))
    mid = 0.5 * (w_corner + w_fold)
    for regime, sticks in ((lj.Regime.SL, False), (lj.Regime.SSL, True)):
        cand = np.flatnonzero((reg == regime) & stable & (np.abs(lam - mid) < 0.03))
        assert len(cand) > 0, regime
        j = cand[np.argmin(np.abs(lam[cand] - mid))]
        y = np.asarray(b.state[0, j])
        r = _reference_period(dict(omega=float(lam[j])), y)
        assert any("slip->stick" in kind for _, kind in r["events"]) == sticks
        np.testing.assert_allclose(_end(r), y, atol=1e-6)


def test_liftoff_and_bad_input():
    """Strict reading along a at omega = 16: the branch ends where the smallest normal force of the
    orbit reaches zero, located to 1e-8; under the reference the orbit's neighbourhood keeps contact
    just below and loses it just above. An invalid configuration in the same batch is flagged alone."""
    p = lj.Params(omega=16.0, mu_s=jnp.asarray([0.7, 0.3]), check=False)
    b = lj.continuation(p, "a", 0.15)
    assert list(np.asarray(b.status)) == [BranchStatus.LIFTOFF, BranchStatus.INVALID]
    assert int(b.start_status[1]) == GaitStatus.INVALID and int(b.n_points[1]) == 0
    assert np.all(np.isnan(np.asarray(b.lam[1]))) and np.all(np.asarray(b.events.kind[1]) == -1)
    ev = _events(b, 0, EventKind.LIFTOFF)
    assert len(ev) == 1 and ev[0]["located"] and ev[0]["lam_error"] < 1e-8
    a_star = ev[0]["lam"]
    n = int(b.n_points[0])
    assert float(b.lam[0, n - 1]) < a_star < float(b.lam[0, n - 1]) + 1e-4
    assert np.all(np.asarray(b.min_normal[0, :n]) > 0)
    assert 0 < float(b.min_normal[0, n - 1]) < 1e-3
    delta = 1e-5
    for sign, lifts in ((-1, False), (1, True)):
        # 40 periods under the paper reading (it integrates through a sign change of N and logs it),
        # from the located orbit: the motion settles on the orbit at a* -+ delta.
        y = ev[0]["y"]
        r = _reference_period(dict(omega=16.0, a=a_star + sign * delta), y, periods=40, contact="paper")
        T = 2 * np.pi / 16.0
        late = [t for t, kind in r["events"] if "normal" in kind and t > 39 * T]
        assert bool(late) == lifts, (sign, late)


@pytest.mark.slow  # its own compilation of the corrector (a coefficient as the parameter)
def test_waveform_coefficient():
    """A Fourier coefficient as the parameter (d = 0, mhat = 0.3, second harmonic): points equal
    steady_gait under the same waveform."""
    wave = lj.Fourier(omega=2.0, lbar=3.0, cos=jnp.asarray([0.0, 0.1]), sin=jnp.asarray([0.2, 0.0]))
    p = lj.Params(omega=2.0, d=0.0, mhat=0.3)
    b = lj.continuation(p, "sin2", 0.04, waveform=wave, max_points=6)
    n = int(b.n_points)
    assert n == 6 and float(b.lam[0]) == 0.0 and b.parameter == "sin2"
    j = n - 1
    w2 = lj.Fourier(omega=2.0, lbar=3.0, cos=jnp.asarray([0.0, 0.1]), sin=jnp.asarray([0.2, float(b.lam[j])]))
    g = lj.steady_gait(p, waveform=w2, periods=int(b.k))
    assert abs(float(b.mean_speed[j]) / float(g.mean_speed) - 1) < 1e-8
    assert abs(float(b.state[j, 0]) - float(g.u)) < 1e-9


def test_no_recompilation_and_parameter_leaving_its_range():
    """Another parameter, other values and another gait period reuse the compiled corrector and
    transient; a branch whose parameter leaves its valid range (mu_s below mu_k) ends INVALID there."""
    from locomotion_jax.gaits import _corrector, _shooting

    sizes = lambda: (_shooting._transient_batch._cache_size(), _corrector.correct_batch._cache_size())  # pyright: ignore[reportFunctionMemberAccess]
    lj.continuation(lj.Params(omega=jnp.asarray([2.0, 16.0])), "omega", jnp.asarray([2.1, 15.0]), max_points=3)
    before = sizes()
    b = lj.continuation(lj.Params(omega=jnp.asarray([2.0, 16.0])), "mu_s", 0.4, periods=2, max_points=60)
    assert sizes() == before
    n = int(b.n_points[1])
    assert int(b.status[1]) == BranchStatus.INVALID and 0.5 <= float(b.lam[1, n - 1]) < 0.5 + 1e-5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(parameter="foo", stop=1.0), "parameter"),
        (dict(parameter="cos1", stop=1.0), "Fourier"),
        (dict(parameter="omega", stop=2.0), "stop"),
        (dict(parameter="omega", stop=3.0, max_points=1), "max_points"),
        (dict(parameter="omega", stop=3.0, step=0.5, max_step=0.1), "step"),
        (dict(parameter="omega", stop=3.0, dynamics=lj.Smoothed()), "Exact"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        lj.continuation(lj.Params(omega=2.0), **kwargs)


# -- Every mechanism: a 3-mass chain with anisotropic friction on the same period map and corrector.


def _worm(omega) -> lj.Chain:
    """A 3-mass worm (travelling wave, d = 0) with anisotropic Coulomb friction: the pure-slip and
    stick-slip gaits of `tests/test_gait.py`'s anisotropic worms."""
    omega = jnp.asarray(omega, float)
    friction = lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)
    return lj.Chain(masses=np.ones(3), d=0.0, waveforms=lj.TravellingWave(0.05 + 0 * omega, omega, 2 * np.pi / 3),
                    friction=friction)  # fmt: skip


@pytest.fixture(scope="module")
def worm_branch() -> tuple[lj.Chain, lj.Branch]:
    """The worm continued in omega, 6 -> 6.6 and 12 -> 11.4 (a stick-slip and a pure-slip gait)."""
    chain = _worm([6.0, 12.0])
    return chain, lj.continuation(chain, "omega", jnp.asarray([6.6, 11.4]), max_points=6, step=0.25, max_step=0.5)


def test_chain_points_are_steady_gaits(worm_branch):
    """Points of a chain's branch are steady gaits: `steady_gait` of the chain at two points' omega
    (a batch of two, the branch's compiled solver), started on the points' section states, converges
    to the same orbits (state to 1e-9, speed, cost of transport and dissipation to 1e-8, multipliers
    to 1e-8), with the same regimes."""
    _, b = worm_branch
    assert b.names == "bodies" and b.state.shape[-1] == 5 and b.stick_fraction.shape[-1] == 3
    with pytest.raises(ValueError, match="`u` is the paper's name .* 3 bodies"):
        _ = b.u
    n = [int(q) for q in np.asarray(b.n_points)]
    assert min(n) >= 3 and set(np.asarray(b.status).tolist()) <= {BranchStatus.REACHED, BranchStatus.MAX_POINTS}
    for i, (start, stop) in enumerate(((6.0, 6.6), (12.0, 11.4))):
        lam = np.asarray(b.lam[i, : n[i]])
        assert lam[0] == start and np.all(np.diff(lam) * (stop - start) > 0), lam  # towards stop
        assert (lam[-1] == stop) == (int(b.status[i]) == BranchStatus.REACHED)
    rows = [(0, n[0] // 2), (1, n[1] - 1)]
    pick = lambda x: np.stack([np.asarray(x[i, j]) for i, j in rows])
    g = lj.steady_gait(_worm(pick(b.lam)), start=pick(b.state), periods=1, transient=0)
    assert np.all(np.asarray(g.status) == GaitStatus.CONVERGED) and list(np.asarray(b.k)) == [1, 1]
    np.testing.assert_allclose(np.asarray(g.state), pick(b.state), atol=1e-9)
    for name in ("mean_speed", "cost_of_transport", "e_d", "slip_margin"):
        np.testing.assert_allclose(np.asarray(getattr(g, name)), pick(getattr(b, name)), rtol=1e-8, err_msg=name)
    np.testing.assert_allclose(np.abs(np.asarray(g.multipliers)), np.abs(pick(b.multipliers)), atol=1e-8)
    np.testing.assert_array_equal(np.asarray(g.regime), pick(b.regime))


def _hop_return(cfg: dict, omega: float, y: np.ndarray, n: int) -> tuple[float, float, int]:
    """The independent hopping reference over one period from the section state `y` (gaps, velocities,
    heights, vertical velocities of `n` bodies): the largest difference of its end from `y`, its
    centre of mass's speed over the period, and its landings."""
    T = 2 * np.pi / omega
    gaps, v, h, w = y[: n - 1], y[n - 1 : 2 * n - 1], y[2 * n - 1 : 3 * n - 1], y[3 * n - 1 :]
    x0 = np.concatenate([[0.0], np.cumsum(gaps)])
    r = reference_hop_simulate(cfg, T, [T], x0=x0, v0=v, y0=h, w0=w)
    end = np.concatenate([np.diff(r["x"][0]), r["v"][0], r["y"][0], r["w"][0]])
    m = np.asarray(cfg["m"])
    return float(np.abs(end - y).max()), float(m @ (r["x"][0] - x0) / m.sum() / T), int(r["n_landings"].sum())


def _hopping_worm(omega) -> tuple[lj.Chain, list[dict]]:
    """3-mass chains on anisotropic Coulomb friction that hop (`tests/test_hop_reference.py`'s first and
    last: a = 0.08, phi = 2 pi / 3), one per `omega`, with their reference configurations."""
    cfgs = [chain_config([1.0] * 3, omega=float(w), a=0.08, phi=2 * np.pi / 3, **dict[str, Any](ANISO)) for w in omega]
    chains = [lj.Chain(masses=c["m"], k=c["k"], d=c["d"], lbar=c["lbar"], c=c["c"],
                       friction=lj.AnisotropicCoulomb(**ANISO), waveforms=lj.SpringFourier(c["A"], c["B"], c["omega"]))
              for c in cfgs]  # fmt: skip
    return lj.Chain.stack(chains), cfgs


def _check_hopping_branch(b: lj.Branch, stops, cfg_of, n: int, tol: float) -> None:
    """Every point of each branch returns onto itself under the independent reference within `tol` after
    one period, at the branch's mean speed to 1e-6 and with its landings; the points walk towards
    `stop`; each orbit flies."""
    for i, stop in enumerate(stops):
        m = int(b.n_points[i])
        lam = np.asarray(b.lam[i, :m])
        assert int(b.status[i]) in (BranchStatus.REACHED, BranchStatus.MAX_POINTS) and m >= 4, (b.status, lam)
        assert np.all(np.diff(lam) * (stop - lam[0]) > 0), lam
        assert np.all(np.asarray(b.liftoff[i, :m])) and np.all(np.asarray(b.n_land[i, :m]) > 0)
        for j in range(m):
            gap, speed, land = _hop_return(cfg_of(float(lam[j])), float(lam[j]), np.asarray(b.state[i, j]), n)
            print(i, j, lam[j], "reference return", gap, "speed", speed, float(b.mean_speed[i, j]), "landings", land)
            assert gap < tol and abs(speed - float(b.mean_speed[i, j])) < 1e-6 and int(b.n_land[i, j]) == land


def test_hopping_branches_against_the_reference():
    """Continuation under `contact="hop"` (SPEC §10), for the paper's model (a = 0.1, omega 15 -> 15.6,
    a body in flight at the section, and 20 -> 19.4) and for a hopping 3-mass chain on anisotropic
    friction (omega 6 -> 6.2 and 10 -> 9.8): each point's section state, heights and vertical velocities
    included, is carried back onto itself by the independent event-driven reference
    (`tests/reference_hop.py`) over one period within 5e-6 and 2e-5 (the exact engine's truncation error
    at dt = 0.01: measured 2.2e-6 and 9.7e-6), at the branch's mean speed to 1e-6 (measured 1.2e-7 and
    3.1e-7), with the same landings per period."""
    p = lj.Params(omega=jnp.asarray([15.0, 20.0]), a=0.1)
    b = lj.continuation(p, "omega", jnp.asarray([15.6, 19.4]), contact="hop", max_points=4, step=0.2, max_step=0.5)
    assert b.names == "paper" and b.state.shape[-1] == 7 and float(b.state[0, 0, 3]) > 0  # in flight at the section
    _check_hopping_branch(b, (15.6, 19.4), lambda w: paper_config(omega=w, a=0.1), 2, 5e-6)
    chain, _ = _hopping_worm([6.0, 10.0])
    b = lj.continuation(chain, "omega", jnp.asarray([6.2, 9.8]), contact="hop", max_points=4, step=0.25, max_step=0.5)
    assert b.names == "bodies" and b.state.shape[-1] == 11
    cfg = lambda w: chain_config([1.0] * 3, omega=w, a=0.08, phi=2 * np.pi / 3, **dict[str, Any](ANISO))
    _check_hopping_branch(b, (6.2, 9.8), cfg, 3, 2e-5)


def _hop_map(omega: float, y: np.ndarray) -> np.ndarray:
    """The independent hopping reference's period map of the paper's model (a = 0.1) on the section state
    `(u, v1, v2, y1, y2, w1, w2)`."""
    T = 2 * np.pi / omega
    r = reference_hop_simulate(paper_config(omega=omega, a=0.1), T, [T], x0=[0.0, y[0]], v0=y[1:3], y0=y[3:5],
                               w0=y[5:7])  # fmt: skip
    return np.concatenate([np.diff(r["x"][0]), r["v"][0], r["y"][0], r["w"][0]])


def _reference_torus_radius(omega: float, y: np.ndarray, free: list[int]) -> tuple[float, np.ndarray]:
    """The reference's own gait near `y` (Newton's method on the coordinates `free`, the others held) and
    the largest modulus of its complex multipliers, by central differences of its period map."""

    def jacobian(y: np.ndarray, h: float = 1e-6) -> np.ndarray:
        J = np.empty((len(free), len(free)))
        for c, k in enumerate(free):
            e = np.zeros_like(y)
            e[k] = h
            J[:, c] = (_hop_map(omega, y + e)[free] - _hop_map(omega, y - e)[free]) / (2 * h)
        return J

    y = y.copy()
    for _ in range(4):
        y[free] -= np.linalg.solve(jacobian(y) - np.eye(len(free)), (_hop_map(omega, y) - y)[free])
    assert np.abs(_hop_map(omega, y) - y).max() < 1e-10
    mu = np.linalg.eigvals(jacobian(y))
    return float(np.abs(mu[np.abs(mu.imag) > 1e-8]).max()), y


def test_a_torus_bifurcation_against_the_reference():
    """Under `contact="hop"` (the paper's model at a = 0.1), a pair of complex multipliers leaves the unit
    circle near omega = 12.437 (a torus, or Neimark-Sacker, bifurcation). Continued from either side it
    is located as `TORUS` at the same omega to 1e-10, with a complex pair of modulus 1 (1e-8) there; the
    points below it are stable, those above not, and `det_torus` changes sign between them. The
    independent reference's own gaits (Newton's method on its period map, whose Jacobian is taken by
    central differences) have their complex pair on the unit circle at an omega within 1e-4 of it
    (measured 1.5e-5: the engine's truncation error at dt = 0.01), found by the secant method."""
    b = lj.continuation(lj.Params(omega=jnp.asarray([12.40, 12.47]), a=0.1), "omega", jnp.asarray([12.47, 12.40]),
                        contact="hop", max_points=6, step=0.1, max_step=0.2)  # fmt: skip
    found = [_events(b, i, EventKind.TORUS) for i in range(2)]
    assert [len(x) for x in found] == [1, 1], found
    w_star = found[0][0]["lam"]
    assert 12.42 < w_star < 12.45 and abs(found[1][0]["lam"] - w_star) < 1e-10
    for i, (ev,) in enumerate(found):
        assert ev["located"] and ev["smooth"] and not ev["turn"]
        mu = ev["multipliers"]
        print("torus", ev["lam"], "multipliers", mu[:2], "modulus - 1", abs(mu[0]) - 1)
        assert abs(abs(mu[0]) - 1) < 1e-8 and abs(mu[0].imag) > 0.1 and mu[1] == pytest.approx(np.conj(mu[0]))
        n = int(b.n_points[i])
        lam, det = np.asarray(b.lam[i, :n]), np.asarray(b.det_torus[i, :n])
        np.testing.assert_array_equal(np.asarray(b.stable[i, :n]), lam < w_star)
        np.testing.assert_array_equal(det > 0, lam > w_star)
    # The second body stays on the ground at the section (its height and vertical velocity 0): the
    # reference's map is smooth in the other five coordinates, whose multipliers these are.
    y = found[0][0]["y"]
    assert y[4] == 0 and y[6] == 0 and y[3] > 0
    free = [0, 1, 2, 3, 5]
    w0, w1 = w_star - 0.005, w_star + 0.005
    r0, _ = _reference_torus_radius(w0, y, free)
    r1, y1 = _reference_torus_radius(w1, y, free)
    assert r0 < 1 < r1
    for _ in range(4):
        w0, r0, w1 = w1, r1, w1 - (r1 - 1) * (w1 - w0) / (r1 - r0)
        r1, y1 = _reference_torus_radius(w1, y1, free)
    print("torus at", w_star, "reference", w1, "modulus there", r1)
    assert abs(r1 - 1) < 1e-8 and abs(w1 - w_star) < 1e-4


def test_hopping_events_that_pass_each_other_are_no_torus():
    """On the hopping branch of `test_a_torus_bifurcation_against_the_reference`, continued past its torus
    point (an unstable gait, complex pair of modulus 1.37), the multipliers jump at omega = 12.95918 to
    a stable pair of modulus 0.72 while the gait keeps its 2 switches and 2 landings per period: two of
    its events pass each other, which changes the order of the bodies' mode changes (`sequence`). That
    is a `SWITCH`, bracketed by points 1e-6 apart, not a torus bifurcation (a complex pair crossing the
    unit circle smoothly). Branch 0 runs from the gait at 12.9584 (its section state, from a
    continuation from omega = 12) to 12.96, branch 1 from the same gait back to 12.957: no event."""
    y = np.array([2.9530058971622375, 1.4890430209953922, -0.3633287159244951, 0.01303765224396134, 0.0,
                  0.08317254774339829, 0.0])  # fmt: skip
    b = lj.continuation(lj.Params(omega=jnp.asarray([12.9584, 12.9584]), a=0.1), "omega", jnp.asarray([12.96, 12.957]),
                        contact="hop", start=np.stack([y, y]), transient=0, periods=1, max_points=12, step=0.05,
                        max_step=0.2)  # fmt: skip
    assert int(b.start_status[0]) == GaitStatus.CONVERGED
    kinds = [np.asarray(b.events.kind[i])[np.asarray(b.events.kind[i]) >= 0].tolist() for i in range(2)]
    assert kinds == [[EventKind.SWITCH], []], kinds
    lam_switch = float(b.events.lam[0, 0])
    for i in range(2):
        n = int(b.n_points[i])
        lam, mod = np.asarray(b.lam[i, :n]), np.abs(np.asarray(b.multipliers[i, :n, 0]))
        assert np.all(np.asarray(b.n_switch[i, :n]) == 2) and np.all(np.asarray(b.n_land[i, :n]) == 2)
        after = lam > lam_switch
        print(i, "switch at", lam_switch, "largest modulus", mod.max(), "after", mod[after])
        np.testing.assert_array_equal(np.asarray(b.stable[i, :n]), after)
        assert np.all(mod[~after] > 1.36) and np.all(mod[after] < 0.73)
    lam = np.asarray(b.lam[0, : int(b.n_points[0])])
    gap = lam[lam > lam_switch].min() - lam[lam < lam_switch].max()
    assert 12.9591 < lam_switch < 12.9593 and gap < 1e-5, (lam_switch, gap)


def test_the_torus_test_function():
    """`det(M2 - I)`, with `M2` the second compound matrix: its eigenvalues are the products of pairs of
    the eigenvalues of `M` (against numpy's eigenvalues of a random matrix), so it vanishes where a
    complex pair has modulus 1, and at a neutral saddle (real multipliers 2 and 1/2), which
    `complex_radius` (NaN where every multiplier is real) keeps from counting as a torus."""
    from locomotion_jax.gaits._bifurcation import complex_radius, compound, torus_function

    rng = np.random.default_rng(3)
    M = rng.normal(size=(5, 5))
    mu = np.linalg.eigvals(M)
    pairs = np.array([mu[i] * mu[j] for i in range(5) for j in range(i + 1, 5)])
    got = np.linalg.eigvals(compound(M))
    np.testing.assert_allclose(np.sort_complex(got), np.sort_complex(pairs), rtol=1e-10, atol=1e-12)
    assert torus_function(M) == pytest.approx(np.real(np.prod(pairs - 1)), rel=1e-10)

    def rotation(r: float) -> np.ndarray:
        """A complex pair of modulus `r` at angle 2 and a real multiplier 0.3."""
        return np.array([[r * np.cos(2.0), -r * np.sin(2.0), 0.0], [r * np.sin(2.0), r * np.cos(2.0), 0.0],
                         [0.0, 0.0, 0.3]])  # fmt: skip

    below, above = rotation(0.99), rotation(1.01)
    assert torus_function(below) < 0 < torus_function(above)
    radius = complex_radius(np.stack([np.linalg.eigvals(below), np.linalg.eigvals(above)]))
    np.testing.assert_allclose(radius, [0.99, 1.01], rtol=1e-12)
    saddle = np.diag([2.0, 0.5, 0.3])
    assert abs(torus_function(saddle)) < 1e-12 and np.isnan(complex_radius(np.linalg.eigvals(saddle)))


def test_the_sequence_code_sees_events_pass_each_other():
    """`_shooting._sequence`: two periods with the same mode changes (mass 0 sticks, mass 1 starts to
    slip backwards) in the other order, or at the other masses, get other codes, though their counts
    are equal; a step without a change keeps the code; one entry holding both masses (the array
    layout) gives the code of one entry per mass; changes made in one step are told apart by body."""
    from types import SimpleNamespace

    from locomotion_jax.gaits._shooting import _sequence

    def state(stuck, sdir, array=False):
        stuck, sdir = jnp.asarray(stuck), jnp.asarray(sdir, float)
        if array:
            return SimpleNamespace(stuck=(stuck,), sdir=(sdir,), fly=None)
        return SimpleNamespace(stuck=tuple(stuck), sdir=tuple(sdir), fly=None)

    def code(path, array=False):
        c = jnp.zeros((), jnp.uint32)
        for before, after in zip(path, path[1:]):
            c = _sequence(c, state(*before, array=array), state(*after, array=array))
        return int(c)

    start = ([False, False], [1.0, 1.0])  # both slipping forwards
    stick0 = ([True, False], [1.0, 1.0])
    back1 = ([False, False], [1.0, -1.0])
    both = ([True, False], [1.0, -1.0])
    stick1 = ([False, True], [1.0, 1.0])
    back0 = ([False, False], [-1.0, 1.0])
    one_way = code([start, stick0, stick0, both])
    other_order = code([start, back1, both])
    other_masses = code([start, stick1, ([True, True], [-1.0, 1.0])])
    assert len({one_way, other_order, other_masses, 0}) == 4
    assert code([start, start, start]) == 0 and code([start, back0]) != code([start, back1])
    for path in ([start, stick0, both], [start, back1, both], [start, stick1, back0]):
        assert code(path, array=True) == code(path)
    # Changes made in one step: mass 0 starts to slip as mass 1 sticks, then the other way round,
    # against the two steps swapped (a sum over the changed masses gives both steps one term).
    held0, held1 = ([True, False], [1.0, 1.0]), ([False, True], [1.0, 1.0])
    assert code([held0, held1, held0]) != code([held1, held0, held1])
    assert code([held0, held1], array=True) == code([held0, held1]) != code([held1, held0])
