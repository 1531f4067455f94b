"""The exact optimisers' local steps (`optimisation._descent`) on problems with known optima, and one local
run's bookkeeping around them (`optimisation._local`).

The optimisers' problems have the cost falling where the speed constraint would be broken, so
that the optimum lies on it; these analytic problems have the same shape and closed-form optima.
"""

import math
import zlib
from types import SimpleNamespace

import numpy as np
import pytest
from locomotion_jax.optimisation import _descent
from locomotion_jax.optimisation._descent import descent, direction, sqp_descent
from locomotion_jax.optimisation._local import local_run


def _tangent_problem():
    """min x0 + 0.1 (x1 - 1)^2 s.t. x0 - x1^2 >= 0 (and an inactive second constraint).

    The optimum lies on the curved constraint, x1 = 1/11, x0 = x1^2, multiplier 1."""

    def at(x):
        return SimpleNamespace(
            f=x[0] + 0.1 * (x[1] - 1) ** 2,
            df=np.array([1.0, 0.2 * (x[1] - 1)]),
            c=np.array([x[0] - x[1] ** 2, 5.0]),
            dc=np.array([[1.0, -2 * x[1]], [0.0, 0.0]]),
            ok=True,
        )

    x1 = 1 / 11
    return at, np.array([x1**2, x1]), x1**2 + 0.1 * (x1 - 1) ** 2


def _run(at, x0, strict, max_iter=600, proj=lambda x: x, method=sqp_descent, **options):
    points = []

    def ask(x):
        fig = at(x)
        points.append((x.copy(), fig))
        return fig

    method(x0, ask, proj, max_iter, trust_radius=0.1, rho=10.0, strict=strict, **options)
    held = [(fig.f, x) for x, fig in points if fig.ok and min(fig.c) >= 0]
    return points, min(held, key=lambda t: t[0]) if held else None


@pytest.mark.parametrize("strict", [False, True])
def test_descent_follows_an_active_curved_constraint_to_its_optimum(strict):
    at, x_star, f_star = _tangent_problem()
    points, best = _run(at, np.array([2.0, 2.0]), strict)
    assert best is not None, "no evaluated point meets the constraint"
    f, x = best
    # The iterates aim `INSIDE` = 1e-9 into the constraint: the optimum to that order.
    assert abs(f - f_star) <= 1e-7 * f_star, (f, f_star)
    np.testing.assert_allclose(x, x_star, atol=1e-6)
    # It stops by itself (stationary), in few evaluations.
    assert len(points) < 100, len(points)


def test_penalty_descent_zigzags_across_the_active_constraint():
    """`descent` (the L-BFGS descent on the merit itself) on the same problem: its steps cross
    the constraint's kink and backtrack, and it stops short of the optimum that `sqp_descent`
    reaches in a tenth of the evaluations."""
    at, _, f_star = _tangent_problem()
    points, best = _run(at, np.array([2.0, 2.0]), strict=True, method=descent)
    sqp_points, _ = _run(at, np.array([2.0, 2.0]), strict=True)
    assert best is not None
    assert best[0] > f_star * (1 + 1e-3)
    assert len(points) > 2 * len(sqp_points)


def test_descent_stops_where_the_merit_stalls():
    """With `stall_rtol`, `descent` stops within one iteration (at most 13 evaluations: a step
    and its 12 trials) of the first evaluation after which its merit fell by at most `stall_rtol`
    over the last `STALL_WINDOW` evaluations, and not before; without it, it goes on."""
    rtol = 1e-6
    at, _, _ = _tangent_problem()
    # A slow creep: the cost's slope along the constraint is small against its value.
    creep = lambda x: SimpleNamespace(**{**vars(at(x)), "f": 1e3 + at(x).f})
    points, _ = _run(creep, np.array([2.0, 2.0]), strict=True, method=descent, stall_rtol=rtol)
    longer, _ = _run(creep, np.array([2.0, 2.0]), strict=True, method=descent)
    phi = [fig.f + 10.0 * np.sum(np.maximum(0.0, -fig.c)) for _, fig in points]
    best = np.minimum.accumulate(phi)
    w = _descent.STALL_WINDOW
    stalled = [e for e in range(w, len(best)) if best[e - w] - best[e] <= rtol * abs(best[e])]
    assert stalled, "the merit never stalled: no test of the stop"
    assert stalled[0] + 1 <= len(points) <= stalled[0] + 1 + 13, (len(points), stalled[0])
    assert len(longer) > len(points) + 13
    assert all(np.array_equal(x, y) for (x, _), (y, _) in zip(points, longer))  # the same path until the stop


def test_descent_far_from_feasible_stops_at_the_looser_stall(monkeypatch):
    """From accepted points `FAR` from feasible, `descent`'s stall tolerance is at least
    `FAR_STALL_RTOL`: a run that creeps while it misses its constraint by 5 % stops within one
    iteration of the first evaluation after which its merit fell by at most that over
    `STALL_WINDOW` evaluations, where the caller's 1e-6 alone lets it run to its last iteration."""

    def at(x):
        # The violation shrinks by 1e-6 per unit of x0: the merit falls by ~1e-5 relative over
        # 20 steps of the trust radius, between the two tolerances.
        return SimpleNamespace(
            f=1.0 + 0.1 * (x[1] - 1) ** 2,
            df=np.array([0.0, 0.2 * (x[1] - 1)]),
            c=np.array([-0.05 + 1e-6 * x[0], 5.0]),
            dc=np.array([[1e-6, 0.0], [0.0, 0.0]]),
            ok=True,
        )

    points, _ = _run(at, np.array([0.0, 2.0]), strict=True, max_iter=300, method=descent, stall_rtol=1e-6)
    phi = [fig.f + 10.0 * np.sum(np.maximum(0.0, -fig.c)) for _, fig in points]
    best = np.minimum.accumulate(phi)
    w, rtol = _descent.STALL_WINDOW, _descent.FAR_STALL_RTOL
    assert all(max(-fig.c) > _descent.FAR for _, fig in points)
    stalled = [e for e in range(w, len(best)) if best[e - w] - best[e] <= rtol * abs(best[e])]
    assert stalled and all(best[e - w] - best[e] > 1e-6 * abs(best[e]) for e in range(w, len(best)))
    assert stalled[0] + 1 <= len(points) <= stalled[0] + 1 + 13, (len(points), stalled[0])
    monkeypatch.setattr(_descent, "FAR_STALL_RTOL", 0.0)
    longer, _ = _run(at, np.array([0.0, 2.0]), strict=True, max_iter=300, method=descent, stall_rtol=1e-6)
    assert len(longer) >= 300 > len(points) + 13


def test_descent_steps_around_failed_orbits_and_never_takes_their_figures():
    at, x_star, f_star = _tangent_problem()

    def flaky(x):
        fig = at(x)
        # One point in four (by a hash of its coordinates) has no orbit, and figures that would
        # look far cheaper than any true point if they were taken.
        if x.tobytes() != np.array([2.0, 2.0]).tobytes() and zlib.crc32(x.tobytes()) % 4 == 0:
            fig.ok, fig.f, fig.c = False, -1e9, np.array([1.0, 1.0])
        return fig

    points, best = _run(flaky, np.array([2.0, 2.0]), strict=True)
    assert any(not fig.ok for _, fig in points), "no failed orbit was met: the test tests nothing"
    assert best is not None
    f, x = best
    assert abs(f - f_star) <= 1e-6 * f_star, (f, f_star)
    np.testing.assert_allclose(x, x_star, atol=1e-5)


def test_descent_keeps_the_projection():
    at, _, _ = _tangent_problem()
    box = lambda x: np.clip(x, [-10.0, 0.3], [10.0, 10.0])  # the optimum's x1 = 1/11 is cut off
    points, best = _run(at, np.array([2.0, 2.0]), strict=True, proj=box)
    assert all(x[1] >= 0.3 for x, _ in points)
    assert best is not None
    f, x = best
    # The optimum on the box: x1 = 0.3, x0 = 0.09.
    assert abs(x[1] - 0.3) <= 1e-9 and abs(x[0] - 0.09) <= 1e-6
    assert abs(f - (0.09 + 0.1 * 0.49)) <= 1e-6


def test_direction_solves_the_linearised_problem():
    """One step without curvature pairs: the projection of -g onto the active constraint's
    tangent, restoring its linearisation; an inactive constraint gets no multiplier."""
    g = np.array([1.0, 0.5, 0.0])
    a = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    c = np.array([0.2, 3.0])
    d, lam = direction(g, c, a, lambda v: v)
    assert lam[1] == 0.0 and lam[0] > 0
    assert math.isclose(c[0] + a[0] @ d, 0.0, abs_tol=1e-12)
    # Stationarity of the QP: g + H^-1 d = lam_0 a_0.
    np.testing.assert_allclose(g + d, lam[0] * a[0], atol=1e-12)
    # Free step where no constraint binds.
    d, lam = direction(g, np.array([10.0, 3.0]), a, lambda v: v)
    np.testing.assert_allclose(d, -g)
    assert not lam.any()
    # Two constraints where the free step breaks both, one of which the other's restoration
    # already satisfies: it leaves the active set (its multiplier would be negative).
    a2 = np.array([[1.0, 0.0, 0.0], [1.0, -1.0, 0.0]])
    d, lam = direction(g, np.array([0.5, 0.2]), a2, lambda v: v)
    np.testing.assert_allclose(d, [-0.5, -0.5, 0.0], atol=1e-12)
    assert math.isclose(lam[0], 0.5) and lam[1] == 0.0


# -- one local run's bookkeeping (`optimisation._local.local_run`) ----------------------------------


def _figure(cot, c_speed, ok=True):
    return SimpleNamespace(f=cot, cot=cot, c=np.array([c_speed, 1.0]), ok=ok)


def test_local_run_reports_its_cheapest_feasible_point_and_runners_up():
    # A search that wanders: its points (x = its index) with the figures below, asked twice each.
    # Feasible points 0, 2, 3, 5 (costs 5, 3, 4, 2); point 1 too slow; point 4 without an orbit;
    # point 6 cheaper still but outside the stroke; point 7 no orbit at all (`None`).
    figs = [_figure(5.0, 0.1), _figure(1.0, -0.2), _figure(3.0, 0.0), _figure(4.0, 0.3),
            _figure(math.inf, -1.0, ok=False), _figure(2.0, 0.2), _figure(0.5, 0.1), None]  # fmt: skip
    asked = []

    def ask(x):
        asked.append(int(x[0]))
        return figs[int(x[0])]

    def search(at, x0):
        assert x0[0] == 0.0
        for i in range(len(figs)):
            at(np.array([float(i)]))
            at(np.array([float(i)]))  # the same point again: answered from the cache
        return {"message": "wandered"}

    log: list = []
    run = local_run(np.zeros(1), search, lambda x: x[0] != 6, log, runners_up=True)
    best, runners = run(ask)
    assert asked == list(range(len(figs)))
    assert best[0] == 5.0
    # The feasible points in order are 0, 2, 3, 5: the fractions 0, 1/4, 1/2, 3/4 pick 0, 2, 3, 5; 5 is the best.
    assert [(c, x[0]) for c, x in runners] == [(5.0, 0.0), (3.0, 2.0), (4.0, 3.0)]
    assert log[0]["message"] == "wandered" and log[0]["evaluations"] == 7  # `None` is not traced
    assert [t["ok"] for t in log[0]["trace"]] == [True] * 4 + [False] + [True] * 2
    assert local_run(np.zeros(1), search, lambda x: x[0] != 6, [])(ask)[0] == 5.0  # without runners-up


def test_local_run_without_a_feasible_point_reports_the_smallest_violation():
    figs = [_figure(1.0, -0.5), _figure(2.0, -0.1), _figure(0.5, -0.3)]

    def search(at, x0):
        for i in range(len(figs)):
            at(np.array([float(i)]))
        return {}

    best, runners = local_run(np.zeros(1), search, lambda x: True, [], runners_up=True)(lambda x: figs[int(x[0])])
    assert best[0] == 1.0 and runners == []
