"""Independent float64 reference solver for the two-mass friction locomotion model.

Written only from ``SPEC.md`` (sections 1, 2, 4, 5) and the paper's equation numbering
(Zhou, Majidi, O'Reilly, Nonlinear Dyn. 78, 2014).  It shares no code with the
``locomotion_jax`` package and uses only numpy and scipy, so that the package can be
tested against it.

Method
------
Event-driven integration of the exact hybrid (Coulomb stick/slip) dynamics, eqs. (7, 9)
as corrected in SPEC section 2: one ``scipy.integrate.solve_ivp`` (DOP853) call per
segment of constant friction mode.  Each segment ends at the first located event:

* a stuck mass reaching its static limit ``|F_i| = mu_s n_i`` (stick -> slip, eq. 7);
* a slipping mass reaching ``v_i = 0`` (slip -> stick, or slip reversal, eq. 9);
* a normal force ``N_i`` crossing zero (lift-off, eq. 5);
* optionally ``|X - X_ref| = z`` (measurement of ``tau_z``, SPEC section 5).

After every event *both* masses are re-checked from the state (with a tiny tolerance),
so that simultaneous switches, e.g. the symmetric ``d = 0, m1 = m2`` case, are taken
together.  Event functions that are zero at the start of a segment are never re-detected
there: every event has a direction that points away from the side the segment starts on,
the state is set exactly onto the switching surface (``v_i = 0``) at each switch, and a
function that starts at zero (``v_i`` after a switch, ``N_i`` after a paper-mode crossing)
is divided by ``t - t0`` so that a quick return across zero is still located.
scipy tests events only at step ends, so after each segment the dense output is also
sampled inside every step (``_HybridSolver._audit``) to catch grazing double crossings.
The number of segments is capped, and a run of zero-length segments raises
``RuntimeError`` (Zeno / chattering guard), so no run can loop forever.

The ODE state is augmented with the dissipated energy ``e_d`` (eq. 15) and the
actuator work ``w`` (integral of ``-T dl0/dt``), so that the balance
``w = e_d + e(t2) - e(t1)`` (eq. 16) is a genuine check of the integration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import BSpline
from scipy.optimize import brentq


__all__ = ["DEFAULTS", "reference_natural_frequencies", "reference_simulate", "reference_measure"]

DEFAULTS = dict(k=50.0, c=0.01, d=0.5, lbar=3.0, a=0.05, omega=2.0, mu_s=0.7, mu_k=0.5, mhat=0.5)

# Friction-mode codes of SPEC section 2.
MODE_BOTH_STUCK, MODE_BOTH_SLIP, MODE_M1_SLIPS, MODE_M2_SLIPS = 0, 1, 2, 3


def _terminal(event: Callable[..., float], direction: float) -> Callable[..., float]:
    """`event` marked for `solve_ivp` as terminal, firing on zero crossings in `direction`."""
    setattr(event, "terminal", True)
    setattr(event, "direction", direction)
    return event


# Tolerances of the post-event re-check of the non-triggering mass (forces and
# velocities are O(1) here; located events leave residuals ~1e-15).
_TOL_FORCE = 1e-10
_TOL_VEL = 1e-10
# Zeno / chattering guards.
_MAX_SEGMENTS = 500_000
_MAX_TINY_SEGMENTS = 200  # consecutive segments shorter than _TINY_DT
_TINY_DT = 1e-12


def _mode_code(stuck1: bool, stuck2: bool) -> int:
    """Friction mode of SPEC section 2: 0 both stuck, 1 both slip, 2 m1 slips, 3 m2 slips."""
    if stuck1 and stuck2:
        return MODE_BOTH_STUCK
    if not stuck1 and not stuck2:
        return MODE_BOTH_SLIP
    return MODE_M1_SLIPS if stuck2 else MODE_M2_SLIPS


def _sign(x: float) -> int:
    return 1 if x >= 0.0 else -1


class _Model:
    """Parameters and the smooth parts of the model (SPEC section 1).

    Masses (Sect. 2.1): ``m1 = 2 mhat``, ``m2 = 2 (1 - mhat)`` so that ``m1 + m2 = 2``.
    """

    def __init__(self, params: dict, contact: str, wave=None):
        unknown = set(params) - set(DEFAULTS)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; valid: {sorted(DEFAULTS)}")
        if contact not in ("strict", "paper"):
            raise ValueError(f"contact must be 'strict' or 'paper', got {contact!r}")
        p = {**DEFAULTS, **params}
        self.k = float(p["k"])
        self.c = float(p["c"])
        self.d = float(p["d"])
        self.lbar = float(p["lbar"])
        self.a = float(p["a"])
        self.omega = float(p["omega"])
        # Optional Fourier actuation (replaces eq. 13's sinusoid, ``a`` unused):
        # l0 = lbar + sum_h cos_h cos(h omega t) + sin_h sin(h omega t), h = 1..H.
        # Or ``("spline", c)``: a periodic uniform cubic B-spline in the phase with control values
        # c_j centred at the phases 2 pi j / M (scipy's BSpline on an extended knot vector).
        self.wave = None
        self.spline = None
        if wave is not None and isinstance(wave[0], str):
            if wave[0] != "spline":
                raise ValueError(f"unknown waveform kind {wave[0]!r}")
            c = np.asarray(wave[1], dtype=float)
            m = len(c)
            # Basis i (degree 3) starts at knot i - 3 and is centred at i - 1: coefficient c_{(i-1) mod M}.
            self.spline = (m, BSpline(np.arange(-3.0, m + 4.0), c[(np.arange(m + 3) - 1) % m], 3, extrapolate=False))
        elif wave is not None:
            cos, sin = (np.atleast_1d(np.asarray(w, dtype=float)) for w in wave)
            if cos.shape != sin.shape or cos.ndim != 1:
                raise ValueError(f"wave must be two 1-D sequences of the same length, got {cos.shape}, {sin.shape}")
            self.wave = (cos.tolist(), sin.tolist())
        self.mu_s = float(p["mu_s"])
        self.mu_k = float(p["mu_k"])
        mhat = float(p["mhat"])
        if not 0.0 < mhat < 1.0:
            raise ValueError(f"mhat must lie in (0, 1), got {mhat}")
        if self.mu_s < self.mu_k:
            raise ValueError(f"need mu_s >= mu_k, got mu_s={self.mu_s}, mu_k={self.mu_k}")
        self.m1 = 2.0 * mhat
        self.m2 = 2.0 * (1.0 - mhat)
        self.strict = contact == "strict"

    # -- natural frequencies, eqs. (11-12) -------------------------------------------
    def natural_frequencies(self) -> tuple[float, float, float]:
        """``wn1 = sqrt(k (m1+m2)/(m1 m2))``, ``wn2 = sqrt(k/m1)``, ``wn3 = sqrt(k/m2)``."""
        m1, m2, k = self.m1, self.m2, self.k
        return (math.sqrt(k * (m1 + m2) / (m1 * m2)), math.sqrt(k / m1), math.sqrt(k / m2))

    @property
    def fastest_drive(self) -> float:
        """The highest frequency in the actuation."""
        if self.spline is not None:
            return self.omega * self.spline[0] / 2  # knot spacing as half a period
        return self.omega * (1 if self.wave is None else len(self.wave[0]))

    def rest_length(self, t: float) -> tuple[float, float]:
        """``(l0, dl0/dt)`` at time ``t``: eq. (13), or the Fourier series or spline of ``wave``."""
        if self.spline is not None:
            m, bs = self.spline
            s = (self.omega * t * m / (2.0 * math.pi)) % m
            return self.lbar + float(bs(s)), float(bs(s, 1)) * self.omega * m / (2.0 * math.pi)
        if self.wave is None:
            wt = self.omega * t
            return self.a * math.sin(wt) + self.lbar, self.a * self.omega * math.cos(wt)
        l0, l0dot = self.lbar, 0.0
        for h, (ch, sh) in enumerate(zip(*self.wave), start=1):
            hw = h * self.omega
            c, s = math.cos(hw * t), math.sin(hw * t)
            l0 += ch * c + sh * s
            l0dot += hw * (sh * c - ch * s)
        return l0, l0dot

    def rest_length_array(self, t) -> np.ndarray:
        """``l0`` at the times ``t`` (numpy-vectorised)."""
        t = np.asarray(t, dtype=float)
        if self.spline is not None:
            m, bs = self.spline
            return self.lbar + bs((self.omega * t * m / (2.0 * np.pi)) % m)
        if self.wave is None:
            return self.a * np.sin(self.omega * t) + self.lbar
        l0 = np.full_like(t, self.lbar)
        for h, (ch, sh) in enumerate(zip(*self.wave), start=1):
            l0 = l0 + ch * np.cos(h * self.omega * t) + sh * np.sin(h * self.omega * t)
        return l0

    # -- forces -------------------------------------------------------------------------
    def forces(self, t: float, x1: float, x2: float):
        """Spring and normal forces at time ``t``.

        Actuation, eq. (13): ``l0 = a sin(omega t) + lbar`` (or the Fourier series of ``wave``).
        Spring length, eq. (2): ``l = sqrt((x2 - x1)^2 + d^2)``; tension ``T = k (l - l0)``.
        Horizontal force on m1, eq. (8): ``fx = T (x2 - x1)/l`` (on m2: ``-fx``); ``fy = T d / l``.
        Normal forces, eq. (5): ``N1 = m1 - fy``, ``N2 = m2 + fy``.

        Returns ``(fx, N1, N2, T, l0, dl0/dt, l)``.
        """
        dx = x2 - x1
        ell = math.sqrt(dx * dx + self.d * self.d)
        if self.wave is None and self.spline is None:
            wt = self.omega * t
            l0 = self.a * math.sin(wt) + self.lbar
            l0dot = self.a * self.omega * math.cos(wt)
        else:
            l0, l0dot = self.rest_length(t)
        T = self.k * (ell - l0)
        fx = T * dx / ell
        fy = T * self.d / ell
        return fx, self.m1 - fy, self.m2 + fy, T, l0, l0dot, ell

    def normal(self, N: float) -> float:
        """Normal force used by friction: ``n = N`` (strict) or ``n = |N|`` (paper's reading, SPEC section 1)."""
        return N if self.strict else abs(N)

    def energy(self, t, x1, v1, x2, v2):
        """Total energy, eq. (10): ``e = m1 v1^2/2 + m2 v2^2/2 + k (l - l0)^2/2`` (numpy-vectorised)."""
        t, x1, v1, x2, v2 = (np.asarray(u, dtype=float) for u in (t, x1, v1, x2, v2))
        ell = np.sqrt((x2 - x1) ** 2 + self.d**2)
        l0 = self.rest_length_array(t)
        return 0.5 * self.m1 * v1**2 + 0.5 * self.m2 * v2**2 + 0.5 * self.k * (ell - l0) ** 2

    def initial_state(self, start: str | tuple[float, float, float, float]) -> np.ndarray:
        """Initial condition: eq. (14) (``start='paper'``), the relaxed spring (SPEC section 1),
        or a given ``(x1, v1, x2, v2)``.

        State layout: ``(x1, v1, x2, v2, e_d, w)``.
        """
        if not isinstance(start, str):
            x1, v1, x2, v2 = (float(v) for v in start)
            return np.array([x1, v1, x2, v2, 0.0, 0.0])
        if start == "paper":
            x2 = self.lbar
        elif start == "relaxed":
            if self.lbar**2 <= self.d**2:
                raise ValueError("relaxed start needs lbar > |d|")
            x2 = math.sqrt(self.lbar**2 - self.d**2)
        else:
            raise ValueError(f"start must be 'paper' or 'relaxed', got {start!r}")
        return np.array([0.0, 0.0, x2, 0.0, 0.0, 0.0])


class _Segment:
    """One integration segment of constant friction mode, with its dense output."""

    __slots__ = ("t0", "t1", "sol", "stuck", "slip_dir")

    def __init__(self, t0, t1, sol, stuck, slip_dir):
        self.t0, self.t1, self.sol = t0, t1, sol
        self.stuck = tuple(stuck)
        self.slip_dir = tuple(slip_dir)

    @property
    def mode(self) -> int:
        return _mode_code(*self.stuck)


class _HybridSolver:
    """Event-driven integrator of the exact stick/slip dynamics (eqs. 7, 9; SPEC section 2).

    Holds the current time, augmented state ``(x1, v1, x2, v2, e_d, w)``, per-mass
    stuck flags and slip directions, and the list of integrated segments.
    """

    def __init__(self, model: _Model, start: str | tuple[float, float, float, float], rtol: float, atol: float):
        self.m = model
        self.rtol, self.atol = rtol, atol
        self.t = 0.0
        self.y = model.initial_state(start)
        self.stuck = [False, False]
        self.slip_dir = [1, 1]
        self.segments: list[_Segment] = []
        self.events: list[tuple[float, str]] = []
        self.n_switches = 0
        self.liftoff = False
        self.t_liftoff = math.inf
        self.stopped = False  # strict-mode lift-off ends the run
        self._tiny_run = 0
        self._normal_restart = (-1, math.nan)  # (mass, time) of a paper-mode N_i crossing
        wmax = max(model.fastest_drive, *model.natural_frequencies())
        # Events are detected from sign changes between accepted steps; capping the
        # step at 1/16 of the fastest period keeps short excursions from being missed.
        self.max_step = 2.0 * math.pi / wmax / 16.0

        fx, N1, N2, *_ = model.forces(0.0, self.y[0], self.y[2])
        # Side of each normal force (paper contact tracks zero crossings both ways).
        self.n_side = [_sign(N1) if N1 != 0 else -1, _sign(N2) if N2 != 0 else -1]
        if N1 <= 0.0 or N2 <= 0.0:
            self.liftoff, self.t_liftoff = True, 0.0
            if model.strict:
                self.stopped = True
        # Initial modes: a moving mass slips along its velocity; for one at rest eq. (7)
        # decides stick or slip.
        for i, (F, N) in enumerate(((fx, N1), (-fx, N2))):
            n = model.normal(N)
            v = self.y[2 * i + 1]
            if v != 0.0:
                self.stuck[i] = False
                self.slip_dir[i] = _sign(v)
            elif abs(F) <= model.mu_s * n:
                self.stuck[i] = True
            else:
                self.stuck[i] = False
                self.slip_dir[i] = _sign(F)

    # -- derived quantities -------------------------------------------------------------
    @property
    def X(self) -> float:
        """Centre of mass, eq. (4)."""
        m = self.m
        return (m.m1 * self.y[0] + m.m2 * self.y[2]) / (m.m1 + m.m2)

    # -- right-hand side for the current mode ------------------------------------------
    def _rhs(self):
        """Eq. (9), corrected per SPEC section 2, for the current (frozen) mode.

        Slipping mass: ``m_i v_i' = F_i - c v_i - mu_k n_i s_i``; stuck mass: ``v_i = v_i' = 0``.
        Augmented: ``e_d' = mu_k n1 |v1| + mu_k n2 |v2| + c (v1^2 + v2^2)`` (eq. 15),
        ``w' = -T dl0/dt`` (actuator power; eq. 16 then reads ``w = e_d + e(t2) - e(t1)``).
        """
        m = self.m
        stuck1, stuck2 = self.stuck
        s1, s2 = self.slip_dir
        m1, m2, c, mu_k = m.m1, m.m2, m.c, m.mu_k
        forces = m.forces
        # Within a segment sgn(v_i) = s_i and sgn(N_i) = side_i are fixed, so |v_i| and
        # |N_i| are written as s_i v_i and side_i N_i: the right-hand side stays smooth
        # up to (and slightly past) the event that ends the segment, which keeps the
        # dense output accurate at the located event.
        q1, q2 = (1.0, 1.0) if m.strict else (float(self.n_side[0]), float(self.n_side[1]))

        def rhs(t, y):
            x1, v1, x2, v2 = y[0], y[1], y[2], y[3]
            x1 = float(x1)
            x2 = float(x2)
            v1 = 0.0 if stuck1 else float(v1)
            v2 = 0.0 if stuck2 else float(v2)
            fx, N1, N2, T, _l0, l0dot, _l = forces(t, x1, x2)
            n1 = q1 * N1
            n2 = q2 * N2
            a1 = 0.0 if stuck1 else (fx - c * v1 - mu_k * n1 * s1) / m1
            a2 = 0.0 if stuck2 else (-fx - c * v2 - mu_k * n2 * s2) / m2
            ed = mu_k * (n1 * s1 * v1 + n2 * s2 * v2) + c * (v1 * v1 + v2 * v2)
            return np.array([v1, a1, v2, a2, ed, -T * l0dot])

        return rhs

    # -- event functions ----------------------------------------------------------------
    def _make_events(self, rhs, X_ref, z):
        """Build the terminal event functions for the current mode; returns ``(events, tags)``."""
        m = self.m
        forces, normal, mu_s = m.forces, m.normal, m.mu_s
        events, tags = [], []

        for i in (0, 1):
            if self.stuck[i]:
                sgnF = 1.0 if i == 0 else -1.0

                def g_stick(t, y, sgnF=sgnF, i=i):
                    # Static limit of eq. (7): g = mu_s n_i - |F_i| >= 0 while stuck.
                    fx, N1, N2, *_ = forces(t, float(y[0]), float(y[2]))
                    return mu_s * normal(N1 if i == 0 else N2) - abs(sgnF * fx)

                events.append(_terminal(g_stick, -1.0))
                tags.append(("stick_limit", i))
            else:
                j = 2 * i + 1
                if self.y[j] != 0.0:

                    def g_vel(t, y, j=j):
                        return float(y[j])
                else:
                    # The mass has just started (or reversed) from v_i = 0, so v_i is zero
                    # at the segment start and brentq would return t0 for any later
                    # crossing inside the first step.  Divide by (t - t0): the quotient
                    # tends to a_i(t0) at t0 (sign s_i) and changes sign exactly where
                    # v_i returns to zero after the start.
                    t0, a0 = self.t, float(rhs(self.t, self.y)[j])

                    def g_vel_from_rest(t, y, j=j, t0=t0, a0=a0):
                        return a0 if t <= t0 else float(y[j]) / (t - t0)

                    g_vel = g_vel_from_rest

                # v_i moves from 0 (or its side s_i) towards s_i: only a crossing back
                # towards -s_i counts, so the start is never re-detected.
                events.append(_terminal(g_vel, -float(self.slip_dir[i])))
                tags.append(("v_zero", i))

        for i in (0, 1):
            if self._normal_restart == (i, self.t):
                # Paper contact, segment starting on N_i = 0 (just crossed): as for v_i,
                # divide by (t - t0) so that a quick return across zero inside the first
                # step is located instead of being reported at t0 (or missed).
                t0, dN0 = self.t, self._normal_rate(i)

                def g_normal_restart(t, y, i=i, t0=t0, dN0=dN0):
                    if t <= t0:
                        return dN0
                    fx, N1, N2, *_ = forces(t, float(y[0]), float(y[2]))
                    return (N1 if i == 0 else N2) / (t - t0)

                g_normal = g_normal_restart
            else:

                def g_normal(t, y, i=i):
                    fx, N1, N2, *_ = forces(t, float(y[0]), float(y[2]))
                    return N1 if i == 0 else N2

            # Strict: N_i > 0 throughout, stop when it reaches 0.  Paper: every crossing
            # ends a segment (|N_i| has a kink there); the direction follows the side.
            events.append(_terminal(g_normal, -float(self.n_side[i])))
            tags.append(("normal_zero", i))

        if X_ref is not None:
            m1, m2 = m.m1, m.m2
            M = m1 + m2

            def g_up(t, y):
                return (m1 * y[0] + m2 * y[2]) / M - X_ref - z

            def g_down(t, y):
                return (m1 * y[0] + m2 * y[2]) / M - X_ref + z

            events += [_terminal(g_up, 1.0), _terminal(g_down, -1.0)]
            tags += [("target", 0), ("target", 1)]
        return events, tags

    def _normal_rate(self, i: int) -> float:
        """Time derivative of the normal force N_i (eq. 5) at the current state.

        ``dfy/dt = d (T' l - T l') / l^2`` with ``l' = (x2 - x1)(v2 - v1)/l`` and
        ``T' = k (l' - dl0/dt)``; ``dN1/dt = -dfy/dt``, ``dN2/dt = +dfy/dt``.
        """
        m, y = self.m, self.y
        fx, N1, N2, T, l0, l0dot, ell = m.forces(self.t, y[0], y[2])
        ldot = (y[2] - y[0]) * (y[3] - y[1]) / ell
        fydot = m.d * (m.k * (ldot - l0dot) * ell - T * ldot) / (ell * ell)
        return -fydot if i == 0 else fydot

    def _switching_values(self, t, Y, X_ref, z):
        """Switching functions of the current mode on arrays (all >= 0 while the mode is valid).

        Returns a list of ``(tag, values)``: stuck ``mu_s n_i - |F_i|`` (eq. 7), slipping
        ``s_i v_i`` (eq. 9), normal ``side_i N_i`` (eq. 5) and, when measuring,
        ``z - |X - X_ref|``.
        """
        m = self.m
        x1, v1, x2, v2 = Y[0], Y[1], Y[2], Y[3]
        dx = x2 - x1
        ell = np.sqrt(dx * dx + m.d * m.d)
        T = m.k * (ell - m.rest_length_array(t))
        fx = T * dx / ell
        fy = T * m.d / ell
        N = (m.m1 - fy, m.m2 + fy)
        F = (fx, -fx)
        out = []
        for i in (0, 1):
            if self.stuck[i]:
                n = N[i] if m.strict else np.abs(N[i])
                out.append((("stick_limit", i), m.mu_s * n - np.abs(F[i])))
            else:
                out.append((("v_zero", i), self.slip_dir[i] * (v1 if i == 0 else v2)))
            out.append((("normal_zero", i), N[i] if m.strict else self.n_side[i] * N[i]))
        if X_ref is not None:
            X = (m.m1 * x1 + m.m2 * x2) / (m.m1 + m.m2)
            out.append((("target", 0), z - np.abs(X - X_ref)))
        return out

    def _audit(self, sol, t0, t1, X_ref, z, n_sub=16, tol=1e-12) -> tuple[float, Any] | None:
        """Look for switching events that scipy's step-end sign test missed.

        scipy only compares event values at the ends of each accepted step, so a
        switching function that dips below zero and returns inside one step (a grazing
        lift-off, say) is not seen.  Sample every step at ``n_sub`` interior points of
        its dense output; if any switching function is below ``-tol`` before ``t1``,
        locate the first crossing with brentq and return ``(t_event, tag)``.
        """
        ts = np.asarray(sol.ts)
        ts = ts[ts <= t1]
        if ts.size < 2 or t1 <= t0:
            return None
        frac = np.arange(1, n_sub + 1) / n_sub
        grid = (ts[:-1, None] + np.diff(ts)[:, None] * frac[None, :]).ravel()
        grid = np.concatenate([grid[grid < t1], [t1]])
        Y = sol(grid)
        first, found = np.inf, None
        for tag, q in self._switching_values(grid, Y, X_ref, z):
            bad = np.nonzero(q < -tol)[0]
            if bad.size and grid[bad[0]] < first:
                first, found = grid[bad[0]], (tag, bad[0], q)
        if found is None:
            return None
        tag, k, q = found
        # Bracket: the last sample before k with a non-negative value (or the segment start).
        ok = np.nonzero(q[:k] >= 0.0)[0]
        ta = grid[ok[-1]] if ok.size else t0
        tb = grid[k]

        def qfun(t) -> float:
            for tg, val in self._switching_values(np.array([t]), sol(np.array([t])), X_ref, z):
                if tg == tag:
                    return float(val[0])
            raise AssertionError(f"no switching function {tag}")  # `tag` came from the same list

        if qfun(ta) <= 0.0 and ta == t0:
            # The function starts on its switching surface (e.g. v_i = 0 after a switch):
            # look for the first positive value before tb on a finer grid.
            fine = t0 + (tb - t0) * np.arange(1, 257) / 256
            pos = [t for t in fine if qfun(t) > 0.0]
            ta = pos[0] if pos else t0
        if qfun(ta) <= 0.0:
            t_ev = ta
        else:
            # A float without `full_output` (scipy's stubs return every variant's type).
            t_ev = cast(float, brentq(qfun, ta, tb, xtol=4 * np.finfo(float).eps, rtol=4 * np.finfo(float).eps))
        if t_ev >= t1:
            return None
        return cast(float, t_ev), tag  # a float or a numpy float64 (a float too); numpy's stubs say ndarray

    def _check_consistency(self, tol: float = 1e-8):
        """Raise if the state lies clearly on the wrong side of a switching surface.

        That would mean an event was missed (two crossings inside one step), which the
        step cap is meant to prevent; the reference must fail loudly rather than drift.
        """
        m, y = self.m, self.y
        fx, N1, N2, *_ = m.forces(self.t, y[0], y[2])
        for i, (F, N) in enumerate(((fx, N1), (-fx, N2))):
            if self.stuck[i] and m.mu_s * m.normal(N) - abs(F) < -tol:
                raise RuntimeError(f"m{i + 1} stuck beyond its static limit at t={self.t}")
            if not self.stuck[i] and self.slip_dir[i] * y[2 * i + 1] < -tol:
                raise RuntimeError(f"m{i + 1} velocity against its slip direction at t={self.t}")
            if not m.strict and self.n_side[i] * N < -tol:
                raise RuntimeError(f"missed a zero crossing of N{i + 1} at t={self.t}")

    # -- mode re-check after an event ---------------------------------------------------
    def _log(self, t, kind, switch=True):
        self.events.append((t, kind))
        if switch:
            self.n_switches += 1

    def _recheck(self, forced):
        """Apply the transition rules of SPEC section 2 to *both* masses at the current state.

        ``forced`` is the ``(tag, mass)`` of the event that ended the segment; that mass
        switches unconditionally.  The other mass switches if it is within a tiny
        tolerance of its own switching surface (simultaneous events).
        """
        m = self.m
        t, y = self.t, self.y
        fx, N1, N2, *_ = m.forces(t, y[0], y[2])
        for i, (F, N, m_i) in enumerate(((fx, N1, m.m1), (-fx, N2, m.m2))):
            n = m.normal(N)
            is_forced = forced[1] == i and forced[0] in ("stick_limit", "v_zero")
            j = 2 * i + 1
            if self.stuck[i]:
                # stick -> slip when |F_i| exceeds mu_s n_i, in the direction of F_i (eq. 7).
                if is_forced or m.mu_s * n - abs(F) <= _TOL_FORCE:
                    self.stuck[i] = False
                    self.slip_dir[i] = _sign(F)
                    y[j] = 0.0
                    self._log(t, f"m{i + 1} stick->slip")
            else:
                s = self.slip_dir[i]
                v = y[j]
                acc = (F - m.c * v - m.mu_k * n * s) / m_i
                if is_forced or (s * v <= _TOL_VEL and s * acc < 0.0):
                    y[j] = 0.0  # put the state exactly on the switching surface
                    if abs(F) <= m.mu_s * n:
                        self.stuck[i] = True  # slip -> stick (eq. 7)
                        self._log(t, f"m{i + 1} slip->stick")
                    else:
                        new = _sign(F)  # velocity passes through zero, kinetic friction reverses
                        if new != s:
                            self.slip_dir[i] = new
                            self._log(t, f"m{i + 1} reverse", switch=False)

    # -- main loop ----------------------------------------------------------------------
    def advance(self, t_target: float, X_ref: float | None = None, z: float | None = None) -> str:
        """Integrate to ``t_target``; returns ``'time'``, ``'liftoff'`` (strict stop) or ``'target'``.

        With ``X_ref``/``z`` given, stops early when ``|X - X_ref|`` reaches ``z``.
        """
        if self.stopped:
            return "liftoff"
        while self.t < t_target:
            if len(self.segments) >= _MAX_SEGMENTS:
                raise RuntimeError(f"segment cap {_MAX_SEGMENTS} exceeded at t={self.t} (chattering?)")
            self._check_consistency()
            rhs = self._rhs()
            events, tags = self._make_events(rhs, X_ref, z)
            t0 = self.t
            res = solve_ivp(
                rhs,
                (t0, t_target),
                self.y,
                method="DOP853",
                rtol=self.rtol,
                atol=self.atol,
                dense_output=True,
                events=events,
                max_step=self.max_step,
            )
            if res.status == -1:
                raise RuntimeError(f"integration failed at t={t0}: {res.message}")
            t1 = float(res.t[-1])
            y1 = res.y[:, -1].copy()
            tag = None
            missed = self._audit(res.sol, t0, t1, X_ref, z)
            if missed is not None:  # an event scipy did not see (two crossings in one step)
                t1, tag = missed
                y1 = res.sol(t1)
            elif res.status == 0:
                tag = ("time", -1)
            if t1 > t0:
                self.segments.append(_Segment(t0, t1, res.sol, self.stuck, self.slip_dir))
            self.t = t1
            self.y = y1
            if tag == ("time", -1):
                return "time"

            # Zeno guard: a long run of (near) zero-length segments means no progress.
            self._tiny_run = self._tiny_run + 1 if t1 - t0 < _TINY_DT * (1.0 + abs(t0)) else 0
            if self._tiny_run > _MAX_TINY_SEGMENTS:
                raise RuntimeError(f"Zeno/chattering: {self._tiny_run} zero-length segments at t={t1}")

            if tag is None:
                # The terminal event is the one whose (single) root equals t1.
                hit = [k for k, te in enumerate(res.t_events) if len(te) and te[-1] == t1]
                if not hit:
                    hit = [
                        max(range(len(tags)), key=lambda k: res.t_events[k][-1] if len(res.t_events[k]) else -np.inf)
                    ]
                tag = tags[hit[0]]

            if tag[0] == "target":
                return "target"
            if tag[0] == "normal_zero":
                i = tag[1]
                if not self.liftoff:
                    self.liftoff, self.t_liftoff = True, t1
                self.events.append((t1, f"m{i + 1} normal {'off' if self.n_side[i] > 0 else 'on'}"))
                if self.m.strict:
                    self.stopped = True
                    return "liftoff"
                self.n_side[i] = -self.n_side[i]
                self._normal_restart = (i, t1)
            self._recheck(tag)
        return "time"

    # -- sampling -----------------------------------------------------------------------
    def sample(self, ts: np.ndarray):
        """Evaluate the augmented state and mode at times ``ts`` (within the integrated range)."""
        ts = np.asarray(ts, dtype=float)
        out = np.empty((6, ts.size))
        modes = np.empty(ts.size, dtype=int)
        if not self.segments:
            out[:] = self.y[:, None]
            modes[:] = _mode_code(*self.stuck)
            return out, modes
        starts = np.array([s.t0 for s in self.segments])
        idx = np.clip(np.searchsorted(starts, ts, side="right") - 1, 0, len(self.segments) - 1)
        for k in np.unique(idx):
            sel = idx == k
            seg = self.segments[k]
            out[:, sel] = seg.sol(np.clip(ts[sel], seg.t0, seg.t1))
            modes[sel] = seg.mode
        return out, modes

    def stuck_time(self, ta: float, tb: float) -> tuple[float, float]:
        """Total time each mass is stuck within ``[ta, tb]``."""
        tot = [0.0, 0.0]
        for seg in self.segments:
            lo, hi = max(seg.t0, ta), min(seg.t1, tb)
            if hi > lo:
                for i in (0, 1):
                    if seg.stuck[i]:
                        tot[i] += hi - lo
        return tot[0], tot[1]


def reference_natural_frequencies(params: dict) -> tuple[float, float, float]:
    """``(wn1, wn2, wn3)`` of eqs. (11-12) for ``params`` (any subset of ``DEFAULTS``)."""
    return _Model(params, "strict").natural_frequencies()


def reference_simulate(
    params: dict,
    t_end: float,
    save_at=None,
    *,
    contact="strict",
    start: str | tuple[float, float, float, float] = "paper",
    wave=None,
    rtol=1e-11,
    atol=1e-12,
) -> dict:
    """Simulate the exact hybrid model on ``[0, t_end]`` and sample it at ``save_at``.

    Args:
        params: any subset of ``DEFAULTS`` (missing keys take the default).
        t_end: final time.
        save_at: 1-D times in ``[0, t_end]`` (default ``np.linspace(0, t_end, 1001)``).
        contact: ``'strict'`` (``n_i = N_i``, stop at the first lift-off) or ``'paper'``
            (``n_i = |N_i|``, continue but flag lift-off).
        start: ``'paper'`` (eq. 14), ``'relaxed'``, or a state ``(x1, v1, x2, v2)`` at ``t = 0``.
        wave: ``("spline", c)`` for a periodic cubic B-spline of control values ``c`` in the phase, or
            ``(cos, sin)``, the Fourier coefficients of harmonics ``1..H`` of ``omega``:
            ``l0 = lbar + sum_h cos_h cos(h omega t) + sin_h sin(h omega t)`` replaces eq. (13).

    Returns:
        dict with arrays ``t, x1, v1, x2, v2, X, e_d, w, e, mode`` at ``save_at`` and the
        scalars ``liftoff, t_liftoff, n_switches, n_segments, valid_until`` and ``events``
        (list of ``(t, kind)``: stick->slip, slip->stick, reversals, normal-force crossings).
        ``n_switches`` counts stick<->slip changes only (not reversals).  After a strict
        lift-off stop the samples repeat the last valid state.
    """
    model = _Model(params, contact, wave)
    ts = np.linspace(0.0, t_end, 1001) if save_at is None else np.atleast_1d(np.asarray(save_at, dtype=float))
    if ts.ndim != 1 or np.any(ts < 0.0) or np.any(ts > t_end):
        raise ValueError(f"save_at must be a 1-D array of times in [0, t_end={t_end}]")
    solver = _HybridSolver(model, start, rtol, atol)
    solver.advance(float(t_end))
    valid_until = solver.t if solver.stopped else float(t_end)

    ts_eval = np.minimum(ts, valid_until)
    Y, modes = solver.sample(ts_eval)
    x1, v1, x2, v2, e_d, w = Y
    return dict(
        t=ts.copy(),
        x1=x1,
        v1=v1,
        x2=x2,
        v2=v2,
        X=(model.m1 * x1 + model.m2 * x2) / (model.m1 + model.m2),
        e_d=e_d,
        w=w,
        e=model.energy(ts_eval, x1, v1, x2, v2),
        mode=modes,
        liftoff=bool(solver.liftoff),
        t_liftoff=float(solver.t_liftoff),
        n_switches=int(solver.n_switches),
        n_segments=len(solver.segments),
        events=list(solver.events),
        valid_until=float(valid_until),
        contact=contact,
        start=start,
    )


def reference_measure(
    params: dict,
    z=5.0,
    *,
    horizon=2000.0,
    window=25.0,
    contact="strict",
    start: str | tuple[float, float, float, float] = "paper",
    t_start=None,
    wave=None,
    rtol=1e-11,
    atol=1e-12,
) -> dict:
    """Measurements of SPEC section 5 (``start``, ``wave`` as in ``reference_simulate``).

    * ``t_start = 80 * 2 pi / min(wn1, wn2, wn3)`` (eqs. 11-12), unless given.
    * ``tau_z``: first time after ``t_start`` at which ``|X - X(t_start)| = z``, located as an
      event; ``e_z = e_d(t_start + tau_z) - e_d(t_start)`` (eq. 15).  Not reached by
      ``t_start + horizon`` (or a strict lift-off first): ``reached=False``, ``tau_z = e_z = inf``.
    * ``regime`` over ``[t_start, t_start + window]``: 1 (SSL) if either mass is stuck for
      more than 1e-6 in total, 0 (SL) otherwise, -1 if the run stopped (strict lift-off)
      before the window ended (then the stick fractions are NaN).
    * ``mean_speed = (X(t_m) - X(t_start)) / (t_m - t_start)`` with ``t_m = t_start + tau_z`` if
      reached, else the horizon end (or the strict lift-off time; NaN if that precedes t_start).
    """
    model = _Model(params, contact, wave)
    solver = _HybridSolver(model, start, rtol, atol)
    if t_start is None:
        t_start = 80.0 * 2.0 * math.pi / min(model.natural_frequencies())
    t_window = t_start + window
    t_horizon = t_start + horizon
    nan, inf = math.nan, math.inf
    out: dict[str, Any] = dict(
        tau_z=inf,
        e_z=inf,
        reached=False,
        regime=-1,
        mean_speed=nan,
        stick_fraction1=nan,
        stick_fraction2=nan,
        t_start=t_start,
        X_start=nan,
        e_d_start=nan,
    )

    if solver.advance(t_start) == "time":
        X_s, ed_s = float(solver.X), float(solver.y[4])
        out.update(X_start=X_s, e_d_start=ed_s)
        reason = solver.advance(t_horizon, X_ref=X_s, z=z)
        if reason == "target":
            tau = solver.t - t_start
            out.update(tau_z=tau, e_z=float(solver.y[4]) - ed_s, reached=True, mean_speed=float((solver.X - X_s) / tau))
            solver.advance(t_window)  # the regime window may extend beyond tau_z
        else:
            if solver.t > t_start:
                out.update(mean_speed=float((solver.X - X_s) / (solver.t - t_start)))
            solver.advance(t_window)  # only matters if horizon < window
        if not solver.stopped or solver.t >= t_window:
            s1, s2 = solver.stuck_time(t_start, t_window)
            out.update(regime=int(max(s1, s2) > 1e-6), stick_fraction1=s1 / window, stick_fraction2=s2 / window)
    out.update(
        liftoff=bool(solver.liftoff),
        t_liftoff=float(solver.t_liftoff),
        n_segments=len(solver.segments),
        contact=contact,
        start=start,
    )
    return out
