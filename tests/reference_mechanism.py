"""Independent float64 reference for mechanisms on a line (SPEC §9): bodies with or without ground
contact, carried bodies, linear springs and linear dampers between any bodies or to a wall (at
x = 0), internal forces and external forces.

Written only from SPEC.md §9 (and §8 for stick and slip); it imports nothing from the
``locomotion_jax`` package nor from the other references, only numpy and scipy.

Model (0-based bodies): a spring ``(a, b, k, r)`` exerts ``f = k (x_b - x_a - r)``, ``+f`` on ``a``
and ``-f`` on ``b`` (``x = 0`` for the wall ``-1``); an internal force ``(a, b, s)`` exerts ``+s(t)`` on
``b`` and ``-s(t)`` on ``a``; an external force ``(i, s)`` exerts ``s(t)`` on ``i``; a damper ``(a, b, c)``
exerts ``f = c (v_b - v_a)``, ``+f`` on ``a`` and ``-f`` on ``b`` (``v = 0`` for the wall), and dissipates
``c (v_b - v_a)^2``. A signal is
``s(t) = mean + sum_n A_n cos(n w t) + B_n sin(n w t)``, or a periodic uniform cubic B-spline in the
phase, ``s(t) = mean + sum_j c_j beta(M w t / (2 pi) - j)`` over the ``M`` control values ``c_j`` repeated
with period ``M``, with the centred cubic B-spline ``beta(u) = 2/3 - u^2 + |u|^3/2`` for ``|u| < 1``,
``(2 - |u|)^3/6`` for ``1 <= |u| < 2`` and 0 beyond. A body in contact has the normal load
``N_i = m_i + sum of the masses it carries`` (constant: the springs are horizontal) and anisotropic
Coulomb friction; a body without contact feels no friction. Ground damping ``c_i v_i``.

Method: event-driven, one ``solve_ivp(DOP853)`` per segment of constant mode (the set of stuck
contact bodies and each slipping body's direction), terminal events at a stuck body's static
limits and a slipping body's zero velocity; after every event every contact body is re-decided
from the state. The state carries the dissipated energy ``e_d`` and the work ``w``.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp


def _beta(u: float) -> tuple[float, float]:
    """The centred cubic B-spline and its derivative at ``u``."""
    a = abs(u)
    if a < 1:
        return 2 / 3 - a * a + a**3 / 2, float(np.sign(u)) * (-2 * a + 1.5 * a * a)
    if a < 2:
        return (2 - a) ** 3 / 6, -float(np.sign(u)) * (2 - a) ** 2 / 2
    return 0.0, 0.0


@dataclass
class Sig:
    """``mean + sum_n A[n] cos((n+1) w t) + B[n] sin((n+1) w t)``, or with ``control`` (M >= 4
    values) ``mean + sum_j control[j] beta(M w t / (2 pi) - j)``, periodic in ``j`` (module docstring)."""

    mean: float = 0.0
    A: tuple = ()
    B: tuple = ()
    w: float = 0.0
    control: tuple = ()

    def at(self, t: float) -> tuple[float, float]:
        """Value and time derivative."""
        if self.control:
            M = len(self.control)
            s = (M * self.w * t / (2 * np.pi)) % M
            val, rate = self.mean, 0.0
            for j, c in enumerate(self.control):
                d = (s - j + M / 2) % M - M / 2  # the nearest periodic copy of knot j
                b, db = _beta(d)
                val += c * b
                rate += c * db * M * self.w / (2 * np.pi)
            return val, rate
        val, rate = self.mean, 0.0
        for n, (a, b) in enumerate(zip(self.A, self.B), start=1):
            p = n * self.w * t
            val += a * np.cos(p) + b * np.sin(p)
            rate += n * self.w * (b * np.cos(p) - a * np.sin(p))
        return val, rate


@dataclass
class Body:
    m: float
    law: tuple | None = None  # (mu_s_fwd, mu_s_bwd, mu_k_fwd, mu_k_bwd) or None: no contact
    carrier: int | None = None
    c: float = 0.0
    x0: float = 0.0
    v0: float = 0.0


@dataclass
class System:
    bodies: list
    springs: list = field(default_factory=list)  # (a, b, k, rest: float or Sig); -1 is the wall
    forces: list = field(default_factory=list)  # (a, b, Sig)
    externals: list = field(default_factory=list)  # (i, Sig)
    dampers: list = field(default_factory=list)  # (a, b, c); -1 is the wall

    def normal(self) -> np.ndarray:
        N = np.array([b.m if b.law is not None else 0.0 for b in self.bodies])
        for i, b in enumerate(self.bodies):
            j = b.carrier
            while j is not None and self.bodies[j].law is None:
                j = self.bodies[j].carrier
            if b.carrier is not None and j is not None:
                N[j] += b.m
        return N

    def loads(self, t: float, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float, float]:
        """Forces F_i, the elastic energy and the power put in by the actuators and forces."""
        F = np.zeros(len(self.bodies))
        pos = lambda i: 0.0 if i < 0 else x[i]
        vel = lambda i: 0.0 if i < 0 else v[i]
        elastic = power = 0.0
        for a, b, k, rest in self.springs:
            r, dr = rest.at(t) if isinstance(rest, Sig) else (rest, 0.0)
            f = k * (pos(b) - pos(a) - r)
            if a >= 0:
                F[a] += f
            if b >= 0:
                F[b] -= f
            elastic += f * f / (2 * k)
            power += -f * dr
        for a, b, s in self.forces:
            f = s.at(t)[0]
            if b >= 0:
                F[b] += f
            if a >= 0:
                F[a] -= f
            power += f * (vel(b) - vel(a))
        for i, s in self.externals:
            g = s.at(t)[0]
            F[i] += g
            power += g * v[i]
        for a, b, c in self.dampers:
            f = c * (vel(b) - vel(a))
            if a >= 0:
                F[a] += f
            if b >= 0:
                F[b] -= f
        return F, elastic, power

    def damping(self, v: np.ndarray) -> float:
        """The power the dampers dissipate."""
        vel = lambda i: 0.0 if i < 0 else v[i]
        return sum(c * (vel(b) - vel(a)) ** 2 for a, b, c in self.dampers)


def run(sys: System, t_end: float, save: np.ndarray, rtol: float = 1e-12, atol: float = 1e-13) -> dict:
    """Positions, velocities, e_d, w and energy at the times `save` (increasing, in [0, t_end])."""
    n = len(sys.bodies)
    m = np.array([b.m for b in sys.bodies])
    c = np.array([b.c for b in sys.bodies])
    N = sys.normal()
    contact = [b.law is not None for b in sys.bodies]
    law = [b.law if b.law is not None else (0.0, 0.0, 0.0, 0.0) for b in sys.bodies]
    y = np.concatenate([[b.x0 for b in sys.bodies], [b.v0 for b in sys.bodies], [0.0, 0.0]])

    def decide(t, y, stuck, sdir, fired):
        """Re-decide every contact body after an event; `fired`: `(body, direction)` of the event that
        ended the segment (direction +-1: the static limit it crossed; 0: its velocity reached zero)."""
        F = sys.loads(t, y[:n], y[n : 2 * n])[0]
        for i in range(n):
            if not contact[i]:
                continue
            tol = 1e-10 * max(1.0, abs(F[i]))
            holds = -law[i][1] * N[i] - tol <= F[i] <= law[i][0] * N[i] + tol
            if stuck[i] and i == fired[0]:  # beyond the limit that fired: slip that way
                stuck[i], sdir[i] = False, fired[1]
            elif stuck[i] and not holds:
                stuck[i], sdir[i] = False, 1.0 if F[i] > 0 else -1.0
            elif not stuck[i] and i == fired[0]:
                y[n + i] = 0.0
                if holds:
                    stuck[i] = True
                else:
                    sdir[i] = 1.0 if F[i] > 0 else -1.0
        return stuck, sdir

    stuck = [contact[i] and sys.bodies[i].v0 == 0 for i in range(n)]
    sdir = [1.0 if b.v0 > 0 else -1.0 if b.v0 < 0 else 1.0 for b in sys.bodies]
    F0 = sys.loads(0.0, y[:n], y[n : 2 * n])[0]
    for i in range(n):
        if sys.bodies[i].v0 == 0:
            sdir[i] = 1.0 if F0[i] >= 0 else -1.0
            if stuck[i] and not (-law[i][1] * N[i] <= F0[i] <= law[i][0] * N[i]):
                stuck[i] = False

    def rhs(t, y, stuck, sdir):
        x, v = y[:n], y[n : 2 * n]
        F, _, power = sys.loads(t, x, v)
        a = np.zeros(n)
        ed = 0.0
        for i in range(n):
            if contact[i] and stuck[i]:
                continue
            mu = 0.0 if not contact[i] else (law[i][2] if sdir[i] > 0 else law[i][3])
            a[i] = (F[i] - c[i] * v[i] - sdir[i] * mu * N[i]) / m[i]
            ed += mu * N[i] * abs(v[i]) + c[i] * v[i] ** 2
        xd = np.where([contact[i] and stuck[i] for i in range(n)], 0.0, v)
        return np.concatenate([xd, a, [ed + sys.damping(v), power]])

    def events(stuck, sdir):
        out, owner = [], []
        for i in range(n):
            if not contact[i]:
                continue
            if stuck[i]:
                out.append(lambda t, y, *_, i=i: law[i][0] * N[i] - sys.loads(t, y[:n], y[n : 2 * n])[0][i])
                out.append(lambda t, y, *_, i=i: sys.loads(t, y[:n], y[n : 2 * n])[0][i] + law[i][1] * N[i])
                owner += [(i, 1.0), (i, -1.0)]
            else:
                out.append(lambda t, y, *_, i=i: sdir[i] * y[n + i])
                owner.append((i, 0.0))
        for e in out:
            e.terminal, e.direction = True, -1
        return out, owner

    t = 0.0
    rows, k = [], 0
    segments = 0
    while t < t_end and segments < 200_000:
        segments += 1
        st, sd = list(stuck), list(sdir)
        ev, owner = events(st, sd)
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", args=(st, sd), events=ev, rtol=rtol, atol=atol,
                        dense_output=True, max_step=0.05)  # fmt: skip
        t_next = sol.t[-1]
        while k < len(save) and save[k] <= t_next:
            rows.append((save[k], sol.sol(save[k])))
            k += 1
        y, t = sol.y[:, -1].copy(), t_next
        if sol.status == 1:
            fired = owner[next(j for j, te in enumerate(sol.t_events) if len(te))]
            stuck, sdir = decide(t, y, st, sd, fired)
    out = np.array([r for _, r in rows])
    energy = np.array([0.5 * np.sum(m * r[n : 2 * n] ** 2) + sys.loads(s, r[:n], r[n : 2 * n])[1] for s, r in rows])
    return dict(t=np.array([s for s, _ in rows]), x=out[:, :n], v=out[:, n : 2 * n], ed=out[:, -2], w=out[:, -1],
                e=energy, com=out[:, :n] @ m / m.sum())  # fmt: skip
