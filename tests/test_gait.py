"""Steady gaits (periodic orbits) of every mechanism.

- The paper's model: against long direct simulations averaged over whole periods, the monodromy
  matrix against finite differences of the independent reference, the statuses (`GaitStatus`, an
  `enum.IntEnum` like `Status`), and gaits with flight phases (`contact="hop"`, SPEC §10: the period
  map through lift-offs, flights and landings).
- Chains of N masses: the orbit against a long direct simulation averaged over whole periods, its
  monodromy against finite differences of the period map, and the N = 2 chain against the
  two-mass solver.
- Mechanisms (SPEC §9): a capsule's orbit against a direct `simulate` over its period and the
  independent event-driven reference (`tests/reference_mechanism.py`), the exact periodic solution
  of a damped linear oscillator on a wall spring driven by a harmonic external force; batches flag
  a bad configuration alone."""

import dataclasses
import enum
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax import GaitStatus, steady_gait
from locomotion_jax.gaits import _select, _shooting as cg
from mechanism_cases import ANISO, capsule, capsule_ref
from reference import reference_simulate
from reference_mechanism import Body, run, Sig, System


pytestmark = pytest.mark.xdist_group("gait")

# SSL and SL gaits, several stiffnesses, offsets, friction and mass ratios.
CASES: list[dict[str, Any]] = [
    dict(omega=1.0),
    dict(omega=2.0),
    dict(omega=4.0),
    dict(omega=16.0),
    dict(omega=23.0),
    dict(omega=3.0, a=0.02),
    dict(omega=2.0, mu_s=0.5, mu_k=0.3),
    dict(omega=5.0, mhat=0.3, c=0.1),
    dict(omega=8.0, d=0.2),
    dict(omega=6.0, k=30.0, a=0.03),
]


def _batch(cases: list[dict[str, Any]]) -> lj.Params:
    keys = sorted({k for c in cases for k in c})
    cols = {k: jnp.asarray([c.get(k, lj.DEFAULTS[k]) for c in cases]) for k in keys}
    return lj.Params(**cols, check=False)


def _direct(params: lj.Params, k: int, waveform=None, n0: int = 200, n: int = 20) -> tuple[float, float]:
    """Mean speed and cost of transport of `simulate` over `n` gait periods after `n0`,
    saved at every gait period (so that its steps restart where the period map's do)."""
    kT = k * 2 * np.pi / float(params.omega)
    tr = lj.simulate(params, (n0 + n) * kT, save_at=np.arange(n0 + n + 1) * kT, waveform=waveform)
    X, ed = np.asarray(tr.X), np.asarray(tr.e_d)
    dX = X[-1] - X[n0]
    return dX / (n * kT), (ed[-1] - ed[n0]) / abs(dX)


BAD: list[dict[str, Any]] = [dict(omega=2.0, mu_s=0.3), dict(omega=10.0, a=0.3)]
"""An invalid configuration (mu_s < mu_k) and one that lifts off (strict reading)."""


def test_gait_matches_long_direct_simulation():
    """Speed and cost of transport equal a long direct simulation's over whole periods, with
    bad configurations in the same batch flagged alone (NaN numbers, their own status)."""
    g = steady_gait(_batch(CASES + BAD))
    n = len(CASES)
    assert list(np.asarray(g.status)[n:]) == [GaitStatus.INVALID, GaitStatus.LIFTOFF]
    assert bool(g.liftoff[n + 1]) and not np.any(np.asarray(g.liftoff)[:n])
    for i in (n, n + 1):
        assert np.isnan(float(g.mean_speed[i])) and np.isnan(float(g.cost_of_transport[i]))
        assert not bool(g.stable[i]) and int(g.k[i]) == 0 and np.all(np.isnan(np.asarray(g.monodromy[i])))
    assert np.all(np.asarray(g.status)[:n] == GaitStatus.CONVERGED)
    regimes = {int(r) for r in np.asarray(g.regime)[:n]}
    assert regimes == {int(lj.Regime.SSL), int(lj.Regime.SL)}, "the cases cover both regimes"
    for i, case in enumerate(CASES):
        speed, cot = _direct(lj.Params(**case), int(g.k[i]))
        assert abs(float(g.mean_speed[i]) / speed - 1) < 1e-8, (case, float(g.mean_speed[i]), speed)
        assert abs(float(g.cost_of_transport[i]) / cot - 1) < 1e-8, (case, float(g.cost_of_transport[i]), cot)
        # On the orbit the energy (eq. 10) is periodic: the work equals the dissipation, to
        # the truncation error of the step (dt = 0.03), which the two integrals do not share.
        assert abs(float(g.work[i]) - float(g.e_d[i])) < 3e-5 * float(g.e_d[i])
    # A configuration's result is its own, batch or not (to round-off: a batch and a single
    # configuration compile to different kernels).
    alone = steady_gait(lj.Params(**CASES[1]))
    assert float(g.mean_speed[1]) == pytest.approx(float(alone.mean_speed), rel=1e-12)
    np.testing.assert_allclose(np.asarray(g.monodromy[1]), np.asarray(alone.monodromy), rtol=1e-10, atol=1e-12)


def test_gait_with_waveform_at_d0():
    """d = 0, mhat = 0.3 under a waveform with a second harmonic: a gait that moves
    although the normal forces are constant."""
    wave = lj.Fourier(omega=2.0, lbar=3.0, cos=jnp.asarray([0.0, 0.1]), sin=jnp.asarray([0.2, 0.0]))
    p = lj.Params(omega=2.0, d=0.0, mhat=0.3)
    g = steady_gait(p, waveform=wave)
    assert int(g.status) == GaitStatus.CONVERGED
    speed, cot = _direct(p, int(g.k), waveform=wave)
    assert abs(speed) > 1e-3
    assert abs(float(g.mean_speed) / speed - 1) < 1e-8
    assert abs(float(g.cost_of_transport) / cot - 1) < 1e-8


def _reference_map(case: dict, y: np.ndarray, k: int = 1) -> np.ndarray:
    """The period map of the independent scipy solver: $(u, v_1, v_2)$ after $kT$ from phase 0."""
    kT = k * 2 * np.pi / case["omega"]
    r = reference_simulate(case, kT, save_at=[kT], start=(0.0, y[1], y[0], y[2]), rtol=1e-12, atol=1e-13)
    return np.array([r["x2"][0] - r["x1"][0], r["v1"][0], r["v2"][0]])


UNSTABLE: dict[str, Any] = dict(omega=1.5, d=0.3, mhat=0.3)
"""Past a period doubling: the attractor repeats every two periods; the period-1 orbit
it doubled from has a Floquet multiplier of about -3.6."""


@pytest.mark.parametrize(
    "case", [dict(omega=2.0), dict(omega=4.0), dict(omega=16.0), dict(omega=5.0, mhat=0.3, c=0.1), UNSTABLE]
)
def test_monodromy_matches_reference_differences(case):
    """Forward-mode monodromy (events by the implicit function theorem, saltation included)
    against central differences of the reference's period map; its fixed point is periodic
    under the reference too, and its stability is the reference's."""
    g = steady_gait(lj.Params(**case), dynamics=lj.Exact(dt=0.005), periods=1)
    assert int(g.status) == GaitStatus.CONVERGED
    y = np.asarray([float(g.u), float(g.v1), float(g.v2)])
    np.testing.assert_allclose(_reference_map(case, y), y, atol=1e-6)
    M = np.asarray(g.monodromy)
    # A mass at rest at the section is held there: its velocity is no unknown (zero column).
    free = [0] + [1 + i for i in range(2) if y[1 + i] != 0.0]
    for j in set(range(3)) - set(free):
        assert np.all(M[:, j] == 0)
    # Central differences at steps h and 2h, extrapolated (Richardson): the unstable orbit's
    # map is strongly curved (|M| ~ 37), so that plain differences are 2.5e-5 off at 1e-6,
    # and at 1e-7 the reference's round-off (rtol 1e-12) costs as much. That map's
    # derivative also moves by ~1e-5 between orbits computed at dt = 0.005 and 0.0025.
    h = 1e-6
    fd = np.zeros((3, 3))
    for j in free:
        e = np.zeros(3)
        e[j] = h
        d1 = (_reference_map(case, y + e) - _reference_map(case, y - e)) / (2 * h)
        d2 = (_reference_map(case, y + 2 * e) - _reference_map(case, y - 2 * e)) / (4 * h)
        fd[:, j] = (4 * d1 - d2) / 3
    np.testing.assert_allclose(M, fd, rtol=2e-5, atol=1e-5)
    mult = np.asarray(g.multipliers)
    ref = np.linalg.eigvals(fd)
    ref = ref[np.argsort(-np.abs(ref))]
    np.testing.assert_allclose(np.abs(mult), np.abs(ref), rtol=1e-5, atol=1e-5)
    assert bool(g.stable) == (np.max(np.abs(ref)) < 1)


def test_unstable_orbit_and_period_two_gait():
    """`periods=1` returns the unstable period-1 orbit; by default the stable period-2 gait,
    which a direct simulation settles on: its state at whole actuation periods alternates
    between the two section states of the gait, on either side of the unstable orbit."""
    p = lj.Params(**UNSTABLE)
    g1 = steady_gait(p, periods=1)
    assert int(g1.status) == GaitStatus.CONVERGED and not bool(g1.stable)
    assert float(np.real(g1.multipliers[0])) < -3
    g = steady_gait(p)
    assert int(g.status) == GaitStatus.CONVERGED and int(g.k) == 2 and bool(g.stable)
    assert float(g.period) == pytest.approx(2 * 2 * np.pi / UNSTABLE["omega"], rel=1e-14)
    T = 2 * np.pi / UNSTABLE["omega"]
    tr = lj.simulate(p, 300 * T, save_at=np.arange(301) * T)
    u = np.asarray(tr.x2 - tr.x1)[-4:]
    assert abs(u[0] - u[2]) < 1e-9 and abs(u[1] - u[3]) < 1e-9 and abs(u[0] - u[1]) > 1e-3
    assert min(abs(float(g.u) - u[0]), abs(float(g.u) - u[1])) < 1e-9
    assert min(u[0], u[1]) < float(g1.u) < max(u[0], u[1])


def test_a_stuck_gait_is_not_tried_at_longer_periods(monkeypatch):
    """A sinusoid too small to overcome static friction leaves both masses stuck: the transient
    ends on the orbit (no Newton iteration), unstable by its multiplier 1. That state is a fixed
    point of every longer period's map, no more stable there, so periods 2 to 4 are not tried for
    it; they are for an unstable orbit Newton's method iterated to (a period doubling, a gait of
    period 3). Every field of the result is what trying them gives."""
    cases = [dict(a=0.05 / 6, omega=0.5), UNSTABLE, dict(a=0.05, omega=4.253), dict(omega=2.0)]
    tried: list[tuple[int, list[int]]] = []
    newton = cg.newton

    def spy(C, physics_of, contact, dt, y0, go, k, *args):
        tried.append((k, np.flatnonzero(np.asarray(go)).tolist()))
        return newton(C, physics_of, contact, dt, y0, go, k, *args)

    monkeypatch.setattr(cg, "newton", spy)
    g = steady_gait(_batch(cases))
    assert tried == [(1, [0, 1, 2, 3]), (2, [1, 2]), (3, [2])]
    assert np.asarray(g.k).tolist() == [1, 2, 3, 1] and np.asarray(g.stable).tolist() == [False, True, True, True]
    assert int(g.n_iter[0]) == 0 and float(np.abs(g.multipliers[0, 0])) == pytest.approx(1.0, abs=1e-9)
    assert float(g.mean_speed[0]) == 0.0
    # Periods 2 to 4 tried for the stuck gait too (every unstable orbit still open): the same result.
    tried.clear()
    monkeypatch.setattr(_select, "still_open", lambda r: (r["status"] == GaitStatus.NOT_CONVERGED)
                        | ((r["status"] == GaitStatus.CONVERGED) & ~r["stable"]))  # fmt: skip
    every = steady_gait(_batch(cases))
    assert tried == [(1, [0, 1, 2, 3]), (2, [0, 1, 2]), (3, [0, 2]), (4, [0])]
    for name in (f.name for f in dataclasses.fields(g)):
        a, b = np.asarray(getattr(g, name)), np.asarray(getattr(every, name))
        np.testing.assert_array_equal(a, b, err_msg=name)


@pytest.mark.slow  # a second compilation of the solver; float32 engines are tested in the default run
def test_float32():
    """float32: Newton to 1e-5, speeds within 1e-4 of float64 (SL gait, complex multipliers)."""
    p = lj.Params(omega=16.0)
    g = steady_gait(p, dtype=jnp.float32)
    g64 = steady_gait(p)
    assert int(g.status) == GaitStatus.CONVERGED and g.mean_speed.dtype == jnp.float32
    assert float(g.mean_speed) == pytest.approx(float(g64.mean_speed), rel=1e-4)
    np.testing.assert_allclose(np.abs(np.asarray(g.multipliers)), np.abs(np.asarray(g64.multipliers)), atol=1e-3)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(periods=0), "periods"),
        (dict(periods=()), "periods"),
        (dict(transient=-1), "transient"),
        (dict(tol=0.0), "tol"),
        (dict(max_iter=0), "max_iter"),
        (dict(contact="soft"), "contact"),
        (dict(dynamics=lj.Smoothed()), "Exact"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        steady_gait(lj.Params(), **kwargs)


def test_jit_free_of_recompilation():
    """Another configuration of the same batch size, another period or another step `dt` (the
    optimiser's check at dt/2) reuses the compiled solver."""
    from locomotion_jax.gaits import _corrector, _shooting

    steady_gait(lj.Params(omega=3.0), periods=1)
    sizes = lambda: (_shooting._transient_batch._cache_size(), _corrector.correct_batch._cache_size())  # pyright: ignore[reportFunctionMemberAccess]
    before = sizes()
    steady_gait(lj.Params(omega=5.0, mu_s=0.9), periods=2, transient=10)
    steady_gait(lj.Params(omega=3.0), periods=1, dynamics=lj.Exact(dt=0.005))
    assert sizes() == before


def test_batch_sizes_of_a_bucket_share_the_solver():
    """`steady_gait` solves a batch as the rows of its bucket (`_shooting.gait_rows`: 3 and 4
    configurations as 4 rows), the padding not solved: the second batch size compiles nothing, and
    the 3 gaits are bitwise the first 3 of the 4."""
    from locomotion_jax.gaits import _corrector, _shooting

    omegas = jnp.array([1.5, 2.5, 7.0, 4.5])
    kw: dict[str, Any] = dict(periods=1, transient=10, dynamics=lj.Exact(dt=0.02))
    three = steady_gait(lj.Params(omega=omegas[:3], a=0.05), **kw)
    sizes = lambda: (_shooting._transient_batch._cache_size(), _corrector.correct_batch._cache_size())  # pyright: ignore[reportFunctionMemberAccess]
    before = sizes()
    four = steady_gait(lj.Params(omega=omegas, a=0.05), **kw)
    assert sizes() == before
    assert np.all(np.asarray(four.converged)) and three.mean_speed.shape == (3,)
    for name in (f.name for f in dataclasses.fields(three)):
        a, b = getattr(three, name), getattr(four, name)
        if isinstance(a, str):
            assert a == b
        else:
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[:3], err_msg=name)


def test_compact_batch_for_the_longer_periods(monkeypatch):
    """With `compact=True` (the exact optimiser's sinusoid sweep) a gait period tried on fewer
    than a quarter of the batch runs on a quarter-size batch, and one tried on more runs as
    quarter-size batches in the order of the forcing periods: the same gaits as the full batch,
    the period-2 gait past a period doubling included, and every other row as before."""
    from locomotion_jax.gaits import _corrector, _gait

    p = _batch(CASES[:9] + BAD + [UNSTABLE])
    full = _gait.paper_gait(p, dynamics=lj.Exact())
    sizes: list[int] = []
    solve = _corrector.correct_batch
    omegas: list[np.ndarray] = []

    def spy(*a):
        sizes.append(int(a[8].shape[0]))
        omegas.append(np.asarray(a[0][0].omega))  # the configurations: (params, waveform)
        return solve(*a)

    monkeypatch.setattr(_corrector, "correct_batch", spy)
    small = _gait.paper_gait(p, dynamics=lj.Exact(), compact=True)
    assert set(sizes) == {3} and len(sizes) > 4, sizes  # period 1 as four batches of 3 rows, then the others
    # Period 1's batches: every row once, the fastest forcing first.
    first = np.concatenate(omegas[:4])
    assert sorted(first.tolist()) == sorted(np.asarray(p.omega).tolist())
    assert np.all(np.diff(first) <= 0), first
    assert int(small.k[-1]) == 2 and bool(small.stable[-1]) and int(full.k[-1]) == 2
    for name in (f.name for f in dataclasses.fields(full)):
        a, b = getattr(full, name), getattr(small, name)
        if name == "contact":
            assert a == b
        elif np.issubdtype(np.asarray(a).dtype, np.inexact):
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-12, atol=1e-15, err_msg=name)
        else:
            np.testing.assert_array_equal(np.asarray(b), np.asarray(a), err_msg=name)


def test_one_gait_class_under_the_paper_names():
    import warnings

    import equinox as eqx

    g = steady_gait(lj.Params(omega=16.0))
    assert type(g) is lj.Gait and g.names == "paper" and g.n_bodies == 2 and g.state.shape == (3,)
    for name, i in (("u", 0), ("v1", 1), ("v2", 2)):
        np.testing.assert_array_equal(np.asarray(getattr(g, name)), np.asarray(g.state)[i])
    np.testing.assert_array_equal(np.asarray(g.stick_fraction2), np.asarray(g.stick_fraction)[1])
    # Three bodies: the paper's names are refused; an anchored two-body state holds positions.
    three = eqx.tree_at(lambda r: (r.stick_fraction, r.state), g, (jnp.zeros(3), jnp.zeros(5)))
    for name in ("u", "v2", "stick_fraction1"):
        with pytest.raises(ValueError, match=rf"`{name}` is the paper's name .* this result has 3 bodies"):
            getattr(three, name)
    with pytest.raises(ValueError, match="positions then velocities"):
        _ = eqx.tree_at(lambda r: r.state, g, jnp.zeros(4)).v1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert lj.ChainGait is lj.Gait
    assert any(issubclass(w.category, DeprecationWarning) for w in caught)


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
    """One converged gait and one invalid configuration (nothing integrated, no warning of its
    omega = 0) in a batch."""
    params = lj.Params(omega=np.array([2.0, 0.0]), mu_s=np.array([0.5, 0.3]), check=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = lj.steady_gait(params, periods=1)
    names = [lj.GaitStatus(int(s)).name for s in np.asarray(g.status)]
    assert names == ["CONVERGED", "INVALID"]
    assert lj.GaitStatus(int(g.status[0])) == lj.GaitStatus.CONVERGED == 0


def test_hopping_gait_is_the_limit_of_a_long_simulation():
    """The paper's model at omega = 15 and 20, a = 0.1 (`Params`, one batch): both gaits are stable
    1-periodic orbits with flight phases (the long run lands about twice per period); a simulation
    from the paper's start reaches the orbit's section state (gap, velocities, heights, vertical
    velocities) within 1e-7 after 300 periods (measured 6e-9 and 9e-9) and its drift over one period
    gives the gait's mean speed, and its landings (597 and 596) are the gait's two per period but for
    the transient's; the multipliers lie inside the unit circle (a grounded body's
    vertical components give zeros); started on its own section states, each gait is found again."""
    omega = np.asarray([15.0, 20.0])
    p = lj.Params(omega=jnp.asarray(omega), a=0.1)
    g = lj.steady_gait(p, contact="hop")
    assert isinstance(g, lj.Gait) and g.state.shape == (2, 7)
    print("gait", g.status, g.mean_speed, np.abs(np.asarray(g.multipliers)).round(4), np.asarray(g.state))
    assert np.all(np.asarray(g.status) == lj.GaitStatus.CONVERGED) and np.all(np.asarray(g.stable))
    mult = np.abs(np.asarray(g.multipliers))
    assert np.all(mult < 0.95) and np.all(np.sort(mult, -1)[:, :2] < 1e-8)
    T = 2 * np.pi / omega
    for i in range(2):
        ts = np.asarray([300 * T[i], 301 * T[i]])
        tr = lj.simulate(lj.Params(omega=float(omega[i]), a=0.1), t_end=float(ts[-1]), save_at=ts, contact="hop")
        assert tr.y is not None and tr.vy is not None and tr.n_land is not None
        red = np.concatenate(
            [np.asarray(tr.x2 - tr.x1)[:, None], np.asarray(tr.x)[:, :0], np.asarray(tr.v), np.asarray(tr.y),
             np.asarray(tr.vy)], -1,
        )  # fmt: skip
        diff = np.abs(red - np.asarray(g.state[i])[None]).max()
        speed = float(tr.X[1] - tr.X[0]) / T[i]
        print(i, "landings", int(tr.n_land), "|orbit - simulation|", diff, "speed", speed, float(g.mean_speed[i]))
        assert int(tr.status) == lj.Status.OK and int(tr.n_land) > 500  # it hops: about 2 landings per period
        # The gait's landings per period (n_land over k periods) are the long run's after its transient.
        per_period = int(g.n_land[i]) / int(g.k[i])
        print(i, "gait landings per period", per_period, "long run", int(tr.n_land) / 301)
        assert per_period >= 1 and abs(int(tr.n_land) - 301 * per_period) <= 10
        assert diff < 1e-7 and abs(speed - float(g.mean_speed[i])) < 1e-7
    assert float(np.asarray(g.state)[0, 3]) > 0  # at omega = 15 a body is in flight at the section
    # Started on its own section states (heights and vertical velocities given, a body in flight), one
    # transient period: each gait is found again at once (no Newton iteration), to 1e-10.
    again = lj.steady_gait(p, contact="hop", start=g.state, transient=1)
    print("again", np.asarray(again.n_iter), np.abs(np.asarray(again.state - g.state)).max())
    assert np.all(np.asarray(again.converged)) and np.all(np.asarray(again.n_iter) == 0)
    assert np.abs(np.asarray(again.state - g.state)).max() < 1e-10
    # Basins under "hop": from that state and from it with the flying body 1 cm higher, one gait.
    own = np.asarray(g.state[0])
    b = lj.basins(lj.Params(omega=15.0, a=0.1), np.stack([own, own + np.r_[0, 0, 0, 0.01, 0, 0, 0]]), contact="hop")
    assert np.asarray(b.count).tolist() == [2] and abs(float(b.gaits.mean_speed[0] - g.mean_speed[0])) < 1e-9


# Chains of N masses.

CHAIN_GAIT = pytest.mark.xdist_group("chain_gait")  # the worms are solved once, on one worker

P = np.pi


@pytest.fixture(scope="module")
def worms():
    """N = 3 worms (travelling waves), strict contact: two stick-slip gaits (waves towards the
    front and the rear), a pure-slip gait driven by anisotropy (d = 0), an anisotropic stick-slip
    gait, and an invalid configuration (omega < 0)."""
    om = np.array([3.0, 6.0, 12.0, 6.0, -1.0])
    a = np.array([0.08, 0.05, 0.03, 0.05, 0.05])
    phi = np.array([2 * P / 3, -2 * P / 3, 2 * P / 3, 2 * P / 3, 1.0])
    d = np.array([0.5, 0.5, 0.0, 0.0, 0.5])
    col = lambda *v: np.array(v)[:, None]
    friction = lj.AnisotropicCoulomb(col(0.7, 0.7, 0.7, 0.7, 0.7), col(0.7, 0.7, 0.9, 0.9, 0.7),
                                     col(0.5, 0.5, 0.5, 0.5, 0.5), col(0.5, 0.5, 0.7, 0.7, 0.5))  # fmt: skip
    chain = lj.Chain(masses=np.ones((5, 3)), d=d[:, None], waveforms=lj.TravellingWave(a, om, phi),
                     friction=friction, check=False)  # fmt: skip
    return chain, lj.steady_gait(chain)


@CHAIN_GAIT
def test_chain_gait_equals_long_direct_simulation(worms):
    """Speed and cost of transport of the orbit equal `simulate` averaged over 12 periods after
    the transient has decayed below 1e-10 (from the orbit's own multipliers), to 1e-8."""
    chain, g = worms
    assert list(np.asarray(g.status)) == [lj.GaitStatus.CONVERGED] * 4 + [lj.GaitStatus.INVALID]
    assert list(np.asarray(g.regime)[:4]) == [lj.Regime.SSL, lj.Regime.SSL, lj.Regime.SL, lj.Regime.SSL]
    assert np.all(np.asarray(g.stable)[:4]) and np.all(np.asarray(g.k)[:4] == 1)
    assert np.all(np.isnan(np.asarray(g.mean_speed)[4])) and not np.any(np.isnan(np.asarray(g.mean_speed)[:4]))
    omega = np.asarray(chain.waves.omega)[:4]
    mu = np.max(np.abs(np.asarray(g.multipliers)[:4]), axis=-1)
    # Saved at every period of its own omega, the direct run restarts its steps where the
    # period map does (one call per omega, the same number of saves: one compilation).
    n0 = int(np.ceil(np.max(np.log(1e-10) / np.log(mu))))
    K = 12
    assert n0 < 800
    speed, cost, status = np.zeros(4), np.zeros(4), []
    for w in np.unique(omega):
        T = 2 * P / w
        tr = lj.simulate(chain, (n0 + K) * T, save_at=np.arange(n0 + K + 1) * T)
        X, ed = np.asarray(tr.X)[:4], np.asarray(tr.e_d)[:4]
        status.append(np.asarray(tr.status)[4])
        dX = X[:, -1] - X[:, n0]
        at = omega == w
        speed[at], cost[at] = (dX / (K * T))[at], ((ed[:, -1] - ed[:, n0]) / np.abs(dX))[at]
    np.testing.assert_allclose(np.asarray(g.mean_speed)[:4], speed, rtol=1e-8)
    np.testing.assert_allclose(np.asarray(g.cost_of_transport)[:4], cost, rtol=1e-8)
    # On the orbit the energy is periodic: the work per period equals the dissipation, up to
    # the integrator's error (worst here the fast pure-slip worm at 52 steps per period:
    # 1.7e-5 at dt = 0.01, 4.8e-7 at 0.005, 1.1e-8 at 0.0025).
    np.testing.assert_allclose(np.asarray(g.work)[:4], np.asarray(g.e_d)[:4], rtol=5e-5)
    assert status == [lj.Status.INVALID] * len(status)


@CHAIN_GAIT
def test_transient_speed_equals_simulation_and_the_gait(worms):
    """`transient_speed` (the chain optimiser's screen reads it before solving gaits): the centre
    of mass's mean speed over periods 18 to 30 from the start at rest equals `simulate`'s, saved
    at those times (where the steps restart, as in the transient), to 1e-9; it nears the steady
    gait's speed as the transient decays; NaN for the invalid configuration."""
    chain, g = worms
    v = cg.transient_speed(chain, transient=30, last=12, dynamics=lj.Exact(), start="paper")
    assert v.shape == (5,) and np.isnan(v[4]) and np.all(np.isfinite(v[:4]))
    omega = np.asarray(chain.waves.omega)[:4]
    direct = np.zeros(4)
    for w in np.unique(omega):
        T = 2 * P / w
        X = np.asarray(lj.simulate(chain, 30 * T, save_at=np.array([18 * T, 30 * T])).X)[:4]
        direct[omega == w] = ((X[:, 1] - X[:, 0]) / (12 * T))[omega == w]
    np.testing.assert_allclose(v[:4], direct, rtol=1e-9)
    # Its error against the gait decays like the transient, |mu|^n after n periods: 1e-5 (mu = 0.70)
    # to 0.14 for the pure-slip worm (mu = 0.97), which the screen's margin (half of v_min) allows.
    mu = np.max(np.abs(np.asarray(g.multipliers)[:4]), axis=-1)
    gait = np.asarray(g.mean_speed)[:4]
    assert np.all(np.abs(v[:4] - gait) <= (mu**18 + 1e-8) * np.abs(gait))  # 1e-8: the integration error
    with pytest.raises(ValueError, match="1 <= last < transient"):
        cg.transient_speed(chain, transient=10, last=10, dynamics=lj.Exact())


@CHAIN_GAIT
def test_chain_monodromy_against_finite_differences(worms):
    """The monodromy of the pure-slip worm (every mass moving at the section) against central
    differences of the period map, and so its multipliers, to 1e-5."""
    chain, g = worms
    i = 2
    one = jax.tree_util.tree_map(lambda x: x[i], chain.broadcast())
    Pc = one.physics()
    y = jnp.asarray(g.state[i])
    phi = jax.jit(lambda y: cg.period_map(Pc, "strict", 0.01, 100_000, 1.0, y).y)
    h = 1e-6
    cols = [(phi(y + h * e) - phi(y - h * e)) / (2 * h) for e in jnp.eye(y.shape[0], dtype=y.dtype)]
    M_fd = np.stack([np.asarray(c) for c in cols], axis=1)
    M = np.asarray(g.monodromy[i])
    np.testing.assert_allclose(M, M_fd, atol=1e-5 * np.max(np.abs(M)))
    ev = lambda A: np.sort_complex(np.linalg.eigvals(A))
    np.testing.assert_allclose(ev(M), ev(M_fd), atol=1e-5)
    assert np.all(np.asarray(g.state[i])[2:] != 0)  # no mass at rest at the section


@CHAIN_GAIT
@pytest.mark.parametrize("layout", ["array", "unrolled"])
def test_monodromy_through_coincident_events(layout):
    """A symmetric worm (equal masses, springs in antiphase) whose end masses break away and stop at
    the same instants: each switch is differentiated at its own time (`_engine._retimed`), so
    the monodromy equals central differences of the period map to 1e-5, as where the events are
    apart; a mass at rest at the section has a zero column in both."""
    fr = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    chain = lj.Chain(masses=[1.0] * 3, d=0.0, waveforms=lj.TravellingWave(0.05, 3.5, P), friction=fr, layout=layout)
    g = lj.steady_gait(chain, periods=(1,), start="relaxed")
    y = jnp.asarray(g.state)
    assert bool(g.converged) and float(y[2]) == 0.0 and float(y[4]) == 0.0  # the end masses stuck at phase 0
    assert abs(float(y[0] + y[1]) - 6.0) < 1e-9  # x_3 - x_1 = 2 lbar: the end masses move (and switch) together
    Pc = cg.physics_for(chain)(chain)[0]
    phi = jax.jit(lambda y: cg.period_map(Pc, "strict", 0.01, 100_000, 1.0, y).y)
    h = 1e-6
    M_fd = np.stack([np.asarray((phi(y + h * e) - phi(y - h * e)) / (2 * h)) for e in jnp.eye(5, dtype=y.dtype)], 1)
    M = np.asarray(g.monodromy)
    assert np.max(np.abs(M)) > 0.1
    np.testing.assert_allclose(M, M_fd, atol=1e-5 * np.max(np.abs(M)))


@CHAIN_GAIT
def test_two_mass_chain_gait_equals_the_two_mass_solver():
    """`Chain.from_params` (the paper's model as N = 2) on the N-mass solver equals the two-mass
    `steady_gait`: a stick-slip and a pure-slip gait."""
    p = lj.Params(omega=np.array([2.0, 5.0]))
    g2 = lj.steady_gait(p)
    gc = lj.steady_gait(lj.Chain.from_params(p))
    assert list(np.asarray(gc.regime)) == [lj.Regime.SSL, lj.Regime.SL]
    for a, b in ((gc.mean_speed, g2.mean_speed), (gc.cost_of_transport, g2.cost_of_transport),
                 (gc.stick_fraction[:, 0], g2.stick_fraction1), (gc.stick_fraction[:, 1], g2.stick_fraction2),
                 (gc.state[:, 0], g2.u), (gc.state[:, 1], g2.v1), (gc.state[:, 2], g2.v2)):  # fmt: skip
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(np.abs(np.asarray(gc.multipliers)), np.abs(np.asarray(g2.multipliers)), atol=1e-10)


@CHAIN_GAIT
def test_jacfwd_in_turn_equals_jacfwd():
    """The corrector's Jacobian (`_forward.jacfwd_in_turn`: directions in turn on a CPU) is
    `jax.jacfwd`'s, with the auxiliary output of the primal, under `vmap` as well."""
    from locomotion_jax.dynamics._forward import jacfwd_in_turn

    def f(x):
        y = jnp.stack([jnp.sin(x[0]) * x[1], x[2] ** 3 - x[0], jnp.exp(x[1] * x[2])])
        return y, (jnp.sum(x), x[0] > 0)

    X = jnp.asarray(np.random.default_rng(0).normal(size=(4, 3)))
    for a, b in zip(jax.tree_util.tree_leaves(jax.vmap(jacfwd_in_turn(f, has_aux=True))(X)),
                    jax.tree_util.tree_leaves(jax.vmap(jax.jacfwd(f, has_aux=True))(X))):  # fmt: skip
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-14, atol=0)
    g = lambda x: f(x)[0]
    np.testing.assert_allclose(np.asarray(jacfwd_in_turn(g)(X[0])), np.asarray(jax.jacfwd(g)(X[0])), rtol=1e-14)


@CHAIN_GAIT
def test_patience_stops_only_the_stalled_configurations(monkeypatch):
    """`patience` (the optimiser's screen) stops a configuration whose Newton residual has not
    halved for that many iterations: the paper's model at omega = 4.2 has no gait of period 1 to
    4, and its residual cycles near 5e-3. The gaits found are the same to the last bit, with the
    same iterations; the stalled configuration stops within `patience` + 2 iterations instead of 12."""
    its = []
    newton = cg.newton
    monkeypatch.setattr(cg, "newton", lambda *a, **k: (lambda r: its.append(r["it"]) or r)(newton(*a, **k)))
    chain = lj.Chain.from_params(lj.Params(omega=np.array([2.0, 4.2, 5.0, 4.2])))
    runs = {}
    for patience in (None, 3):
        its.clear()
        g = cg.steady_gait_chain(chain, dynamics=lj.Exact(), patience=patience)
        runs[patience] = g, np.array(its)
    (g0, it0), (g3, it3) = runs[None], runs[3]
    assert list(np.asarray(g0.converged)) == [True, False, True, False]
    assert it0.shape == it3.shape and np.all(it0[:, [1, 3]] == 12)
    assert np.all(it3[:, [1, 3]] <= 5)
    np.testing.assert_array_equal(it3[:, [0, 2]], it0[:, [0, 2]])
    for a, b in zip(jax.tree_util.tree_leaves(g0), jax.tree_util.tree_leaves(g3)):
        np.testing.assert_array_equal(np.asarray(a)[[0, 2]], np.asarray(b)[[0, 2]])


@CHAIN_GAIT
def test_chain_gait_bad_input():
    chain = lj.Chain(masses=np.ones(3), waveforms=lj.TravellingWave(0.05, 3.0, 1.0))
    with pytest.raises(ValueError, match="carries its own waveforms"):
        lj.steady_gait(chain, waveform=lj.Sinusoid(0.1, 2.0, 3.0))
    with pytest.raises(ValueError, match=r"section states .* of shape \(5,\)"):
        lj.steady_gait(chain, start=np.zeros(4))
    with pytest.raises(ValueError, match="the gaps u_j must be > 0"):
        lj.steady_gait(chain, start=np.zeros(5))
    with pytest.raises(ValueError, match="contact"):
        lj.steady_gait(chain, contact="soft")


@CHAIN_GAIT
def test_chain_basins_and_gaits_from_given_starts(worms):
    """`steady_gait(chain, start=states)` and `basins` on a chain: starts near and far from the
    anisotropic worm's stick-slip gait (section states: gaps, then velocities) all end on it, its
    speed and cost to 1e-9; a start whose masses are out of order is flagged, never run."""
    chain, gaits = worms
    worm, gait = chain[3], jax.tree_util.tree_map(lambda x: x[3], gaits)
    y = np.asarray(gait.state)
    assert y.shape == (5,) and bool(gait.converged)
    starts = np.stack([y, y + np.array([0.02, -0.02, 0.05, 0.0, -0.05]), y + np.array([-0.1, 0.1, 0, 0, 0]),
                       np.array([3.0, 3.0, 0.0, 0.0, 0.0]), np.array([-1.0, 3.0, 0.0, 0.0, 0.0])])  # fmt: skip
    b = lj.basins(worm, starts)
    assert list(np.asarray(b.label)) == [0, 0, 0, 0, -1] and list(np.asarray(b.count)) == [4]
    assert int(b.per_start.status[-1]) == lj.GaitStatus.INVALID
    np.testing.assert_allclose(float(b.gaits.mean_speed[0]), float(gait.mean_speed), rtol=1e-9)
    np.testing.assert_allclose(float(b.gaits.cost_of_transport[0]), float(gait.cost_of_transport), rtol=1e-9)
    with pytest.raises(ValueError, match=r"starts must have shape grid \+ \(5,\)"):
        lj.basins(worm, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="section states"):
        lj.steady_gait(chain, start=np.zeros((5, 3)))


# Mechanisms.

MECHANISM_GAIT = pytest.mark.xdist_group("mechanism_gait")  # the capsule's gait is solved once, on one worker


def _wall_oscillator(friction, c, g=0.5, w=2.0):
    """Siconos' oscillator (m = k = 1, a spring to the wall) driven by an external force g sin(w t)."""
    links = [lj.Spring(0, lj.WALL, k=1.0, rest=0.0), lj.ExternalForce(0, lj.Sinusoid(a=g, omega=w, lbar=0.0))]
    return lj.Mechanism(masses=[1.0], friction=[friction], links=links, c=c)


@pytest.fixture(scope="module")
def capsule_gait():
    return lj.steady_gait(capsule())


@MECHANISM_GAIT
def test_capsule_gait_is_a_fixed_point_of_a_direct_simulation(capsule_gait):
    """From the orbit's section state, `simulate` returns to it (relative positions, velocities)
    after one gait period, with the gait's drift of the centre of mass and energies."""
    g = capsule_gait
    assert int(g.status) == lj.GaitStatus.CONVERGED and int(g.k) == 1
    assert g.state.shape == (3,) and g.monodromy.shape == (3, 3)
    u, v = np.asarray(g.state[:1]), np.asarray(g.state[1:])
    x0 = np.array([0.0, u[0]])
    M = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*ANISO), None], carried_by=[None, 0],
                     links=capsule().links, x0=x0, v0=v)  # fmt: skip
    T = float(g.period)
    traj = lj.simulate(M, t_end=T, save_at=jnp.array([0.0, T]))
    assert int(traj.status) == lj.Status.OK
    x, vv = np.asarray(traj.x[-1]), np.asarray(traj.v[-1])
    err = max(abs((x[1] - x[0]) - u[0]), *np.abs(vv - v))
    drift = float(np.dot([1.0, 0.5], x - x0) / 1.5)
    print(f"fixed point: state error {err:.2e}; speed {float(g.mean_speed):.10f} vs simulate {drift / T:.10f}")
    assert err < 1e-9
    assert abs(drift / T - float(g.mean_speed)) < 1e-10
    assert abs(float(traj.e_d[-1]) - float(g.e_d)) < 1e-10 and abs(float(traj.w[-1]) - float(g.work)) < 1e-10
    assert abs(float(g.e_d) - float(g.work)) < 1e-9  # the energy is periodic on the orbit
    assert np.all(np.abs(np.asarray(g.multipliers)) < 1) and bool(g.stable)
    assert float(g.stick_fraction[1]) == 0.0  # a carried body never sticks
    # The shell bears both weights; the carried body has no normal load (its placeholder 1 is left out).
    assert float(g.min_normal) == 1.5


@MECHANISM_GAIT
def test_capsule_gait_against_the_reference(capsule_gait):
    """The independent reference, from the orbit's section state, closes the orbit over 5 periods with
    the gait's mean speed and dissipation; from rest, its mean speed over periods 150-160 is the gait's
    (the multipliers' largest modulus, 0.92, leaves 4e-6 of the start there)."""
    g = capsule_gait
    T, u, v = float(g.period), float(g.state[0]), np.asarray(g.state[1:], float)
    ref = run(capsule_ref(0.6, 10.0, 3.0, [0.0, u], v), 5 * T, np.array([0.0, 5 * T]))
    speed = (ref["com"][1] - ref["com"][0]) / (5 * T)
    closed = max(abs(ref["x"][1][1] - ref["x"][1][0] - u), *np.abs(ref["v"][1] - v))
    print(f"reference on the orbit: speed {speed:.10f} (gait {float(g.mean_speed):.10f}), e_d/period "
          f"{ref['ed'][1] / 5:.10f} (gait {float(g.e_d):.10f}), closure {closed:.1e}")  # fmt: skip
    assert closed < 1e-7
    assert abs(speed - float(g.mean_speed)) < 1e-8 * max(1.0, abs(speed))
    assert abs(ref["ed"][1] / 5 - float(g.e_d)) < 1e-8
    far = run(capsule_ref(0.6, 10.0, 3.0, [0.0, 0.0], [0.0, 0.0]), 160 * T, np.array([150 * T, 160 * T]))
    long_speed = (far["com"][1] - far["com"][0]) / (10 * T)
    print(f"reference from rest, periods 150-160: speed {long_speed:.10f}")
    assert abs(long_speed - float(g.mean_speed)) < 1e-5 * abs(long_speed)


@MECHANISM_GAIT
def test_harmonically_forced_wall_oscillator_exact():
    """No friction, damping c: the periodic solution is x = A sin(w t - phi), A = g/sqrt((1 - w^2)^2 +
    (c w)^2), tan(phi) = c w/(1 - w^2); the multipliers are exp((-c/2 +- i sqrt(1 - c^2/4)) T); per
    period the dampers dissipate pi c w A^2, which the force puts in. The anchored section state is
    the absolute (x, v)."""
    c, g, w = 0.3, 0.5, 2.0
    G = lj.steady_gait(_wall_oscillator(None, c, g, w))
    A = g / np.hypot(1 - w * w, c * w)
    phi = np.arctan2(c * w, 1 - w * w)
    want = np.array([A * np.sin(-phi), A * w * np.cos(-phi)])
    T = 2 * np.pi / w
    mu = np.exp((-c / 2 + 1j * np.sqrt(1 - c * c / 4)) * T)
    got_mu = np.sort_complex(np.asarray(G.multipliers))
    print("oscillator:", np.asarray(G.state), want, got_mu, mu)
    assert int(G.status) == lj.GaitStatus.CONVERGED and G.state.shape == (2,)
    assert np.abs(np.asarray(G.state) - want).max() < 1e-10
    assert np.abs(got_mu - np.sort_complex(np.array([mu, np.conj(mu)]))).max() < 1e-9
    assert abs(float(G.e_d) - np.pi * c * w * A * A) < 1e-10 and abs(float(G.work) - float(G.e_d)) < 1e-9
    assert abs(float(G.mean_speed)) < 1e-12


@MECHANISM_GAIT
def test_an_anchored_gait_with_a_body_stuck_all_period():
    """Two bodies, the second tied to the wall and pushed by a harmonic force, the first (heavier, on
    more friction) stuck the whole period: a family of periodic orbits, the first body held anywhere
    within its stick range (a multiplier 1). From a short transient Newton's method takes a step and
    reaches a member (it divided by the zero singular value: NaN, `NOT_CONVERGED`): a fixed point of a
    direct simulation to 1e-9, with the stuck body's stick fraction 1, slip margin `-inf`, the largest
    multiplier's modulus 1 to 1e-9, not stable."""
    laws = [lj.Coulomb(0.6, 0.4), lj.Coulomb(0.1, 0.05)]
    links = [lj.Spring(0, 1, k=6.0, rest=1.0), lj.Spring(lj.WALL, 1, k=0.2, rest=3.5),
             lj.ExternalForce(1, lj.Sinusoid(0.3, 2.0, 0.0))]  # fmt: skip
    M = lj.Mechanism(masses=[1.8, 0.6], friction=laws, links=links, x0=[1.2, 2.3])
    g = steady_gait(M, periods=(1,), transient=40, dynamics=lj.Exact(dt=0.01))
    assert int(g.status) == GaitStatus.CONVERGED and int(g.n_iter) >= 1, (int(g.status), int(g.n_iter))
    y, T = np.asarray(g.state), float(g.period)
    assert y.shape == (4,) and y[2] == 0.0  # absolute positions (tied to the wall), then velocities
    M0 = lj.Mechanism(masses=[1.8, 0.6], friction=laws, links=links, x0=y[:2], v0=y[2:])
    tr = lj.simulate(M0, T, jnp.array([0.0, T]), dynamics=lj.Exact(dt=0.01))
    err = max(np.abs(np.asarray(tr.x[-1]) - y[:2]).max(), np.abs(np.asarray(tr.v[-1]) - y[2:]).max())
    print("stuck-body family: fixed point to", err, "multipliers", np.asarray(g.multipliers))
    assert int(tr.status) == lj.Status.OK and err < 1e-9
    assert float(g.stick_fraction[0]) == 1.0 and float(g.slip_margin) == -np.inf
    assert abs(float(np.abs(np.asarray(g.multipliers)).max()) - 1) < 1e-9 and not bool(g.stable)


@MECHANISM_GAIT
def test_siconos_oscillator_with_a_harmonic_wall_force_against_the_reference():
    """With Coulomb friction (bound 0.4) the oscillator driven by 0.6 sin(0.5 t) sticks and slips; the
    reference, from the gait's section state, returns to it after a period with the gait's dissipation;
    it does not travel (speed 0, cost of transport inf)."""
    G = lj.steady_gait(_wall_oscillator(lj.Coulomb(0.4, 0.4), 0.0, 0.6, 0.5))
    assert int(G.status) == lj.GaitStatus.CONVERGED
    x, v = float(G.state[0]), float(G.state[1])
    T = float(G.period)
    S = System([Body(1.0, (0.4, 0.4, 0.4, 0.4), x0=x, v0=v)], springs=[(0, -1, 1.0, 0.0)],
               externals=[(0, Sig(0.0, (0.0,), (0.6,), 0.5))])  # fmt: skip
    ref = run(S, T, np.array([0.0, T]))
    err = max(abs(ref["x"][1][0] - x), abs(ref["v"][1][0] - v))
    print(f"friction oscillator: state {x:.10f}, {v:.10f}; reference closure {err:.1e}; e_d {float(G.e_d):.10f} "
          f"(ref {ref['ed'][1]:.10f}); stuck {float(G.stick_fraction[0]):.4f}")  # fmt: skip
    assert err < 1e-8 and abs(ref["ed"][1] - float(G.e_d)) < 1e-8
    assert float(G.stick_fraction[0]) > 0  # it sticks at its turning points
    # Tied to the wall it dissipates but does not travel: no distance (what the integration gives
    # over the period is Newton's residual), an infinite cost of transport.
    assert float(G.e_d) > 0.1 and float(G.mean_speed) == 0.0 and float(G.cost_of_transport) == np.inf


@MECHANISM_GAIT
def test_mechanism_gait_batch_flags_the_invalid_configuration_alone(capsule_gait):
    """A batch over the force amplitude with one negative spring stiffness (check=False): that one is
    INVALID with NaN numbers, the others equal the single solves."""
    k = jnp.array([10.0, -1.0, 10.0])
    a = jnp.array([0.6, 0.6, 0.9])
    G = lj.steady_gait(capsule(a=a, k=k, check=False))
    status = np.asarray(G.status)
    assert list(status) == [lj.GaitStatus.CONVERGED, lj.GaitStatus.INVALID, lj.GaitStatus.CONVERGED]
    assert np.isnan(float(G.mean_speed[1]))
    assert abs(float(G.mean_speed[0]) - float(capsule_gait.mean_speed)) < 1e-12
    single = lj.steady_gait(capsule(a=0.9))
    assert abs(float(G.mean_speed[2]) - float(single.mean_speed)) < 1e-12


@MECHANISM_GAIT
def test_mechanism_gait_float32(capsule_gait):
    G = lj.steady_gait(capsule(), dtype=jnp.float32)
    assert G.mean_speed.dtype == jnp.float32 and int(G.status) == lj.GaitStatus.CONVERGED
    assert abs(float(G.mean_speed) - float(capsule_gait.mean_speed)) < 1e-4


@MECHANISM_GAIT
def test_mechanism_gait_start_and_bad_input():
    M = capsule()
    g = lj.steady_gait(M, start=np.array([0.0, 0.0, 0.0]), periods=1)
    assert int(g.status) == lj.GaitStatus.CONVERGED
    with pytest.raises(ValueError, match=r"gaps u_0..u_N-2.*shape \(3,\)"):
        lj.steady_gait(M, start=np.zeros(4))
    with pytest.raises(ValueError, match=r"positions x_0..x_N-1.*shape \(2,\)"):
        lj.steady_gait(_wall_oscillator(None, 0.3), start=np.zeros(3))
    with pytest.raises(ValueError, match="waveform= applies to Params; a Mechanism"):
        lj.steady_gait(M, waveform=lj.Sinusoid(a=1.0, omega=1.0, lbar=0.0))
    still = lj.Mechanism(masses=[1.0], friction=[None], links=[lj.Spring(0, lj.WALL, k=1.0)], c=0.3)
    assert int(lj.steady_gait(still).status) == lj.GaitStatus.INVALID  # no forcing period
