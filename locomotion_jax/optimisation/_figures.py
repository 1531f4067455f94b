"""The exact optimisers' objective and constraints at one evaluated gait, with their gradients.

Shared by the paper's optimiser (`_exact`) and the chain's and the mechanism's (`_chain`,
`_mechanism`, whose local refinement is `_element_local`): each evaluates an
[`Orbit`][locomotion_jax.gaits._orbit.Orbit] (figures $(\\Delta X, e_d, \\min N)$ over the gait's
$k$ periods and their exact gradients with respect to the decision vector, whose last entry is
$\\log\\omega$) and hands these figures to a local solver.
"""

import math

import numpy as np


PENALTY = 10.0
"""Weight of the squared relative speed deficit in the objective, and of the violations in the
merit (costs of transport are O(1))."""


class Figures:
    """Objective, constraints and their gradients at one evaluated point.

    $f = e_d / \\max_\\text{soft}(\\sigma\\Delta X, \\Delta_\\text{need}/4) + \\rho\\,\\delta^2$ with the
    relative speed deficit $\\delta$; constraints
    $c = (\\sigma\\Delta X/\\Delta_\\text{need} - 1, \\min N - \\text{margin}) \\ge 0$, where
    $\\sigma$ is the direction of travel and $\\Delta_\\text{need}$ the distance the required speed
    covers in the gait's period. Without `free_omega` the gradients' $\\log\\omega$ entries are zero.
    """

    def __init__(self, theta, orb, need_rate: float, k: int, direction: int, margin: float, free_omega: bool):
        dX, ed, low = (float(x) for x in orb.figures)
        g_dX, g_ed, g_low = (np.asarray(g, float) for g in orb.gradient)
        T = k * 2 * np.pi / math.exp(theta[-1])  # the gait's period: k actuation periods
        need = need_rate * T  # required distance per period; d need / d log omega = -need
        d_need = np.zeros_like(theta)
        d_need[-1] = -need
        dist, g_dist = direction * dX, direction * g_dX
        # Cost of transport e_d / dist, the distance floored smoothly at a quarter of the
        # required one, so that an iterate that stands still has a finite cost.
        floor, width = 0.25 * need, 0.05 * need
        z = (dist - floor) / width
        den = floor + width * np.logaddexp(0, z)
        sig = 0.5 * (1 + np.tanh(0.5 * z))
        d_den = 0.25 * d_need + 0.05 * d_need * np.logaddexp(0, z) + sig * (g_dist - 0.25 * d_need - z * 0.05 * d_need)
        self.f = ed / den
        self.df = g_ed / den - ed / den**2 * d_den
        self.cot = ed / dist if dist > 0 else math.inf  # the true cost of transport
        self.c = np.array([dist / need - 1, low - margin])
        self.dc = np.stack([g_dist / need - dist / need**2 * d_need, g_low])
        # A quadratic penalty on the speed deficit, zero where the speed constraint holds:
        # without it a waveform that stands still (e_d -> 0) would look cheap, and a local
        # solver far from feasibility would walk there.
        deficit = max(0.0, -self.c[0])
        self.f = self.f + PENALTY * deficit**2
        self.df = self.df - 2 * PENALTY * deficit * self.dc[0]
        if not free_omega:
            self.df[-1] = 0.0
            self.dc[:, -1] = 0.0
        self.ok = bool(orb.ok)
