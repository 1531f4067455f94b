"""The state Jacobian across one stick/slip event against the saltation matrix.

Forward mode through the exact engine gives the Jacobian of the state at a time
after an event with respect to the state at $t = 0$. For a hybrid system
$\\dot y = f_\\pm(y, t)$ that switches where $g(y, t) = 0$ (here non-autonomous: the
rest length $\\ell_0(t)$ drives it), that Jacobian is

$$\\Phi_+(T, t_e)\\, S\\, \\Phi_-(t_e, 0), \\qquad
S = I + \\frac{(f_+ - f_-)\\, \\nabla_y g^\\top}{\\nabla_y g \\cdot f_- + \\partial_t g}$$

at the event $(t_e, y(t_e))$, with $\\Phi_\\pm$ the Jacobians of the flows of the two
modes (the saltation matrix $S$ carries the jump of the vector field through the
moving event time). Everything on the right is computed here from the independent
reference's forces (`tests/reference.py`) with scipy: the flows and their Jacobians
(central differences of DOP853 solutions at rtol 1e-12), the event time, and the
gradient of $g$ (central differences).
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from scipy.integrate import solve_ivp


sys.path.insert(0, str(Path(__file__).parent))
from reference import _Model, DEFAULTS  # noqa: E402


PARAMS = {**DEFAULTS, "omega": 2.0}
MODEL = _Model(PARAMS, "strict")
T_END = 0.1  # the reference's next events: at 0.249 and 0.110
RTOL = 1e-5


def _rhs(stuck: tuple[bool, bool], sdir: tuple[float, float]):
    """The vector field of one mode on $(x_1, v_1, x_2, v_2)$, eq. (9) corrected per SPEC §2."""
    m = MODEL

    def f(t, y):
        x1, v1, x2, v2 = y
        v1 = 0.0 if stuck[0] else v1
        v2 = 0.0 if stuck[1] else v2
        fx, N1, N2, *_ = m.forces(t, x1, x2)
        a1 = 0.0 if stuck[0] else (fx - m.c * v1 - m.mu_k * N1 * sdir[0]) / m.m1
        a2 = 0.0 if stuck[1] else (-fx - m.c * v2 - m.mu_k * N2 * sdir[1]) / m.m2
        return np.array([v1, a1, v2, a2])

    return f


def _flow(f, t0, t1, y0):
    return solve_ivp(f, (t0, t1), y0, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]


def _flow_jacobian(f, t0, t1, y0, h=1e-6):
    cols = [(_flow(f, t0, t1, y0 + h * e) - _flow(f, t0, t1, y0 - h * e)) / (2 * h) for e in np.eye(4)]
    return np.stack(cols, 1)


def _gradients(g, t, y, h=1e-6):
    """$(\\nabla_y g, \\partial_t g)$ by central differences."""
    grad = np.array([(g(t, y + h * e) - g(t, y - h * e)) / (2 * h) for e in np.eye(4)])
    return grad, (g(t + h, y) - g(t - h, y)) / (2 * h)


def _stick_limit(i: int):
    """$g = \\mu_s n_i - |F_i|$: a stuck mass breaks away where it crosses zero (eq. 7)."""

    def g(t, y):
        fx, N1, N2, *_ = MODEL.forces(t, y[0], y[2])
        return MODEL.mu_s * (N1, N2)[i] - abs(fx)

    return g


def _velocity(i: int):
    return lambda t, y: y[1 + 2 * i]


# Case: initial state, the modes before and after, the event function, the columns (initial
# coordinates) that the flow depends on smoothly (a stuck mass's velocity is not one).
CASES = {
    # m1 stuck, m2 moving away: the spring stretches until m1 breaks away forward.
    "stick-to-slip": (
        np.array([0.0, 0.0, np.sqrt(9 - 0.25), 0.3]),
        ((True, False), (1.0, 1.0)),
        ((False, False), (1.0, 1.0)),
        _stick_limit(0),
        [0, 2, 3],
    ),
    # m1 sliding forward on a relaxed spring, m2 stuck: m1 stops and sticks.
    "slip-to-stick": (
        np.array([0.0, 0.05, np.sqrt(9 - 0.25), 0.0]),
        ((False, True), (1.0, 1.0)),
        ((True, True), (1.0, 1.0)),
        _velocity(0),
        [0, 1, 2],
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_state_jacobian_is_the_saltation_formula(case):
    y0, before, after, g, cols = CASES[case]
    f_minus, f_plus = _rhs(*before), _rhs(*after)

    # The event on the reference's flow of the first mode.
    event = lambda t, y: g(t, y)
    event.terminal, event.direction = True, -1  # pyright: ignore[reportFunctionMemberAccess]
    sol = solve_ivp(f_minus, (0, T_END), y0, method="DOP853", rtol=1e-12, atol=1e-13, events=event)
    assert sol.t_events[0].size == 1, "the span must hold exactly one event"
    t_e, y_e = float(sol.t_events[0][0]), sol.y_events[0][0]
    assert 0.02 < t_e < T_END - 0.02

    grad, dg_dt = _gradients(g, t_e, y_e)
    jump = f_plus(t_e, y_e) - f_minus(t_e, y_e)
    S = np.eye(4) + np.outer(jump, grad) / (grad @ f_minus(t_e, y_e) + dg_dt)
    y_after = _flow(f_plus, t_e, T_END, y_e)
    expected = _flow_jacobian(f_plus, t_e, T_END, y_e) @ S @ _flow_jacobian(f_minus, 0.0, t_e, y0)
    no_saltation = _flow_jacobian(f_plus, t_e, T_END, y_e) @ _flow_jacobian(f_minus, 0.0, t_e, y0)

    def run(y):
        tr = lj.simulate(lj.Params(omega=2.0), t_end=T_END, save_at=np.array([T_END]), initial=tuple(y),
                         dynamics=lj.Exact(dt=0.005))  # fmt: skip
        state = jnp.stack([tr.x1[0], tr.v1[0], tr.x2[0], tr.v2[0]])
        return state, state

    jac, state = (np.asarray(x) for x in jax.jacfwd(run, has_aux=True)(jnp.asarray(y0)))
    np.testing.assert_allclose(np.asarray(state), y_after, atol=1e-7)
    scale = np.max(np.abs(expected[:, cols]))
    np.testing.assert_allclose(jac[:, cols], expected[:, cols], atol=RTOL * scale)
    # The jump term matters: without it the Jacobian is far off.
    assert np.max(np.abs(no_saltation[:, cols] - expected[:, cols])) > 100 * RTOL * scale
