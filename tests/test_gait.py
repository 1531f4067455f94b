"""Steady gaits (periodic orbits) of the paper's model: against long direct simulations averaged over
whole periods, the monodromy matrix against finite differences of the independent reference, the
statuses (`GaitStatus`, an `enum.IntEnum` like `Status`), and gaits with flight phases
(`contact="hop"`, SPEC §10: the period map through lift-offs, flights and landings)."""

import dataclasses
import enum
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax import GaitStatus, steady_gait
from locomotion_jax.gaits import _select
from reference import reference_simulate


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


def test_compact_batch_for_the_longer_periods(monkeypatch):
    """With `compact=True` (the exact optimiser's sinusoid sweep) a gait period tried on fewer
    than a quarter of the batch runs on a quarter-size batch: the same gaits as the full batch,
    the period-2 gait past a period doubling included, and every other row as before."""
    from locomotion_jax.gaits import _corrector, _gait

    p = _batch(CASES[:9] + BAD + [UNSTABLE])
    full = _gait.paper_gait(p, dynamics=lj.Exact())
    sizes: list[int] = []
    solve = _corrector.correct_batch
    monkeypatch.setattr(_corrector, "correct_batch", lambda *a: sizes.append(int(a[8].shape[0])) or solve(*a))
    small = _gait.paper_gait(p, dynamics=lj.Exact(), compact=True)
    assert sizes[0] == 12 and set(sizes[1:]) == {3}, sizes  # period 1 on the batch, the others on 3 rows
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
    """One converged gait and one invalid configuration (nothing integrated) in a batch."""
    params = lj.Params(omega=np.array([2.0, 2.0]), mu_s=np.array([0.5, 0.3]), check=False)
    g = lj.steady_gait(params, periods=1)
    names = [lj.GaitStatus(int(s)).name for s in np.asarray(g.status)]
    assert names == ["CONVERGED", "INVALID"]
    assert lj.GaitStatus(int(g.status[0])) == lj.GaitStatus.CONVERGED == 0


def test_hopping_gait_is_the_limit_of_a_long_simulation():
    """The paper's model at omega = 15 and 20, a = 0.1 (`Params`, one batch): both gaits are stable
    1-periodic orbits with flight phases (the long run lands about twice per period); a simulation
    from the paper's start reaches the orbit's section state (gap, velocities, heights, vertical
    velocities) within 1e-7 after 300 periods (measured 6e-9 and 9e-9) and its drift over one period
    gives the gait's mean speed; the multipliers lie inside the unit circle (a grounded body's
    vertical components give zeros)."""
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
        assert diff < 1e-7 and abs(speed - float(g.mean_speed[i])) < 1e-7
    assert float(np.asarray(g.state)[0, 3]) > 0  # at omega = 15 a body is in flight at the section
