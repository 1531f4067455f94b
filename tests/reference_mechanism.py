"""Independent float64 reference for mechanisms on a line (SPEC §9): bodies with or without ground
contact, carried bodies, linear and tilted springs and linear dampers between any bodies or to a
wall (at x = 0), internal forces and external forces.

Written only from SPEC.md §9 (§8 for stick and slip and the tilted springs, §10 for hopping); it imports
nothing from the ``locomotion_jax`` package nor from the other references, only numpy and scipy.

Model (0-based bodies): a spring ``(a, b, k, r)`` exerts ``f = k (x_b - x_a - r)``, ``+f`` on ``a``
and ``-f`` on ``b`` (``x = 0`` for the wall ``-1``); an internal force ``(a, b, s)`` exerts ``+s(t)`` on
``b`` and ``-s(t)`` on ``a``; an external force ``(i, s)`` exerts ``s(t)`` on ``i``; a damper ``(a, b, c)``
exerts ``f = c (v_b - v_a)``, ``+f`` on ``a`` and ``-f`` on ``b`` (``v = 0`` for the wall), and dissipates
``c (v_b - v_a)^2``. A signal is
``s(t) = mean + sum_n A_n cos(n w t) + B_n sin(n w t)``, or a periodic uniform cubic B-spline in the
phase, ``s(t) = mean + sum_j c_j beta(M w t / (2 pi) - j)`` over the ``M`` control values ``c_j`` repeated
with period ``M``, with the centred cubic B-spline ``beta(u) = 2/3 - u^2 + |u|^3/2`` for ``|u| < 1``,
``(2 - |u|)^3/6`` for ``1 <= |u| < 2`` and 0 beyond. A tilted spring ``(a, b, k, d, r)`` (SPEC §8) has
``u = x_b - x_a``, ``l = sqrt(u^2 + d^2)``, tension ``T = k (l - r(t))``; it exerts ``+T u / l``
horizontally and ``+T d / l`` vertically (upwards) on ``a``, the opposites on ``b`` (the wall ``-1``
at ``x = 0``, height 0; under hopping ``d + y_b - y_a`` in place of ``d``, below), stores ``T^2 / (2k)``
and takes in the power ``-T dr/dt``. A body ``g`` in
contact has the normal load ``N_g = m_g + sum of the masses it carries - sum of the vertical spring
forces on g and on the bodies it carries`` (constant without tilted springs; vertical forces on free
bodies are ignored) and anisotropic Coulomb friction with ``N_g`` at the current state; a body
without contact feels no friction. Ground damping ``c_i v_i``. Strict reading: the run stops where a
normal load reaches 0 (``status = "liftoff"``, ``t_liftoff``; later samples repeat the state there).

Method: event-driven, one ``solve_ivp(DOP853)`` per segment of constant mode (the set of stuck
contact bodies, each slipping body's direction and, under hopping, the set of flying groups),
terminal events at a stuck body's static limits, a slipping body's zero velocity, a state-dependent
normal load's zero (lift-off) and, under hopping with tilted springs, a flying group's return to the
ground; after every other event every contact body is re-decided from the state. The state carries
the dissipated energy ``e_d`` and the work ``w``.

Hopping (``run(..., hop=True)``, SPEC §10 applied to a mechanism): each body in contact ``g`` is the
ground body of a group (itself and the bodies it carries, directly or through other carried
bodies), of mass ``M_g`` (``m_g`` and the masses it carries), with a height ``y_g >= 0`` and a
vertical velocity ``w_g``. A carried body has its ground body's height and vertical velocity (it
flies and lands with it); a free body and the wall stay at height 0. A tilted spring acts along
``(u, h)``, ``h = d + y_b - y_a`` with those heights: ``l = sqrt(u^2 + h^2)``, ``T = k (l - r(t))``,
``+T u / l`` horizontally and ``+T h / l`` vertically on ``a``, the opposites on ``b``; it stores
``T^2 / (2k)`` (with all heights 0 this is the strict model). The group load ``N_g`` is ``M_g`` less
the vertical spring forces on ``g`` and on the bodies it carries. On the ground (``y_g = w_g = 0``)
the body sticks and slips with ``N_g`` as above; where ``N_g`` falls through 0 the group lifts off
(the strict reading stops there instead). A body in contact also starts in flight where its
``y0 > 0`` or ``w0 > 0``, or where ``N_g <= 0`` at the start. In flight the group feels no friction,
``M_g w_g' = -N_g`` (the weight less the springs' lift), ``y_g' = w_g``: without tilted springs a
free fall, ``y = y_f + w_f s - s^2/2`` (``s`` the time since the flight began, the landing time in
closed form), with tilted springs integrated in the state with ``x`` and ``v``, the landing an event
(``y_g + max(w_g, 0)`` falling through 0: the ascent is masked, so a flight that starts at ``y = 0``
does not end at its start). The landing (``y_g`` back to 0 with ``w_g < 0``) is an impact of the
group: ``w+ = -e w-`` (``e`` the body's restitution; ``w+ = 0`` where ``e |w-| < zeno``), normal
impulse ``P_n = M_g (w+ - w-)``, tangential impulse ``P_t = min(m_g |v-|, mu_k P_n)`` against ``v-``
on body ``g`` alone (``mu_k`` of ``v-``'s direction). Their losses
``M_g (w-^2 - w+^2)/2 + m_g (v-^2 - v+^2)/2`` join ``e_d``; ``e`` gains ``M_g (y_g + w_g^2/2)`` per
group. After a plastic landing the group flies on at once with ``w = 0`` where ``N_g < 0`` (the
springs still pull it up), else body ``g`` is re-decided stuck or slipping with ``N_g``. After an
event under hopping with tilted springs, other flights at the ground with ``w < 0`` land and other
loads at zero and falling lift off at the same instant. ``w = e_d + Delta e`` holds.
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
    y0: float = 0.0  # hopping only: initial height and vertical velocity of a body in contact
    w0: float = 0.0
    e: float = 0.0  # its restitution


@dataclass
class System:
    bodies: list
    springs: list = field(default_factory=list)  # (a, b, k, rest: float or Sig); -1 is the wall
    forces: list = field(default_factory=list)  # (a, b, Sig)
    externals: list = field(default_factory=list)  # (i, Sig)
    dampers: list = field(default_factory=list)  # (a, b, c); -1 is the wall
    tilted: list = field(default_factory=list)  # (a, b, k, d, rest: float or Sig); -1 is the wall (x = 0, height 0)
    zeno: float = 1e-3  # hopping only: a rebound slower than this is plastic

    def normal(self) -> np.ndarray:
        N = np.array([b.m if b.law is not None else 0.0 for b in self.bodies])
        for i, b in enumerate(self.bodies):
            j = b.carrier
            while j is not None and self.bodies[j].law is None:
                j = self.bodies[j].carrier
            if b.carrier is not None and j is not None:
                N[j] += b.m
        return N

    def loads(
        self, t: float, x: np.ndarray, v: np.ndarray, h: np.ndarray | None = None
    ) -> tuple[np.ndarray, float, float]:
        """Forces F_i, the elastic energy and the power put in by the actuators and forces; `h`: the
        bodies' heights under hopping (None: every height 0)."""
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
        for a, b, k, d, rest in self.tilted:
            T, u, _, l, dr = self._tension(t, x, a, b, k, d, rest, h)
            if a >= 0:
                F[a] += T * u / l
            if b >= 0:
                F[b] -= T * u / l
            elastic += T * T / (2 * k)
            power += -T * dr
        return F, elastic, power

    @staticmethod
    def _tension(t, x, a, b, k, d, rest, h=None) -> tuple[float, float, float, float, float]:
        """A tilted spring's tension, ``u = x_b - x_a``, its vertical extent ``d + h_b - h_a`` (``d``
        where `h` is None), its length and the rest-length rate."""
        r, dr = rest.at(t) if isinstance(rest, Sig) else (rest, 0.0)
        u = (0.0 if b < 0 else x[b]) - (0.0 if a < 0 else x[a])
        hz = d if h is None else d + (0.0 if b < 0 else h[b]) - (0.0 if a < 0 else h[a])
        l = np.sqrt(u * u + hz * hz)
        return k * (l - r), u, hz, l, dr

    def vertical(self, t: float, x: np.ndarray, h: np.ndarray | None = None) -> np.ndarray:
        """The tilted springs' vertical force on each body, upwards positive (``+T hz / l`` on ``a``,
        ``hz = d + h_b - h_a`` with the heights `h`, ``d`` where `h` is None)."""
        V = np.zeros(len(self.bodies))
        for a, b, k, d, rest in self.tilted:
            T, _, hz, l, _ = self._tension(t, x, a, b, k, d, rest, h)
            if a >= 0:
                V[a] += T * hz / l
            if b >= 0:
                V[b] -= T * hz / l
        return V

    def damping(self, v: np.ndarray) -> float:
        """The power the dampers dissipate."""
        vel = lambda i: 0.0 if i < 0 else v[i]
        return sum(c * (vel(b) - vel(a)) ** 2 for a, b, c in self.dampers)


def _grounds(sys: System) -> list[int | None]:
    """Per body, the body in contact that finally carries it (itself if in contact; None: free)."""
    out: list[int | None] = []
    for i, b in enumerate(sys.bodies):
        j: int | None = i
        while j is not None and sys.bodies[j].law is None:
            j = sys.bodies[j].carrier
        out.append(j)
    return out


def run(sys: System, t_end: float, save: np.ndarray, rtol: float = 1e-12, atol: float = 1e-13,
        hop: bool = False, max_segments: int = 200_000) -> dict:  # fmt: skip
    """Positions, velocities, e_d, w and energy at the times `save` (increasing, in [0, t_end]),
    the normal loads `N` (0 without contact or in flight), `status` ("ok", "liftoff", or "stalled":
    `max_segments` integration segments, between events, reached before `t_end`, the rows ending there),
    `t_liftoff` (inf if none) and `valid_until` (later samples repeat the state there);
    with `hop`, heights `y` and vertical velocities `vy` per body (its ground body's; 0 for a free
    body) and the landings per body in contact, `n_landings` (module docstring)."""
    n = len(sys.bodies)
    m = np.array([b.m for b in sys.bodies])
    c = np.array([b.c for b in sys.bodies])
    N = sys.normal()  # the weights alone (each group's mass at its body in contact)
    contact = [b.law is not None for b in sys.bodies]
    law = [b.law if b.law is not None else (0.0, 0.0, 0.0, 0.0) for b in sys.bodies]
    y = np.concatenate([[b.x0 for b in sys.bodies], [b.v0 for b in sys.bodies], [0.0, 0.0]])
    grounds = _grounds(sys)
    # Hopping with tilted springs: the ground bodies' heights and vertical velocities are integrated, the
    # state is (x, v, e_d, w, heights, vertical velocities); otherwise flights are closed-form free falls.
    vert = hop and bool(sys.tilted)
    YH, WH = 2 * n + 2, 3 * n + 2  # where the heights and the vertical velocities start in that state
    gi = np.array([0 if g is None else g for g in grounds])
    on = np.array([g is not None for g in grounds])

    def heights(r: np.ndarray) -> np.ndarray | None:
        """Per body its ground body's height (a free body's 0); None where flights are free falls."""
        return np.where(on, r[YH + gi], 0.0) if vert else None

    def load(t: float, x: np.ndarray, h: np.ndarray | None = None) -> np.ndarray:
        """The normal loads: the weights less the vertical spring forces on each group (module docstring)."""
        if not sys.tilted:
            return N
        V = sys.vertical(t, x, h)
        out = N.copy()
        for i, g in enumerate(grounds):
            if g is not None:
                out[g] -= V[i]
        return out

    # Bodies in contact whose load the tilted springs change (a lift-off event each).
    lifting = sorted({grounds[j] for a, b, *_ in sys.tilted for j in (a, b) if j >= 0 and grounds[j] is not None})
    # Per body in contact in flight: (time the flight began, its height and vertical velocity then).
    flight: dict[int, tuple[float, float, float]] = {}
    if hop:
        flight = {i: (0.0, b.y0, b.w0) for i, b in enumerate(sys.bodies) if contact[i] and (b.y0 > 0 or b.w0 > 0)}
    if vert:
        y = np.concatenate([y, np.zeros(2 * n)])
        for i, (_, h0, w0) in flight.items():
            y[YH + i], y[WH + i] = h0, w0
        N0 = load(0.0, y[:n], heights(y))
        for i in lifting:  # on the ground with no load: in flight from the start
            if i not in flight and N0[i] <= 0:
                flight[i] = (0.0, 0.0, 0.0)
    landings = np.zeros(n, int)

    def vertical(i: int, t: float, r: np.ndarray) -> tuple[float, float]:
        """The height and vertical velocity of body `i` in contact at time `t` (state `r`)."""
        if i not in flight:
            return 0.0, 0.0
        if vert:
            return r[YH + i], r[WH + i]
        t0, y0, w0 = flight[i]
        s = t - t0
        return y0 + w0 * s - 0.5 * s * s, w0 - s

    def landing_time(i: int) -> float:
        t0, y0, w0 = flight[i]
        return t0 + w0 + np.sqrt(w0 * w0 + 2 * y0)

    def decide(t, y, stuck, sdir, fired):
        """Re-decide every contact body after an event; `fired`: `(body, direction)` of the event that
        ended the segment (direction +-1: the static limit it crossed; 0: its velocity reached zero)."""
        h = heights(y)
        F = sys.loads(t, y[:n], y[n : 2 * n], h)[0]
        Nt = load(t, y[:n], h)
        for i in range(n):
            if not contact[i] or i in flight:
                continue
            tol = 1e-10 * max(1.0, abs(F[i]))
            holds = -law[i][1] * Nt[i] - tol <= F[i] <= law[i][0] * Nt[i] + tol
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

    stuck = [contact[i] and i not in flight and sys.bodies[i].v0 == 0 for i in range(n)]
    sdir = [1.0 if b.v0 > 0 else -1.0 if b.v0 < 0 else 1.0 for b in sys.bodies]
    F0 = sys.loads(0.0, y[:n], y[n : 2 * n], heights(y))[0]
    N0 = load(0.0, y[:n], heights(y))
    for i in range(n):
        if sys.bodies[i].v0 == 0:
            sdir[i] = 1.0 if F0[i] >= 0 else -1.0
            if stuck[i] and not (-law[i][1] * N0[i] <= F0[i] <= law[i][0] * N0[i]):  # (in flight: not stuck)
                stuck[i] = False

    def rhs(t, y, stuck, sdir):
        x, v = y[:n], y[n : 2 * n]
        h = heights(y)
        F, _, power = sys.loads(t, x, v, h)
        Nt = load(t, x, h)
        a = np.zeros(n)
        ed = 0.0
        for i in range(n):
            if contact[i] and stuck[i]:
                continue
            mu = 0.0 if not contact[i] or i in flight else (law[i][2] if sdir[i] > 0 else law[i][3])
            a[i] = (F[i] - c[i] * v[i] - sdir[i] * mu * Nt[i]) / m[i]
            # sdir v = |v| in the mode, and smooth through a step that overshoots the v = 0 event (as is
            # its dense output there)
            ed += mu * Nt[i] * sdir[i] * v[i] + c[i] * v[i] ** 2
        xd = np.where([contact[i] and stuck[i] for i in range(n)], 0.0, v)
        out = np.concatenate([xd, a, [ed + sys.damping(v), power]])
        if not vert:
            return out
        dh, dw = np.zeros(n), np.zeros(n)
        for i in flight:  # the group of i: M w' = -N (its weight less the springs' lift), y' = w
            dh[i], dw[i] = y[WH + i], -Nt[i] / N[i]
        return np.concatenate([out, dh, dw])

    def events(stuck, sdir):
        out, owner = [], []
        F = lambda t, y, i: sys.loads(t, y[:n], y[n : 2 * n], heights(y))[0][i]
        for i in range(n):
            if not contact[i] or i in flight:
                continue
            if stuck[i]:
                out.append(lambda t, y, *_, i=i: law[i][0] * load(t, y[:n], heights(y))[i] - F(t, y, i))
                out.append(lambda t, y, *_, i=i: F(t, y, i) + law[i][1] * load(t, y[:n], heights(y))[i])
                owner += [(i, 1.0), (i, -1.0)]
            else:
                out.append(lambda t, y, *_, i=i: sdir[i] * y[n + i])
                owner.append((i, 0.0))
        for i in lifting:  # a load reaching zero: the strict reading stops, hopping lifts the group off
            if i in flight:
                continue
            out.append(lambda t, y, *_, i=i: load(t, y[:n], heights(y))[i])
            owner.append((i, None))
        if vert:  # a landing: y back to 0 with w < 0 (the ascent, w >= 0, masked: y + w > 0 there)
            for i in flight:
                out.append(lambda t, y, *_, i=i: y[YH + i] + max(y[WH + i], 0.0))
                owner.append((i, 2.0))
        for e in out:
            e.terminal, e.direction = True, -1
        return out, owner

    def land(t: float, y: np.ndarray, i: int) -> None:
        """The impact of body `i` and what it carries at time `t` (module docstring)."""
        _, w = vertical(i, t, y)
        e = sys.bodies[i].e
        wp = 0.0 if e * abs(w) < sys.zeno else -e * w
        v = y[n + i]
        mu = law[i][2] if v >= 0 else law[i][3]
        Pt = min(m[i] * abs(v), mu * N[i] * (wp - w))
        vp = 0.0 if Pt >= m[i] * abs(v) else v - np.sign(v) * Pt / m[i]
        y[2 * n] += 0.5 * N[i] * (w * w - wp * wp) + 0.5 * m[i] * (v * v - vp * vp)
        y[n + i] = vp
        landings[i] += 1
        del flight[i]
        if vert:
            y[YH + i], y[WH + i] = 0.0, wp
        Ni = load(t, y[:n], heights(y))[i] if vert else N[i]  # the load on the ground after the impact
        if wp > 0:
            flight[i] = (t, 0.0, wp)
        elif vert and Ni < 0:  # the springs still pull the group up: it flies on at once
            flight[i] = (t, 0.0, 0.0)
        elif vp != 0:
            stuck[i], sdir[i] = False, float(np.sign(vp))
        else:
            F = sys.loads(t, y[:n], y[n : 2 * n], heights(y))[0][i]
            stuck[i] = -law[i][1] * Ni <= F <= law[i][0] * Ni
            sdir[i] = 1.0 if F >= 0 else -1.0

    def lift(t: float, y: np.ndarray, i: int) -> None:
        """Body `i` and what it carries leave the ground at time `t` (its load has reached zero)."""
        flight[i] = (t, 0.0, 0.0)
        stuck[i] = False
        if y[n + i] != 0:
            sdir[i] = float(np.sign(y[n + i]))
        y[YH + i], y[WH + i] = 0.0, 0.0

    def settle(t: float, y: np.ndarray) -> None:
        """After a landing, a lift-off or a stick-slip event under hopping with tilted springs: other flights
        back on the ground land, other loads at zero and falling lift off, stuck bodies are re-checked."""
        for i in [i for i in flight if y[YH + i] <= 1e-12 and y[WH + i] < 0]:
            land(t, y, i)
        Nt = load(t, y[:n], heights(y))
        for i in lifting:
            if i not in flight and Nt[i] <= 1e-12:
                dt = 1e-7  # whether the load falls along the motion (a forward difference; its sign only)
                y2 = y + dt * rhs(t, y, stuck, sdir)
                if Nt[i] <= 0 or load(t + dt, y2[:n], heights(y2))[i] < Nt[i]:
                    lift(t, y, i)
        decide(t, y, stuck, sdir, (-1, 0.0))

    def sample(t: float, r: np.ndarray) -> np.ndarray:
        """A saved row: the integrated state, then per body the height, vertical velocity and normal load."""
        hw = [vertical(g, t, r) if g is not None else (0.0, 0.0) for g in grounds]
        Nt = load(t, r[:n], heights(r))
        Ns = [Nt[i] if contact[i] and i not in flight else 0.0 for i in range(n)]
        return np.concatenate([r, [h for h, _ in hw], [w for _, w in hw], Ns])

    t = 0.0
    rows, k = [], 0  # (save time, the time the row is evaluated at, the row)
    segments = 0
    t_liftoff = np.inf
    if not hop and any(contact[i] and N0[i] <= 0 for i in lifting):
        t_liftoff = 0.0
    while t < t_end and segments < max_segments and t_liftoff == np.inf:
        segments += 1
        st, sd = list(stuck), list(sdir)
        ev, owner = events(st, sd)
        t_land = t_end if vert else min([landing_time(i) for i in flight] + [t_end])
        # A group lifted off at this instant from the surface at rest (a plastic landing whose springs
        # pull it straight off again): the solver's own first step can round to no step at all, whose
        # end repeats the start and reads as a landing there; a first step of 1e-9 (relative) leaves.
        leaving = vert and any(t0 == t and y[YH + i] == 0 and y[WH + i] == 0 for i, (t0, *_) in flight.items())
        first = 1e-9 * max(1.0, abs(t)) if leaving else None
        sol = solve_ivp(rhs, (t, t_land), y, method="DOP853", args=(st, sd), events=ev, rtol=rtol, atol=atol,
                        dense_output=True, max_step=0.05, first_step=first)  # fmt: skip
        t_next = sol.t[-1]
        while k < len(save) and save[k] <= t_next:
            rows.append((save[k], save[k], sample(save[k], sol.sol(save[k]))))
            k += 1
        y, t = sol.y[:, -1].copy(), t_next
        if sol.status == 1:
            hit = [owner[j] for j, te in enumerate(sol.t_events) if len(te)]
            fired = hit[0]
            if not hop and any(h[1] is None for h in hit):  # lift-off: the strict reading stops here
                t_liftoff = t
                break
            if vert and fired[1] is None:
                stuck, sdir = st, sd
                lift(t, y, fired[0])
            elif vert and fired[1] == 2.0:
                stuck, sdir = st, sd
                land(t, y, fired[0])
            else:
                stuck, sdir = decide(t, y, st, sd, fired)
            if vert:
                settle(t, y)
        elif t < t_end:  # a landing (bodies whose flights end together land together)
            for i in [i for i in flight if landing_time(i) <= t + 1e-12]:
                land(t, y, i)
    while t_liftoff < np.inf and k < len(save):  # after a lift-off: the state there
        rows.append((save[k], t, sample(t, y)))
        k += 1
    out = np.array([r for *_, r in rows])
    M = np.array([N[g] if g == i else 0.0 for i, g in enumerate(grounds)])  # each group's mass, once
    hy, vy, Ns = out[:, -3 * n : -2 * n], out[:, -2 * n : -n], out[:, -n:]
    energy = np.array([0.5 * np.sum(m * r[n : 2 * n] ** 2) + sys.loads(s, r[:n], r[n : 2 * n], heights(r))[1]
                       for _, s, r in rows])  # fmt: skip
    energy = energy + (hy + 0.5 * vy * vy) @ M
    base = out[:, : 2 * n + 2]
    return dict(t=np.array([s for s, *_ in rows]), x=base[:, :n], v=base[:, n : 2 * n], ed=base[:, -2], w=base[:, -1],
                e=energy, com=base[:, :n] @ m / m.sum(), y=hy, vy=vy, n_landings=landings.copy(), N=Ns,
                status="liftoff" if t_liftoff < np.inf else "ok" if t >= t_end else "stalled", t_liftoff=t_liftoff,
                valid_until=min(t_liftoff, t_end, t))  # fmt: skip
