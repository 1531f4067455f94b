"""Independent float64 event-driven reference for hopping bodies (SPEC section 10, issue 27).

Written from SPEC sections 1-5, 8 and 10 with the conventions of ``tests/reference_chain.py``
(its ``chain_config`` dicts are the input); it imports nothing from ``locomotion_jax`` and no
solver code from ``reference_chain``: only numpy and scipy.

API
---
``reference_hop_simulate(cfg, t_end, save_at, *, restitution=0.0, zeno_speed=1e-3, x0=None, v0=None,
y0=None, w0=None, rtol=1e-12, atol=1e-12)`` with ``cfg`` from ``reference_chain.chain_config(...)``,
:func:`paper_config` or :func:`ball_config` (one body, no springs).  Default start: reference_chain's
"paper" start (``x_0 = 0``, ``x_{j+1} = x_j + lbar_j``), ``y = 0``, at rest. ``x0, v0, y0, w0`` (N values, or
one for every body; ``y0 >= 0``) replace parts of it; a body started at ``y0 = 0`` with ``w0 < 0`` lands
at ``t = 0`` (the impact is applied before the first sample, its loss is already in ``e_d(0)``).  Returns a dict:
``t`` (S,); ``x, v, y, w`` (S, N); ``e_d, work, energy`` (S,); ``n_landings`` (N,) and ``flight_time``
(N,) over ``[0, t_end]``; ``max_height`` (N,); ``landings``: list of ``(t, body)``; and also
``apexes`` (list of ``(t, body, height)``, the top of every flight), ``mode`` (S, N) with
0 stuck, 1 slipping, 2 in flight, ``n_segments`` and ``events`` (list of ``(t, text)``).

Model (0-based: bodies i = 0..N-1, spring j joins bodies j and j+1)
-------------------------------------------------------------------
``u = x_{j+1} - x_j``, ``h = d_j + y_{j+1} - y_j``, ``l = sqrt(u^2 + h^2)``, ``T = k_j (l - l0_j(t))``;
force ``T (u, h) / l`` on body j and its opposite on body j+1; force actuator ``+f_j`` on j and
``-f_j`` on j+1 (horizontal).  ``F_i``, ``V_i``: horizontal and vertical (upwards) spring forces on i.

* on the ground (``y = w = 0``), normal force ``N_i = m_i - V_i``; stuck (``v = 0``) while
  ``-mu_s_bwd N <= F <= mu_s_fwd N``; slipping ``m v' = F - c v - sgn(v) mu_dir(|v|) N``
  (Coulomb, or Stribeck ``mu_k + (mu_s - mu_k) exp(-(|v|/v_s)^2)``), as in reference_chain;
* lift-off when ``N_i`` falls through 0; in flight ``m v' = F - c v``, ``m w' = -m + V``, ``y' = w``;
* landing when ``y`` returns to 0 with ``w < 0``: an impact (no impulse through springs).  Rebound
  ``w+ = -e w-``, but plastic (``w+ = 0``, effective ``e = 0``) when ``e |w-| < zeno_speed``.
  Normal impulse ``P_n = m (1 + e_eff) |w-|``; tangential ``P_t = min(m |v-|, mu_k,dir(v-) P_n)``
  against ``v-`` (the constant kinetic coefficient of ``v-``'s direction, also for Stribeck).
  After a plastic impact the body is on the ground if ``N >= 0`` (stuck if ``v+ = 0`` and the static
  condition holds, else slipping), else in flight at once with ``w = 0``.
* energy ``e = sum m (v^2 + w^2)/2 + sum k (l - l0)^2/2 + sum m y``; ``e_d`` integrates friction and
  damping and adds each impact's loss ``m (w-^2 - w+^2)/2 + m (v-^2 - v+^2)/2``; ``work`` integrates
  ``sum -T l0' + f_j (v_j - v_{j+1})``.  ``work = e_d + Delta e`` is the check.

Method
------
One DOP853 integration per segment of constant mode, stepped by hand; after every step all
switching functions are evaluated on 16 points of the dense output, the first crossing is
located with ``brentq``.  Functions (>= 0 while the mode holds): stuck: both static limits and
``N``; slipping: ``sgn v`` times ``v`` (divided by ``t - t0`` when it starts on zero) and ``N``;
in flight: ``y`` where ``w < 0`` (the ascent is masked, so a flight that starts at ``y = 0`` is
not ended at its start; a return is located between the apex, found by ``brentq`` on ``w``, and the
first sample below zero).  After each event every body is re-decided (simultaneous switches).
"""

from __future__ import annotations

import math

import numpy as np
from reference_chain import chain_config
from scipy.integrate import DOP853, OdeSolution
from scipy.linalg import eigh
from scipy.optimize import brentq


__all__ = ["ball_config", "paper_config", "reference_hop_simulate"]

_STUCK, _SLIP, _FLIGHT = 0, 1, 2
_ST_FWD, _ST_BWD, _VEL, _NORM, _LAND = range(5)
_TOL = 1e-10
_TOL_CHECK = 1e-8
_N_SUB = 16
_MAX_SEGMENTS = 200_000
_MAX_TINY = 200


def ball_config(m: float = 1.0, mu_s: float = 0.5, mu_k: float = 0.5, c: float = 0.0) -> dict:
    """One body, no springs, isotropic Coulomb friction (same keys as ``chain_config``)."""
    if not (math.isfinite(m) and m > 0.0):
        raise ValueError(f"m must be > 0, got {m}")
    if not (0.0 <= mu_k <= mu_s):
        raise ValueError(f"need 0 <= mu_k <= mu_s, got mu_k={mu_k}, mu_s={mu_s}")
    if c < 0.0:
        raise ValueError(f"c must be >= 0, got {c}")
    one = lambda v: np.array([float(v)])  # noqa: E731
    none = np.zeros(0)
    return dict(m=one(m), c=one(c), k=none, d=none, lbar=none, omega=0.0, A=np.zeros((0, 1)), B=np.zeros((0, 1)),
                spline=None, actuator="length", mu_s_fwd=one(mu_s), mu_s_bwd=one(mu_s), mu_k_fwd=one(mu_k),
                mu_k_bwd=one(mu_k), v_s=None, friction="coulomb")  # fmt: skip


def paper_config(mhat=0.5, k=50.0, d=0.5, lbar=3.0, c=0.01, mu_s=0.7, mu_k=0.5, omega=10.0, a=0.05) -> dict:
    """The paper's two-mass model as a chain: ``m1 = 2 mhat``, ``m2 = 2 (1 - mhat)``, ``l0 = lbar + a sin(omega t)``."""
    return chain_config([2.0 * mhat, 2.0 * (1.0 - mhat)], k=k, d=d, lbar=lbar, c=c, omega=omega, a=a,
                        mu_s_fwd=mu_s, mu_k_fwd=mu_k)  # fmt: skip


class _Model:
    """Forces of the model, vectorised over samples and in Python floats for the right-hand side."""

    def __init__(self, cfg: dict):
        if cfg.get("spline") is not None:
            raise ValueError("reference_hop supports Fourier actuation only (cfg['spline'] must be None)")
        self.cfg = cfg
        self.n = int(cfg["m"].size)
        self.m = np.asarray(cfg["m"], float)
        self.c = np.asarray(cfg["c"], float)
        self.k = np.asarray(cfg["k"], float)
        self.d = np.asarray(cfg["d"], float)
        self.lbar = np.asarray(cfg["lbar"], float)
        self.A = np.asarray(cfg["A"], float)
        self.B = np.asarray(cfg["B"], float)
        self.omega = float(cfg["omega"])
        self.hw = self.omega * np.arange(1, self.A.shape[1] + 1, dtype=float)
        self.force_act = cfg["actuator"] == "force"
        self.stribeck = cfg["friction"] == "stribeck"
        self.v_s = np.asarray(cfg["v_s"], float) if self.stribeck else None
        self.mu_s_fwd = np.asarray(cfg["mu_s_fwd"], float)
        self.mu_s_bwd = np.asarray(cfg["mu_s_bwd"], float)
        self.mu_k_fwd = np.asarray(cfg["mu_k_fwd"], float)
        self.mu_k_bwd = np.asarray(cfg["mu_k_bwd"], float)

    def actuation(self, t: np.ndarray):
        """``s_j(t)`` and ``s_j'(t)``, shape (N-1, S)."""
        ph = self.hw[:, None] * t[None, :]
        cs, sn = np.cos(ph), np.sin(ph)
        s = self.A @ cs + self.B @ sn
        sd = (self.B * self.hw) @ cs - (self.A * self.hw) @ sn
        return s, sd

    def forces(self, t: np.ndarray, x: np.ndarray, y: np.ndarray):
        """``F, V`` (N, S) and per spring ``T, l, l0, l0', f`` (N-1, S) at samples."""
        n = self.n
        S = t.size
        F = np.zeros((n, S))
        V = np.zeros((n, S))
        if n == 1:
            z = np.zeros((0, S))
            return F, V, z, z, z, z, z
        s, sd = self.actuation(t)
        u = x[1:] - x[:-1]
        h = self.d[:, None] + y[1:] - y[:-1]
        ell = np.sqrt(u * u + h * h)
        if self.force_act:
            l0 = np.broadcast_to(self.lbar[:, None], s.shape)
            l0d = np.zeros_like(s)
            f = s
        else:
            l0 = self.lbar[:, None] + s
            l0d = sd
            f = np.zeros_like(s)
        T = self.k[:, None] * (ell - l0)
        hx = T * u / ell + f
        hv = T * h / ell
        F[:-1] += hx
        F[1:] -= hx
        V[:-1] += hv
        V[1:] -= hv
        return F, V, T, ell, l0, l0d, f

    def energy(self, t, x, v, y, w) -> np.ndarray:
        _, _, _, ell, l0, _, _ = self.forces(t, x, y)
        m = self.m[:, None]
        kin = 0.5 * np.sum(m * (v * v + w * w), axis=0)
        spring = 0.5 * np.sum(self.k[:, None] * (ell - l0) ** 2, axis=0)
        return kin + spring + np.sum(m * y, axis=0)

    def mu_kin(self, i: int, sign: float, speed: float) -> float:
        mk = self.mu_k_fwd[i] if sign > 0 else self.mu_k_bwd[i]
        if not self.stribeck:
            return float(mk)
        ms = self.mu_s_fwd[i] if sign > 0 else self.mu_s_bwd[i]
        assert self.v_s is not None
        return float(mk + (ms - mk) * math.exp(-((speed / self.v_s[i]) ** 2)))


class _Segment:
    __slots__ = ("t0", "t1", "mode", "sol", "acc0")

    def __init__(self, t0, t1, mode, sol, acc0):
        self.t0, self.t1, self.mode, self.sol, self.acc0 = t0, t1, mode.copy(), sol, acc0.copy()


class _Solver:
    """State ``(x, v, y, w, e_d, work)``, 4N + 2; mode per body (stuck, slipping, flight) and slip direction."""

    def __init__(self, model: _Model, e: float, zeno: float, x0, v0, y0, w0, rtol, atol):
        self.md = model
        n = self.n = model.n
        self.e, self.zeno = e, zeno
        self.rtol, self.atol = rtol, atol
        self.t = 0.0
        self.Y = np.zeros(4 * n + 2)
        self.Y[:n], self.Y[n : 2 * n], self.Y[2 * n : 3 * n], self.Y[3 * n : 4 * n] = x0, v0, y0, w0
        self.mode = np.full(n, _SLIP)
        self._pending: list[int] = []  # bodies that start slipping from rest at self.t (see _arm)
        self.sdir = np.ones(n)
        self.segments: list[_Segment] = []
        self.events: list[tuple[float, str]] = []
        self.landings: list[tuple[float, int]] = []
        self.apexes: list[tuple[float, int, float]] = []
        self.max_height = np.array(y0, float).copy()
        self.flight_time = np.zeros(n)
        self._restart: dict[int, float] = {}
        self._h = None
        self._tiny = 0
        w_fast = max(model.hw.max() if model.hw.size else 0.0, self._highest_freq(), 1e-3)
        self.max_step = 2.0 * math.pi / w_fast / 8.0
        self._frac = np.arange(1, _N_SUB + 1) / _N_SUB
        F, V = self._fv()
        N = model.m - V
        start_slip = []
        for i in range(n):
            yi, wi, vi = self.Y[2 * n + i], self.Y[3 * n + i], self.Y[n + i]
            if yi > 0.0 or wi > 0.0 or (yi == 0.0 and wi == 0.0 and N[i] <= 0.0):
                self.mode[i] = _FLIGHT
            elif wi < 0.0:
                self.mode[i] = _FLIGHT
                self._impact(i)
            elif vi != 0.0:
                self.mode[i], self.sdir[i] = _SLIP, math.copysign(1.0, vi)
            elif -model.mu_s_bwd[i] * N[i] <= F[i] <= model.mu_s_fwd[i] * N[i]:
                self.mode[i] = _STUCK
            else:
                self.mode[i], self.sdir[i] = _SLIP, 1.0 if F[i] > 0 else -1.0
                start_slip.append(i)
        self._arm(start_slip + self._pending)

    def _highest_freq(self) -> float:
        m, k = self.md.m, self.md.k
        n = self.n
        if n < 2:
            return 0.0
        K = np.zeros((n, n))
        for j, kj in enumerate(k):
            K[j : j + 2, j : j + 2] += kj * np.array([[1.0, -1.0], [-1.0, 1.0]])
        return math.sqrt(max(float(eigh(K, np.diag(m), eigvals_only=True)[-1]), 0.0))

    def _fv(self, t=None, Y=None):
        t = self.t if t is None else t
        Y = self.Y if Y is None else Y
        n = self.n
        F, V, *_ = self.md.forces(np.array([t]), Y[:n, None], Y[2 * n : 3 * n, None])
        return F[:, 0], V[:, 0]

    # -- right-hand side ------------------------------------------------------------------
    def _rhs(self):
        md, n = self.md, self.n
        m, c = md.m.tolist(), md.c.tolist()
        k, d, lbar = md.k.tolist(), md.d.tolist(), md.lbar.tolist()
        hw = md.hw.tolist()
        A, B = md.A.tolist(), md.B.tolist()
        mode = self.mode.tolist()
        sdir = self.sdir.tolist()
        mus = [md.mu_k_fwd[i] if sdir[i] > 0 else md.mu_k_bwd[i] for i in range(n)]
        drop = [(md.mu_s_fwd[i] if sdir[i] > 0 else md.mu_s_bwd[i]) - mus[i] for i in range(n)]
        inv_vs2 = (1.0 / md.v_s**2).tolist() if md.v_s is not None else None
        force_act = md.force_act
        H = range(len(hw))

        def rhs(t, Yv):
            yl = Yv.tolist()
            x, v, y, w = yl[:n], yl[n : 2 * n], yl[2 * n : 3 * n], yl[3 * n : 4 * n]
            v = [0.0 if mode[i] == _STUCK else v[i] for i in range(n)]
            cs = [math.cos(q * t) for q in hw]
            sn = [math.sin(q * t) for q in hw]
            F = [0.0] * n
            V = [0.0] * n
            power = 0.0
            for j in range(n - 1):
                s = 0.0
                sd = 0.0
                for h in H:
                    s += A[j][h] * cs[h] + B[j][h] * sn[h]
                    sd += hw[h] * (B[j][h] * cs[h] - A[j][h] * sn[h])
                u = x[j + 1] - x[j]
                hz = d[j] + y[j + 1] - y[j]
                ell = math.sqrt(u * u + hz * hz)
                if force_act:
                    T = k[j] * (ell - lbar[j])
                    hx = T * u / ell + s
                    power += s * (v[j] - v[j + 1])
                else:
                    T = k[j] * (ell - lbar[j] - s)
                    hx = T * u / ell
                    power -= T * sd
                hv = T * hz / ell
                F[j] += hx
                F[j + 1] -= hx
                V[j] += hv
                V[j + 1] -= hv
            dv = [0.0] * n
            dy = [0.0] * n
            dw = [0.0] * n
            ed = 0.0
            for i in range(n):
                vi = v[i]
                if mode[i] == _SLIP:
                    mu = mus[i]
                    if inv_vs2 is not None:
                        mu += drop[i] * math.exp(-vi * vi * inv_vs2[i])
                    fr = sdir[i] * mu * (m[i] - V[i])
                    dv[i] = (F[i] - c[i] * vi - fr) / m[i]
                    ed += fr * vi + c[i] * vi * vi
                elif mode[i] == _FLIGHT:
                    dv[i] = (F[i] - c[i] * vi) / m[i]
                    dy[i] = w[i]
                    dw[i] = (V[i] - m[i]) / m[i]
                    ed += c[i] * vi * vi
            return np.array(v + dv + dy + dw + [ed, power])

        return rhs

    # -- switching functions --------------------------------------------------------------
    def _switch(self, t: np.ndarray, Y: np.ndarray, t0: float) -> np.ndarray:
        md, n = self.md, self.n
        F, V, *_ = md.forces(t, Y[:n], Y[2 * n : 3 * n])
        N = md.m[:, None] - V
        G = np.full((5 * n, t.size), np.inf)
        st = self.mode == _STUCK
        sl = self.mode == _SLIP
        gr = st | sl
        fl = self.mode == _FLIGHT
        G[0:n][st] = (md.mu_s_fwd[:, None] * N - F)[st]
        G[n : 2 * n][st] = (F + md.mu_s_bwd[:, None] * N)[st]
        G[2 * n : 3 * n][sl] = (self.sdir[:, None] * Y[n : 2 * n])[sl]
        G[3 * n : 4 * n][gr] = N[gr]
        yy, ww = Y[2 * n : 3 * n], Y[3 * n : 4 * n]
        G[4 * n : 5 * n][fl] = np.where(ww < 0.0, yy, np.inf)[fl]
        if self._restart:
            dt = t - t0
            for row, rate in self._restart.items():
                G[row] = np.where(dt > 0.0, G[row] / np.where(dt > 0.0, dt, 1.0), rate)
        return G

    def _arm(self, bodies):
        if not bodies:
            return
        acc = self._rhs()(self.t, self.Y)[self.n : 2 * self.n]
        for i in bodies:
            self._restart[_VEL * self.n + i] = float(self.sdir[i] * acc[i])

    def _row_value(self, row, t, Yt, t0):
        return float(self._switch(np.array([t]), Yt[:, None], t0)[row, 0])

    def _locate(self, p, row, tl, tr, t0) -> float:
        n = self.n
        block, i = divmod(row, n)
        if block == _LAND:
            yl, wl = p(tl)[2 * n + i], p(tl)[3 * n + i]
            if wl >= 0.0:  # the left end is in the ascent: find the apex first
                if p(tr)[3 * n + i] >= 0.0:
                    return tr
                ta = self._root(lambda s: p(s)[3 * n + i], tl, tr)
                if p(ta)[2 * n + i] <= 0.0:
                    return ta
                tl = ta
            elif yl <= 0.0:
                return tl
            return self._root(lambda s: p(s)[2 * n + i], tl, tr)
        gl = self._row_value(row, tl, p(tl), t0)  # a restart row gives its rate at t0
        if gl <= 0.0:
            return tl
        return self._root(lambda s: self._row_value(row, s, p(s), t0), tl, tr)

    @staticmethod
    def _root(g, a, b) -> float:
        eps = 4 * np.finfo(float).eps
        if g(b) > 0.0:
            return b
        return float(brentq(g, a, b, xtol=eps * max(1.0, abs(a)), rtol=eps))  # type: ignore[arg-type]

    # -- one segment ----------------------------------------------------------------------
    def _segment(self, t_target: float):
        n = self.n
        t0 = self.t
        G0 = self._switch(np.array([t0]), self.Y[:, None], t0)[:, 0]
        if np.any(G0 < -_TOL_CHECK):
            row = int(np.argmin(G0))
            raise RuntimeError(f"missed event at t={t0}: row {row} (block {row // n}, body {row % n}) = {G0[row]:.3e}")
        acc0 = self.Y[4 * n :].copy()
        y0 = self.Y.copy()
        y0[4 * n :] = 0.0
        first = None if self._h is None else min(self._h, self.max_step, t_target - t0)
        sv = DOP853(self._rhs(), t0, y0, t_bound=t_target, rtol=self.rtol, atol=self.atol, max_step=self.max_step,
                    first_step=first)  # fmt: skip
        ts, interps = [t0], []
        hit, t_hit, y_hit = None, t_target, None
        gprev = G0
        fl = np.nonzero(self.mode == _FLIGHT)[0]
        while sv.status == "running":
            msg = sv.step()
            if sv.status == "failed":
                raise RuntimeError(f"DOP853 failed at t={sv.t}: {msg}")
            assert sv.t_old is not None
            ta, tb = sv.t_old, sv.t
            p = sv.dense_output()
            grid = ta + (tb - ta) * self._frac
            grid[-1] = tb
            Yg = p(grid)
            Yg[:, -1] = sv.y
            G = self._switch(grid, Yg, t0)
            neg = G < 0.0
            if neg.any():
                rows = np.nonzero(neg.any(axis=1))[0]
                first_neg = np.argmax(neg[rows], axis=1)
                kmin = int(first_neg.min())
                best = math.inf
                for row in rows[first_neg == kmin]:
                    tl = grid[kmin - 1] if kmin > 0 else ta
                    tr = self._locate(p, int(row), tl, grid[kmin], t0)
                    if tr < best:
                        best, hit = tr, int(row)
                t_hit = best
                y_hit = p(t_hit) if t_hit > ta else np.array(sv.y_old, float)
                self._apex(p, fl, ta, t_hit)
                if t_hit > ta:
                    ts.append(t_hit)
                    interps.append(p)
                break
            self._apex(p, fl, ta, tb)
            ts.append(tb)
            interps.append(p)
            gprev = G[:, -1]
            self._h = sv.h_abs
        del gprev
        if hit is None:
            t_hit, y_hit = sv.t, sv.y.copy()
        if t_hit > t0:
            self.segments.append(_Segment(t0, t_hit, self.mode, OdeSolution(np.array(ts), interps), acc0))
            self.flight_time[fl] += t_hit - t0
        self.t = float(t_hit)
        self.Y = np.array(y_hit, float)
        self.Y[4 * n :] += acc0
        self._restart = {}
        return hit

    def _apex(self, p, fl, ta, tb):
        """Record the tops of flights (``w`` from >= 0 to < 0) within ``[ta, tb]``, and the largest height."""
        n = self.n
        if tb <= ta or fl.size == 0:
            return
        grid = np.linspace(ta, tb, _N_SUB + 1)
        Yg = p(grid)
        for i in fl:
            yv, wv = Yg[2 * n + i], Yg[3 * n + i]
            self.max_height[i] = max(self.max_height[i], float(yv.max()))
            for q in range(_N_SUB):
                if wv[q] >= 0.0 > wv[q + 1]:
                    tap = self._root(lambda s, i=i: p(s)[3 * n + i], grid[q], grid[q + 1])
                    yap = float(p(tap)[2 * n + i])
                    self.apexes.append((tap, int(i), yap))
                    self.max_height[i] = max(self.max_height[i], yap)

    # -- events ---------------------------------------------------------------------------
    def _impact(self, i: int):
        """Landing of body ``i`` (SPEC section 10): restitution with the Zeno rule, Coulomb-bounded tangent impulse."""
        n, md = self.n, self.md
        m = float(md.m[i])
        vm, wm = float(self.Y[n + i]), float(self.Y[3 * n + i])
        e = self.e if self.e * abs(wm) >= self.zeno else 0.0
        wp = -e * wm
        Pn = m * (1.0 + e) * abs(wm)
        mu = float(md.mu_k_fwd[i] if vm > 0 else md.mu_k_bwd[i])
        Pt = min(m * abs(vm), mu * Pn)
        vp = 0.0 if Pt >= m * abs(vm) else vm - math.copysign(Pt, vm) / m
        self.Y[4 * n] += 0.5 * m * (wm * wm - wp * wp) + 0.5 * m * (vm * vm - vp * vp)
        self.Y[n + i], self.Y[2 * n + i], self.Y[3 * n + i] = vp, 0.0, wp
        self.landings.append((self.t, i))
        self.events.append((self.t, f"b{i} lands w-={wm:.6g} v-={vm:.6g} w+={wp:.6g} v+={vp:.6g}"))
        if wp > 0.0:
            self.mode[i] = _FLIGHT
            return
        F, V = self._fv()
        N = m - V[i]
        if N < 0.0:
            self.mode[i] = _FLIGHT
        elif vp != 0.0:
            self.mode[i], self.sdir[i] = _SLIP, math.copysign(1.0, vp)
        elif -md.mu_s_bwd[i] * N <= F[i] <= md.mu_s_fwd[i] * N:
            self.mode[i] = _STUCK
        else:
            self.mode[i], self.sdir[i] = _SLIP, 1.0 if F[i] > 0 else -1.0
            self._pending.append(i)

    def _redecide(self, row: int):
        n, md = self.n, self.md
        block, forced = divmod(row, n)
        self._pending = []
        F, V = self._fv()
        N = md.m - V
        # Landings and lift-offs first (they change the bodies' modes), then stick and slip.
        for i in range(n):
            yi, wi = self.Y[2 * n + i], self.Y[3 * n + i]
            if self.mode[i] == _FLIGHT:
                if (block == _LAND and forced == i) or (yi <= _TOL and wi < 0.0):
                    self._impact(i)
            elif (block == _NORM and forced == i) or N[i] <= _TOL * 1e-2:
                if block == _NORM and forced == i or self._normal_falling(i):
                    self.mode[i] = _FLIGHT
                    self.Y[3 * n + i] = 0.0
                    self.events.append((self.t, f"b{i} lifts off"))
        acc = self._rhs()(self.t, self.Y)[n : 2 * n]
        for i in range(n):
            if self.mode[i] == _FLIGHT or i in self._pending:
                continue
            hi, lo = md.mu_s_fwd[i] * N[i], -md.mu_s_bwd[i] * N[i]
            if self.mode[i] == _STUCK:
                up = (block == _ST_FWD and forced == i) or hi - F[i] <= _TOL
                down = (block == _ST_BWD and forced == i) or F[i] - lo <= _TOL
                if up or down:
                    self.mode[i] = _SLIP
                    self.sdir[i] = 1.0 if (up and not down) or (up and down and F[i] >= 0.0) else -1.0
                    self.Y[n + i] = 0.0
                    self._pending.append(i)
            else:
                s, v = self.sdir[i], self.Y[n + i]
                if (block == _VEL and forced == i) or (s * v <= _TOL and s * acc[i] < 0.0):
                    self.Y[n + i] = 0.0
                    if lo <= F[i] <= hi:
                        self.mode[i] = _STUCK
                    else:
                        self.sdir[i] = 1.0 if F[i] > hi else -1.0
                        self._pending.append(i)
        self._arm(self._pending)

    def _normal_falling(self, i: int) -> bool:
        """Whether ``N_i`` decreases along the current velocities (a forward difference; only its sign is used)."""
        n = self.n
        dt = 1e-7
        Y2 = self.Y.copy()
        Y2[:n] += dt * self.Y[n : 2 * n]
        Y2[2 * n : 3 * n] += dt * self.Y[3 * n : 4 * n]
        _, V2 = self._fv(self.t + dt, Y2)
        return bool(self.md.m[i] - V2[i] < self.md.m[i] - self._fv()[1][i])

    def advance(self, t_end: float):
        n = self.n
        self._pending = []
        while self.t < t_end:
            if len(self.segments) > _MAX_SEGMENTS:
                raise RuntimeError(f"segment cap exceeded at t={self.t}")
            t0 = self.t
            row = self._segment(t_end)
            if row is None:
                return
            self._tiny = self._tiny + 1 if self.t - t0 < 1e-12 * (1 + abs(t0)) else 0
            if self._tiny > _MAX_TINY:
                raise RuntimeError(f"Zeno/chattering: {self._tiny} zero-length segments at t={self.t}")
            self._redecide(row)
        del n

    def sample(self, ts: np.ndarray):
        n = self.n
        out = np.empty((4 * n + 2, ts.size))
        mode = np.empty((ts.size, n), dtype=int)
        if not self.segments:
            out[:] = self.Y[:, None]
            mode[:] = self.mode
            return out, mode
        starts = np.array([s.t0 for s in self.segments])
        idx = np.clip(np.searchsorted(starts, ts, side="right") - 1, 0, len(self.segments) - 1)
        for kseg in np.unique(idx):
            sel = idx == kseg
            seg = self.segments[kseg]
            out[:, sel] = seg.sol(np.clip(ts[sel], seg.t0, seg.t1))
            out[4 * n :, sel] += seg.acc0[:, None]
            mode[sel] = seg.mode
        # The end state (after a final event at t_end) wins for samples at t_end.
        at_end = ts >= self.t
        if at_end.any():
            out[:, at_end] = self.Y[:, None]
            mode[at_end] = self.mode
        out[n : 2 * n][(mode == _STUCK).T] = 0.0
        grounded = (mode != _FLIGHT).T
        out[2 * n : 3 * n][grounded] = 0.0
        out[3 * n : 4 * n][grounded] = 0.0
        return out, mode


def reference_hop_simulate(
    cfg: dict,
    t_end: float,
    save_at,
    *,
    restitution: float = 0.0,
    zeno_speed: float = 1e-3,
    x0=None,
    v0=None,
    y0=None,
    w0=None,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> dict:
    """Simulate the hopping model on ``[0, t_end]`` and sample it at ``save_at`` (see the module docstring).

    Raises:
        ValueError: restitution outside [0, 1], zeno_speed <= 0, a negative initial height, bad shapes.
    """
    md = _Model(cfg)
    n = md.n
    if not (0.0 <= restitution <= 1.0):
        raise ValueError(f"restitution must be in [0, 1], got {restitution}")
    if not (zeno_speed > 0.0):
        raise ValueError(f"zeno_speed must be > 0, got {zeno_speed}")
    t_end = float(t_end)
    ts = np.atleast_1d(np.asarray(save_at, dtype=float))
    if ts.ndim != 1 or np.any(ts < 0.0) or np.any(ts > t_end):
        raise ValueError(f"save_at must be 1-D times in [0, t_end={t_end}]")

    def vec(name, val, default):
        a = np.array(default if val is None else val, dtype=float).reshape(-1)
        if a.size == 1 and n > 1:
            a = np.full(n, float(a[0]))
        if a.shape != (n,) or not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite with one value per body ({n}), got {val}")
        return a

    xs = vec("x0", x0, np.concatenate(([0.0], np.cumsum(md.lbar))))
    vs = vec("v0", v0, np.zeros(n))
    ys = vec("y0", y0, np.zeros(n))
    wsv = vec("w0", w0, np.zeros(n))
    if np.any(ys < 0.0):
        i = int(np.argmax(ys < 0.0))
        raise ValueError(f"y0[{i}] must be >= 0, got {ys[i]}")
    sv = _Solver(md, float(restitution), float(zeno_speed), xs, vs, ys, wsv, rtol, atol)
    sv.advance(t_end)
    Y, mode = sv.sample(ts)
    x, v, y, w = Y[:n], Y[n : 2 * n], Y[2 * n : 3 * n], Y[3 * n : 4 * n]
    counts = np.zeros(n, dtype=int)
    for _, i in sv.landings:
        counts[i] += 1
    return dict(
        t=ts.copy(),
        x=x.T.copy(),
        v=v.T.copy(),
        y=y.T.copy(),
        w=w.T.copy(),
        e_d=Y[4 * n].copy(),
        work=Y[4 * n + 1].copy(),
        energy=md.energy(ts, x, v, y, w),
        n_landings=counts,
        flight_time=sv.flight_time.copy(),
        max_height=sv.max_height.copy(),
        landings=list(sv.landings),
        apexes=list(sv.apexes),
        mode=mode,
        n_segments=len(sv.segments),
        events=list(sv.events),
    )
