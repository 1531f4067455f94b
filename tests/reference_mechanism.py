"""Independent float64 reference for mechanisms on a line (SPEC §9): bodies with or without ground
contact, carried bodies, linear and tilted springs and linear dampers between any bodies or to a
wall (at x = 0), internal forces and external forces.

Written only from SPEC.md §9 (and §8 for stick and slip and the tilted springs); it imports
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
at ``x = 0``, height 0), stores ``T^2 / (2k)`` and takes in the power ``-T dr/dt``. A body ``g`` in
contact has the normal load ``N_g = m_g + sum of the masses it carries - sum of the vertical spring
forces on g and on the bodies it carries`` (constant without tilted springs; vertical forces on free
bodies are ignored) and anisotropic Coulomb friction with ``N_g`` at the current state; a body
without contact feels no friction. Ground damping ``c_i v_i``. Strict reading: the run stops where a
normal load reaches 0 (``status = "liftoff"``, ``t_liftoff``; later samples repeat the state there).

Method: event-driven, one ``solve_ivp(DOP853)`` per segment of constant mode (the set of stuck
contact bodies and each slipping body's direction), terminal events at a stuck body's static
limits, a slipping body's zero velocity and a state-dependent normal load's zero (lift-off); after
every other event every contact body is re-decided from the state. The state carries the
dissipated energy ``e_d`` and the work ``w``.

Hopping (``run(..., hop=True)``, SPEC §10; with tilted springs ``NotImplementedError``): a body in
contact starts in flight where its ``y0 > 0`` or ``w0 > 0``. No vertical force acts (the elements
are horizontal), so a body in flight and every body it carries fall freely,
``y = y_f + w_f s - s^2/2`` (``s`` the time since the flight began),
and it feels no friction; on the ground its load is constant, so it never lifts off by itself.
A carried body rides with the body that finally carries it. The landing (``y`` back to 0, at the
time solved in closed form; a segment ends there) is an impact of the group, ``M`` = the body's
mass and the masses it carries: ``w+ = -e w-`` (``e`` the body's restitution; ``w+ = 0`` where
``e |w-| < zeno``), normal impulse ``P_n = M (w+ - w-)``, tangential impulse
``P_t = min(m |v-|, mu_k P_n)`` against ``v-`` on the body alone (``mu_k`` of ``v-``'s
direction). Their losses ``M (w-^2 - w+^2)/2 + m (v-^2 - v+^2)/2`` join ``e_d``; ``e`` gains
``M (y + w^2/2)``. After a plastic landing the body is re-decided stuck or slipping.
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
        for a, b, k, d, rest in self.tilted:
            T, u, l, dr = self._tension(t, x, a, b, k, d, rest)
            if a >= 0:
                F[a] += T * u / l
            if b >= 0:
                F[b] -= T * u / l
            elastic += T * T / (2 * k)
            power += -T * dr
        return F, elastic, power

    @staticmethod
    def _tension(t, x, a, b, k, d, rest) -> tuple[float, float, float, float]:
        """A tilted spring's tension, ``u = x_b - x_a``, length and rest-length rate."""
        r, dr = rest.at(t) if isinstance(rest, Sig) else (rest, 0.0)
        u = (0.0 if b < 0 else x[b]) - (0.0 if a < 0 else x[a])
        l = np.sqrt(u * u + d * d)
        return k * (l - r), u, l, dr

    def vertical(self, t: float, x: np.ndarray) -> np.ndarray:
        """The tilted springs' vertical force on each body, upwards positive (``+T d / l`` on ``a``)."""
        V = np.zeros(len(self.bodies))
        for a, b, k, d, rest in self.tilted:
            T, _, l, _ = self._tension(t, x, a, b, k, d, rest)
            if a >= 0:
                V[a] += T * d / l
            if b >= 0:
                V[b] -= T * d / l
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
        hop: bool = False) -> dict:  # fmt: skip
    """Positions, velocities, e_d, w and energy at the times `save` (increasing, in [0, t_end]),
    the normal loads `N` (0 without contact or in flight), `status` ("ok" or "liftoff"),
    `t_liftoff` (inf if none) and `valid_until` (later samples repeat the state there);
    with `hop`, heights `y` and vertical velocities `vy` per body (a carried body's its carrier's)
    and the landings per body in contact, `n_landings` (module docstring)."""
    if hop and sys.tilted:
        raise NotImplementedError("reference_mechanism.run: hop=True with tilted springs is not implemented "
                                  "(the reference's flights are free falls); use the hopping reference")  # fmt: skip
    n = len(sys.bodies)
    m = np.array([b.m for b in sys.bodies])
    c = np.array([b.c for b in sys.bodies])
    N = sys.normal()  # the weights alone (each group's mass at its body in contact)
    contact = [b.law is not None for b in sys.bodies]
    law = [b.law if b.law is not None else (0.0, 0.0, 0.0, 0.0) for b in sys.bodies]
    y = np.concatenate([[b.x0 for b in sys.bodies], [b.v0 for b in sys.bodies], [0.0, 0.0]])
    grounds = _grounds(sys)

    def load(t: float, x: np.ndarray) -> np.ndarray:
        """The normal loads: the weights less the vertical spring forces on each group (module docstring)."""
        if not sys.tilted:
            return N
        V = sys.vertical(t, x)
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
    landings = np.zeros(n, int)

    def vertical(i: int, t: float) -> tuple[float, float]:
        if i not in flight:
            return 0.0, 0.0
        t0, y0, w0 = flight[i]
        s = t - t0
        return y0 + w0 * s - 0.5 * s * s, w0 - s

    def landing_time(i: int) -> float:
        t0, y0, w0 = flight[i]
        return t0 + w0 + np.sqrt(w0 * w0 + 2 * y0)

    def decide(t, y, stuck, sdir, fired):
        """Re-decide every contact body after an event; `fired`: `(body, direction)` of the event that
        ended the segment (direction +-1: the static limit it crossed; 0: its velocity reached zero)."""
        F = sys.loads(t, y[:n], y[n : 2 * n])[0]
        Nt = load(t, y[:n])
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
    F0 = sys.loads(0.0, y[:n], y[n : 2 * n])[0]
    N0 = load(0.0, y[:n])
    for i in range(n):
        if sys.bodies[i].v0 == 0:
            sdir[i] = 1.0 if F0[i] >= 0 else -1.0
            if stuck[i] and not (-law[i][1] * N0[i] <= F0[i] <= law[i][0] * N0[i]):  # (in flight: not stuck)
                stuck[i] = False

    def rhs(t, y, stuck, sdir):
        x, v = y[:n], y[n : 2 * n]
        F, _, power = sys.loads(t, x, v)
        Nt = load(t, x)
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
        return np.concatenate([xd, a, [ed + sys.damping(v), power]])

    def events(stuck, sdir):
        out, owner = [], []
        F = lambda t, y, i: sys.loads(t, y[:n], y[n : 2 * n])[0][i]
        for i in range(n):
            if not contact[i] or i in flight:
                continue
            if stuck[i]:
                out.append(lambda t, y, *_, i=i: law[i][0] * load(t, y[:n])[i] - F(t, y, i))
                out.append(lambda t, y, *_, i=i: F(t, y, i) + law[i][1] * load(t, y[:n])[i])
                owner += [(i, 1.0), (i, -1.0)]
            else:
                out.append(lambda t, y, *_, i=i: sdir[i] * y[n + i])
                owner.append((i, 0.0))
        for i in lifting:  # strict reading: the run stops where a normal load reaches zero
            out.append(lambda t, y, *_, i=i: load(t, y[:n])[i])
            owner.append((i, None))
        for e in out:
            e.terminal, e.direction = True, -1
        return out, owner

    def land(t: float, y: np.ndarray, i: int) -> None:
        """The impact of body `i` and what it carries at time `t` (module docstring)."""
        _, w = vertical(i, t)
        e = sys.bodies[i].e
        wp = 0.0 if e * abs(w) < sys.zeno else -e * w
        v = y[n + i]
        mu = law[i][2] if v >= 0 else law[i][3]
        Pt = min(m[i] * abs(v), mu * N[i] * (wp - w))
        vp = 0.0 if Pt >= m[i] * abs(v) else v - np.sign(v) * Pt / m[i]
        y[-2] += 0.5 * N[i] * (w * w - wp * wp) + 0.5 * m[i] * (v * v - vp * vp)
        y[n + i] = vp
        landings[i] += 1
        del flight[i]
        if wp > 0:
            flight[i] = (t, 0.0, wp)
        elif vp != 0:
            stuck[i], sdir[i] = False, float(np.sign(vp))
        else:
            F = sys.loads(t, y[:n], y[n : 2 * n])[0][i]
            stuck[i] = -law[i][1] * N[i] <= F <= law[i][0] * N[i]
            sdir[i] = 1.0 if F >= 0 else -1.0

    def sample(t: float, r: np.ndarray) -> np.ndarray:
        """A saved row: the integrated state, then per body the height, vertical velocity and normal load."""
        hw = [vertical(g, t) if g is not None else (0.0, 0.0) for g in grounds]
        Nt = load(t, r[:n])
        Ns = [Nt[i] if contact[i] and i not in flight else 0.0 for i in range(n)]
        return np.concatenate([r, [h for h, _ in hw], [w for _, w in hw], Ns])

    t = 0.0
    rows, k = [], 0  # (save time, the time the row is evaluated at, the row)
    segments = 0
    t_liftoff = np.inf
    if any(contact[i] and N0[i] <= 0 for i in lifting):
        t_liftoff = 0.0
    while t < t_end and segments < 200_000 and t_liftoff == np.inf:
        segments += 1
        st, sd = list(stuck), list(sdir)
        ev, owner = events(st, sd)
        t_land = min([landing_time(i) for i in flight] + [t_end])
        sol = solve_ivp(rhs, (t, t_land), y, method="DOP853", args=(st, sd), events=ev, rtol=rtol, atol=atol,
                        dense_output=True, max_step=0.05)  # fmt: skip
        t_next = sol.t[-1]
        while k < len(save) and save[k] <= t_next:
            rows.append((save[k], save[k], sample(save[k], sol.sol(save[k]))))
            k += 1
        y, t = sol.y[:, -1].copy(), t_next
        if sol.status == 1:
            hit = [owner[j] for j, te in enumerate(sol.t_events) if len(te)]
            if any(h[1] is None for h in hit):  # lift-off: the strict reading stops here
                t_liftoff = t
                break
            fired = hit[0]
            stuck, sdir = decide(t, y, st, sd, fired)
        elif t < t_end:  # a landing (bodies whose flights end together land together)
            for i in [i for i in flight if landing_time(i) <= t + 1e-12]:
                land(t, y, i)
    while t_liftoff < np.inf and k < len(save):  # after a lift-off: the state there
        rows.append((save[k], t, sample(t, y)))
        k += 1
    out = np.array([r for *_, r in rows])
    M = np.array([N[g] if g == i else 0.0 for i, g in enumerate(grounds)])  # each group's mass, once
    hy, vy, Ns = out[:, -3 * n : -2 * n], out[:, -2 * n : -n], out[:, -n:]
    energy = np.array([0.5 * np.sum(m * r[n : 2 * n] ** 2) + sys.loads(s, r[:n], r[n : 2 * n])[1] for _, s, r in rows])
    energy = energy + (hy + 0.5 * vy * vy) @ M
    base = out[:, : 2 * n + 2]
    return dict(t=np.array([s for s, *_ in rows]), x=base[:, :n], v=base[:, n : 2 * n], ed=base[:, -2], w=base[:, -1],
                e=energy, com=base[:, :n] @ m / m.sum(), y=hy, vy=vy, n_landings=landings.copy(), N=Ns,
                status="liftoff" if t_liftoff < np.inf else "ok", t_liftoff=t_liftoff,
                valid_until=min(t_liftoff, t_end))  # fmt: skip
