"""Independent event-driven float64 reference for hopping: lift-off, flight and landing (SPEC section 10).

Written only from SPEC.md sections 1-5, 8 and 10.  It imports nothing from ``locomotion_jax``;
from ``tests/reference_chain.py`` it takes only the configuration helper ``chain_config`` (and the
frequency used for the step cap), never its solver.  Only numpy and scipy.

API
---
``reference_hop_simulate(cfg, t_end, save_at, *, restitution=0.0, zeno_speed=1e-3, x0=None, v0=None,
y0=None, w0=None, rtol=1e-12, atol=1e-12) -> dict``

* ``cfg``: a :func:`reference_chain.chain_config` dict (N >= 2 bodies, springs between neighbours),
  :func:`paper_config` (the paper's two-mass model) or :func:`ball_config` (one body, no spring).
* ``save_at``: 1-D times in ``[0, t_end]`` (any order).
* Start (defaults): the paper's start of SPEC section 8 (``x_0 = 0``, ``x_{j+1} = x_j + lbar_j``) at
  ``y = 0``, at rest; ``x0, v0, y0, w0`` (length N) replace any part of it (``y0 >= 0``).
* Returns a dict: ``t`` (S,); ``x, v, y, w`` (S, N); ``e_d, work, energy`` (S,); over ``[0, t_end]``
  ``n_landings`` (N,) ints, ``flight_time`` (N,), ``max_height`` (N,), ``landings`` (list of
  ``(t, body)``), and for tests ``impacts`` (list of dicts ``t, body, v_minus, w_minus, v_plus,
  w_plus, plastic``), ``apexes`` (list of ``(t, body, y)``, the tops of flight arcs), ``n_segments``.

Model (0-based: bodies i = 0..N-1, spring j joins bodies j and j+1)
--------------------------------------------------------------------
``u_j = x_{j+1} - x_j``, ``h_j = d_j + y_{j+1} - y_j``, ``l_j = sqrt(u_j^2 + h_j^2)``,
``T_j = k_j (l_j - l0_j(t))``.  Spring j pushes body j by ``T_j (u_j, h_j) / l_j`` and body j+1 by its
opposite; a force actuator adds ``+f_j`` (horizontal) on body j and ``-f_j`` on body j+1.  ``F_i``
and ``V_i`` are the resulting horizontal and vertical (upwards positive) forces on body i.  The
actuation (Fourier series in ``omega t``, length or force actuator) is ``reference_chain``'s.

Modes per body:

* stuck: ``y = w = 0``, ``v = 0``, valid while ``-mu_s_bwd N_i <= F_i <= mu_s_fwd N_i`` and ``N_i >= 0``,
  ``N_i = m_i - V_i``;
* slipping in direction ``s = sgn v``: ``y = w = 0``,
  ``m_i v_i' = F_i - c_i v_i - s mu_dir(|v_i|) N_i`` (Coulomb, or the Stribeck law of reference_chain);
* in flight: ``m_i v_i' = F_i - c_i v_i``, ``m_i w_i' = -m_i + V_i``, no friction.

Events: a stuck body leaves a static limit (slips that way) or its ``N_i`` reaches 0; a slipping
body's ``v_i`` reaches 0 (sticks if the static condition holds, else slips the way ``F_i`` pushes)
or its ``N_i`` reaches 0; a grounded body whose ``N_i`` falls through 0 lifts off (flight from
``w = 0``); a flying body lands when ``y_i`` returns to 0 (``w_i < 0``).  After every event every body
is re-decided: those within a tiny tolerance of their own switching surface switch too.

Impact at landing (springs transmit no impulse): ``w+ = -e w-`` with ``e = restitution``, normal
impulse ``P_n = m (1 + e) |w-|``; tangential impulse ``P_t = min(m |v-|, mu_k P_n)`` against ``v-``,
with the constant kinetic coefficient of ``v-``'s direction (``mu_k_fwd`` or ``mu_k_bwd``).  Zeno
rule: when the rebound speed ``e |w-|`` is below ``zeno_speed`` the impact is plastic (``w+ = 0``,
``P_n = m |w-|``).  After a plastic impact the body stays on the ground if ``N_i >= 0`` there (stuck
when ``v+ = 0`` and the static condition holds, else slipping), otherwise it flies on at once from
``w = 0``.

Energy: ``e = sum m_i (v_i^2 + w_i^2)/2 + sum k_j (l_j - l0_j)^2/2 + sum m_i y_i``; ``e_d`` integrates
``sum_slipping mu N |v| + sum_i c_i v_i^2`` and adds each impact's loss ``m (w-^2 - w+^2)/2 +
m (v-^2 - v+^2)/2``; ``work`` integrates ``sum_j -T_j dl0_j/dt + f_j (v_j - v_{j+1})``, so that
``work = e_d + e(t) - e(0)`` is a real check.

Method
------
One DOP853 integration per segment of constant modes, stepped by hand: after each step all switching
functions are evaluated on 16 points of the dense output and the first crossing is located with
``brentq``.  A function that is zero where its segment starts (the velocity of a body that has just
started to slip, the height of a body that has just left the ground) is divided by ``(t - t0)^p``,
``p`` the order of its first non-vanishing derivative there, so that a return (a landing, a velocity
reversal) is located and the start is not.  The step is capped at 1/8 of the shortest period
(actuation and free-chain frequencies).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from reference_chain import chain_config
from scipy.integrate import DOP853
from scipy.optimize import brentq


__all__ = ["ball_config", "paper_config", "reference_hop_simulate"]

_TOL = 1e-10  # re-decision tolerance of the bodies that did not trigger an event
_N_SUB = 16
_MAX_SEGMENTS = 200_000

STICK, SLIP, FLY = 0, 1, 2


def ball_config(m: float = 1.0, mu_s: float = 0.7, mu_k: float = 0.5, c: float = 0.0) -> dict:
    """One body without springs (``N = 1``): mass ``m``, isotropic Coulomb friction, damping ``c``."""
    if not (math.isfinite(m) and m > 0.0):
        raise ValueError(f"m must be > 0, got {m}")
    if not (0.0 <= mu_k <= mu_s):
        raise ValueError(f"need 0 <= mu_k <= mu_s, got mu_k={mu_k}, mu_s={mu_s}")
    if c < 0.0:
        raise ValueError(f"c must be >= 0, got {c}")
    one = lambda v: np.array([float(v)])  # noqa: E731
    return dict(
        m=one(m),
        c=one(c),
        k=np.zeros(0),
        d=np.zeros(0),
        lbar=np.zeros(0),
        A=np.zeros((0, 1)),
        B=np.zeros((0, 1)),
        omega=0.0,
        actuator="length",
        mu_s_fwd=one(mu_s),
        mu_s_bwd=one(mu_s),
        mu_k_fwd=one(mu_k),
        mu_k_bwd=one(mu_k),
        v_s=None,
        friction="coulomb",
        spline=None,
    )


def paper_config(
    mhat: float = 0.5,
    k: float = 50.0,
    d: float = 0.5,
    lbar: float = 3.0,
    c: float = 0.01,
    mu_s: float = 0.7,
    mu_k: float = 0.5,
    omega: float = 10.0,
    a: float = 0.05,
) -> dict:
    """The paper's two-mass model (SPEC section 1) as a chain: ``m1 = 2 mhat``, ``m2 = 2 (1 - mhat)``, one spring
    with ``l0(t) = lbar + a sin(omega t)``."""
    if not (0.0 < mhat < 1.0):
        raise ValueError(f"mhat must be in (0, 1), got {mhat}")
    return chain_config(
        masses=[2.0 * mhat, 2.0 * (1.0 - mhat)],
        k=k,
        d=d,
        lbar=lbar,
        c=c,
        omega=omega,
        a=a,
        mu_s_fwd=mu_s,
        mu_k_fwd=mu_k,
    )


class _Model:
    """Forces of the hopping chain on ``S`` samples: positions (N, S), times (S,)."""

    def __init__(self, cfg: dict):
        if cfg.get("spline") is not None:
            raise ValueError("spline actuation is not supported by reference_hop")
        self.n = int(np.asarray(cfg["m"]).size)
        col = lambda v: np.asarray(v, dtype=float).reshape(-1, 1)  # noqa: E731
        self.m, self.c = col(cfg["m"]), col(cfg["c"])
        self.k, self.d, self.lbar = col(cfg["k"]), col(cfg["d"]), col(cfg["lbar"])
        self.mu_s_fwd, self.mu_s_bwd = col(cfg["mu_s_fwd"]), col(cfg["mu_s_bwd"])
        self.mu_k_fwd, self.mu_k_bwd = col(cfg["mu_k_fwd"]), col(cfg["mu_k_bwd"])
        self.stribeck = cfg["friction"] == "stribeck"
        self.v_s = col(cfg["v_s"]) if self.stribeck else None
        self.omega = float(cfg["omega"])
        self.A = np.asarray(cfg["A"], dtype=float)
        self.B = np.asarray(cfg["B"], dtype=float)
        harm = np.arange(1, self.A.shape[1] + 1, dtype=float)
        self.hw = (harm * self.omega)[:, None]
        self.force_act = cfg["actuator"] == "force"
        ns = self.n - 1
        self.D = np.zeros((self.n, max(ns, 0)))
        if ns > 0:
            self.D[np.arange(ns), np.arange(ns)] = 1.0
            self.D[np.arange(1, self.n), np.arange(ns)] = -1.0
        self.cfg = cfg

    def actuation(self, t: np.ndarray):
        ph = self.hw * t[None, :]
        cs, sn = np.cos(ph), np.sin(ph)
        s = self.A @ cs + self.B @ sn
        sd = (self.B * self.hw.T) @ cs - (self.A * self.hw.T) @ sn
        return s, sd

    def forces(self, t: np.ndarray, x: np.ndarray, y: np.ndarray):
        """``(F, V, T, l, l0, l0dot, f)``: forces on bodies (N, S), per spring (N-1, S)."""
        s, sd = self.actuation(t)
        if self.force_act:
            l0 = np.broadcast_to(self.lbar, s.shape)
            l0dot = np.zeros_like(s)
            f = s
        else:
            l0 = self.lbar + s
            l0dot = sd
            f = np.zeros_like(s)
        u = x[1:] - x[:-1]
        h = self.d + y[1:] - y[:-1]
        ell = np.sqrt(u * u + h * h)
        T = self.k * (ell - l0)
        F = self.D @ (T * u / ell + f)
        V = self.D @ (T * h / ell)
        return F, V, T, ell, l0, l0dot, f

    def kinetic_mu(self, sigma: np.ndarray, speed: np.ndarray) -> np.ndarray:
        fwd = sigma > 0
        mu_k = np.where(fwd, self.mu_k_fwd, self.mu_k_bwd)
        if not self.stribeck:
            return np.broadcast_to(mu_k, speed.shape)
        mu_s = np.where(fwd, self.mu_s_fwd, self.mu_s_bwd)
        return mu_k + (mu_s - mu_k) * np.exp(-((speed / self.v_s) ** 2))

    def energy(self, t, x, v, y, w) -> np.ndarray:
        _, _, _, ell, l0, _, _ = self.forces(t, x, y)
        kin = 0.5 * np.sum(self.m * (v * v + w * w), axis=0)
        return kin + 0.5 * np.sum(self.k * (ell - l0) ** 2, axis=0) + np.sum(self.m * y, axis=0)


class _Solver:
    def __init__(self, model: _Model, rtol: float, atol: float, e: float, zeno: float):
        self.mdl = model
        self.n = model.n
        self.rtol, self.atol = rtol, atol
        self.e, self.zeno = e, zeno
        cfg = model.cfg
        freqs = [model.omega * model.A.shape[1]]
        if self.n >= 2:
            K = np.zeros((self.n, self.n))
            for j, kj in enumerate(cfg["k"]):
                K[j : j + 2, j : j + 2] += kj * np.array([[1.0, -1.0], [-1.0, 1.0]])
            lam = np.linalg.eigvalsh(K / np.sqrt(np.outer(cfg["m"], cfg["m"])))
            freqs.append(math.sqrt(max(float(lam[-1]), 0.0)))
        fmax = max(freqs)
        self.max_step = 2.0 * math.pi / fmax / 8.0 if fmax > 0 else np.inf
        self.mode = np.zeros(self.n, dtype=int)
        self.sigma = np.zeros(self.n)  # slip direction
        self.power = np.zeros(self.n, dtype=int)  # divisor power of the body's own zero-start function
        self.e_d = 0.0
        self.work = 0.0
        self.impacts: list[dict[str, Any]] = []
        self.apexes: list[tuple[float, int, float]] = []
        self.flight_time = np.zeros(self.n)
        self.max_height = np.zeros(self.n)
        self.n_segments = 0

    # ---- dynamics -----------------------------------------------------------------------
    def rhs(self, t: float, z: np.ndarray) -> np.ndarray:
        n, mdl = self.n, self.mdl
        x, v, y, w = z[:n, None], z[n : 2 * n, None], z[2 * n : 3 * n, None], z[3 * n : 4 * n, None]
        F, V, T, _, _, l0dot, f = mdl.forces(np.array([t]), x, y)
        m, c = mdl.m, mdl.c
        Nrm = m - V
        mu = mdl.kinetic_mu(self.sigma[:, None], np.abs(v))
        out = np.zeros_like(z)
        fly = (self.mode == FLY)[:, None]
        slip = (self.mode == SLIP)[:, None]
        acc_h = np.where(slip, (F - c * v - self.sigma[:, None] * mu * Nrm) / m, (F - c * v) / m)
        acc_h = np.where(self.mode[:, None] == STICK, 0.0, acc_h)
        out[:n] = np.where(self.mode[:, None] == STICK, 0.0, v)[:, 0]
        out[n : 2 * n] = acc_h[:, 0]
        out[2 * n : 3 * n] = np.where(fly, w, 0.0)[:, 0]
        out[3 * n : 4 * n] = np.where(fly, (-m + V) / m, 0.0)[:, 0]
        diss = np.sum(np.where(slip, mu * Nrm * np.abs(v), 0.0) + c * v * v)
        pw = -np.sum(T * l0dot)
        if n >= 2:
            pw += np.sum(f[:, 0] * (v[:-1, 0] - v[1:, 0]))
        out[4 * n] = diss
        out[4 * n + 1] = pw
        return out

    def body_forces(self, t: float, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        F, V, *_ = self.mdl.forces(np.array([t]), z[:n, None], z[2 * n : 3 * n, None])
        return F[:, 0], self.mdl.m[:, 0] - V[:, 0]

    def switching(self, t: np.ndarray, Z: np.ndarray, t0: float) -> np.ndarray:
        """Switching functions (3N, S): rows [0:N] static fwd or v/y function, [N:2N] static bwd, [2N:3N] N."""
        n, mdl = self.n, self.mdl
        x, v, y = Z[:n], Z[n : 2 * n], Z[2 * n : 3 * n]
        F, V, *_ = mdl.forces(t, x, y)
        Nrm = mdl.m - V
        g = np.full((3 * n, t.size), np.inf)
        dt = t - t0
        for i in range(n):
            if self.mode[i] == STICK:
                g[i] = mdl.mu_s_fwd[i, 0] * Nrm[i] - F[i]
                g[n + i] = F[i] + mdl.mu_s_bwd[i, 0] * Nrm[i]
                g[2 * n + i] = Nrm[i]
            elif self.mode[i] == SLIP:
                g[i] = self.sigma[i] * v[i] / dt ** self.power[i]
                g[2 * n + i] = Nrm[i]
            else:
                g[i] = y[i] / dt ** self.power[i]
        return g

    # ---- decisions ----------------------------------------------------------------------
    def _static_ok(self, i: int, F: float, N: float) -> bool:
        return -self.mdl.mu_s_bwd[i, 0] * N <= F <= self.mdl.mu_s_fwd[i, 0] * N

    def _ground(self, i: int, z: np.ndarray, F: float, N: float) -> None:
        """Body i on the ground (y = w = 0) with N >= 0: stuck or slipping."""
        n = self.n
        z[2 * n + i] = 0.0
        z[3 * n + i] = 0.0
        v = z[n + i]
        if v != 0.0:
            self.mode[i], self.sigma[i], self.power[i] = SLIP, math.copysign(1.0, v), 0
        elif self._static_ok(i, F, N):
            self.mode[i], self.sigma[i], self.power[i] = STICK, 0.0, 0
        else:
            self.mode[i], self.sigma[i], self.power[i] = SLIP, (1.0 if F > 0 else -1.0), 1

    def _fly(self, i: int, z: np.ndarray, N: float) -> None:
        """Body i leaves the ground (or is in the air) from its current state."""
        n = self.n
        self.mode[i], self.sigma[i] = FLY, 0.0
        y, w = z[2 * n + i], z[3 * n + i]
        if y > 0.0:
            self.power[i] = 0
        elif w > 0.0:
            self.power[i] = 1
        elif N < -_TOL:
            self.power[i] = 2
        else:
            self.power[i] = 3

    def _impact(self, t: float, i: int, z: np.ndarray) -> None:
        n, mdl = self.n, self.mdl
        m = mdl.m[i, 0]
        vm, wm = z[n + i], z[3 * n + i]
        pn = m * (1.0 + self.e) * abs(wm)
        wp = -self.e * wm
        plastic = self.e * abs(wm) < self.zeno
        if plastic:
            pn, wp = m * abs(wm), 0.0
        vp = vm
        if vm != 0.0:
            mu_k = mdl.mu_k_fwd[i, 0] if vm > 0 else mdl.mu_k_bwd[i, 0]
            pt = min(m * abs(vm), mu_k * pn)
            vp = 0.0 if pt >= m * abs(vm) else vm - math.copysign(pt / m, vm)
        self.e_d += 0.5 * m * (wm * wm - wp * wp) + 0.5 * m * (vm * vm - vp * vp)
        z[n + i], z[2 * n + i], z[3 * n + i] = vp, 0.0, wp
        self.impacts.append(dict(t=t, body=i, v_minus=vm, w_minus=wm, v_plus=vp, w_plus=wp, plastic=plastic))
        if wp > 0.0:
            self._fly(i, z, 0.0)
            return
        F, N = self.body_forces(t, z)
        if N[i] >= 0.0:
            self._ground(i, z, F[i], N[i])
        else:
            self._fly(i, z, N[i])

    def decide(self, t: float, z: np.ndarray, trigger: tuple[int, int] | None) -> None:
        """Re-decide every body at an event (``trigger = (row, body)``) or at the start (None)."""
        n = self.n
        F, N = self.body_forces(t, z)
        order = list(range(n))
        if trigger is not None:
            order.remove(trigger[1])
            order.insert(0, trigger[1])
        for i in order:
            forced = trigger is not None and i == trigger[1]
            row = trigger[0] if forced else -1
            mode = self.mode[i]
            if mode == FLY:
                y, w = z[2 * n + i], z[3 * n + i]
                if (forced or (y < _TOL and self.power[i] == 0)) and w < 0.0:
                    self._impact(t, i, z)
                    F, N = self.body_forces(t, z)
                continue
            if forced and row == 2 * n + i or (not forced and N[i] < _TOL and N[i] <= 0.0):
                self._fly(i, z, N[i])
                continue
            if mode == STICK:
                lim_f = self.mdl.mu_s_fwd[i, 0] * N[i] - F[i]
                lim_b = F[i] + self.mdl.mu_s_bwd[i, 0] * N[i]
                if (forced and row == i) or (not forced and lim_f < _TOL):
                    self.mode[i], self.sigma[i], self.power[i] = SLIP, 1.0, 1
                elif (forced and row == n + i) or (not forced and lim_b < _TOL):
                    self.mode[i], self.sigma[i], self.power[i] = SLIP, -1.0, 1
            else:  # SLIP
                if forced or abs(z[n + i]) < _TOL and self.power[i] == 0:
                    z[n + i] = 0.0
                    self._ground(i, z, F[i], N[i])

    def start(self, z: np.ndarray) -> None:
        n = self.n
        F, N = self.body_forces(0.0, z)
        for i in range(n):
            if z[2 * n + i] > 0.0 or z[3 * n + i] > 0.0:
                self._fly(i, z, N[i])
            elif z[3 * n + i] < 0.0:
                self.mode[i] = FLY
                self._impact(0.0, i, z)
            elif N[i] >= 0.0:
                self._ground(i, z, F[i], N[i])
            else:
                self._fly(i, z, N[i])

    # ---- integration --------------------------------------------------------------------
    def run(self, z: np.ndarray, t_end: float, ts: np.ndarray) -> np.ndarray:
        n = self.n
        out = np.zeros((ts.size, 4 * n + 2))
        order = np.argsort(ts, kind="stable")
        k = 0
        while k < ts.size and ts[order[k]] <= 0.0:
            out[order[k], : 4 * n] = z[: 4 * n]
            k += 1
        t = 0.0
        self.start(z)
        while t < t_end:
            self.n_segments += 1
            if self.n_segments > _MAX_SEGMENTS:
                raise RuntimeError(f"more than {_MAX_SEGMENTS} segments by t = {t} (Zeno or chattering)")
            t0 = t
            zs = z.copy()
            zs[4 * n :] = 0.0
            solver = DOP853(self.rhs, t0, zs, t_end, rtol=self.rtol, atol=self.atol, max_step=self.max_step)
            event = None
            while True:
                t_old = solver.t
                msg = solver.step()
                if solver.status == "failed":
                    raise RuntimeError(f"DOP853 failed at t = {solver.t}: {msg}")
                t_new = solver.t
                dense = solver.dense_output()
                sub = t_old + (t_new - t_old) * np.arange(1, _N_SUB + 1) / _N_SUB
                G = self.switching(sub, dense(sub), t0)
                neg = np.any(G < 0.0, axis=0)
                t_stop = t_new
                if np.any(neg):
                    kk = int(np.argmax(neg))
                    a = t_old if kk == 0 else sub[kk - 1]
                    b = sub[kk]
                    best = (np.inf, -1)
                    for r in np.nonzero(G[:, kk] < 0.0)[0]:
                        fun = lambda s, r=r: self.switching(np.array([s]), dense(np.array([s])), t0)[r, 0]  # noqa: E731
                        aa = a if a > t0 else a + 1e-9 * (b - a)
                        if fun(aa) < 0.0:
                            root = aa
                        else:
                            root = brentq(fun, aa, b, xtol=1e-15, rtol=8.9e-16, maxiter=200)
                        if root < best[0]:
                            best = (root, int(r))
                    t_stop, event = best[0], (best[1], best[1] % n)
                # apex search and samples within (t_old, t_stop]
                self._apex(t_old, t_stop, dense)
                while k < ts.size and ts[order[k]] <= t_stop:
                    zz = dense(np.array([ts[order[k]]]))[:, 0].copy()
                    out[order[k]] = zz
                    out[order[k], 4 * n] += self.e_d
                    out[order[k], 4 * n + 1] += self.work
                    k += 1
                if event is not None or solver.status == "finished":
                    break
            zend = dense(np.array([t_stop]))[:, 0].copy() if event is not None else solver.y.copy()
            self.e_d += zend[4 * n]
            self.work += zend[4 * n + 1]
            self.flight_time += (t_stop - t0) * (self.mode == FLY)
            t = t_stop
            z = zend
            z[4 * n :] = 0.0
            if event is not None:
                self.decide(t, z, event)
        while k < ts.size:
            out[order[k], : 4 * n] = z[: 4 * n]
            out[order[k], 4 * n] = self.e_d
            out[order[k], 4 * n + 1] = self.work
            k += 1
        return out

    def _apex(self, ta: float, tb: float, dense) -> None:
        n = self.n
        for i in np.nonzero(self.mode == FLY)[0]:
            sub = ta + (tb - ta) * np.arange(0, _N_SUB + 1) / _N_SUB
            W = dense(sub)[3 * n + i]
            for q in range(_N_SUB):
                if W[q] > 0.0 >= W[q + 1]:
                    ta_ = brentq(lambda s: dense(np.array([s]))[3 * n + i, 0], sub[q], sub[q + 1], xtol=1e-15)
                    yy = float(dense(np.array([ta_]))[2 * n + i, 0])
                    self.apexes.append((float(ta_), int(i), yy))
                    self.max_height[i] = max(self.max_height[i], yy)
                    break


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
    """Simulate the hopping chain on ``[0, t_end]`` and sample it at ``save_at`` (see the module docstring)."""
    if not (0.0 <= restitution <= 1.0):
        raise ValueError(f"restitution must be in [0, 1], got {restitution}")
    if not (zeno_speed >= 0.0):
        raise ValueError(f"zeno_speed must be >= 0, got {zeno_speed}")
    t_end = float(t_end)
    if not (t_end > 0.0):
        raise ValueError(f"t_end must be > 0, got {t_end}")
    ts = np.atleast_1d(np.asarray(save_at, dtype=float))
    if ts.ndim != 1 or np.any(ts < 0.0) or np.any(ts > t_end):
        raise ValueError(f"save_at must be a 1-D array of times in [0, t_end={t_end}]")
    mdl = _Model(cfg)
    n = mdl.n

    def per_body(name: str, val, default: np.ndarray) -> np.ndarray:
        if val is None:
            return default
        arr = np.asarray(val, dtype=float).reshape(-1)
        if arr.shape != (n,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must have {n} finite values, got {val!r}")
        return arr

    x_paper = np.concatenate([[0.0], np.cumsum(np.asarray(cfg["lbar"], dtype=float))])
    x = per_body("x0", x0, x_paper)
    v = per_body("v0", v0, np.zeros(n))
    y = per_body("y0", y0, np.zeros(n))
    w = per_body("w0", w0, np.zeros(n))
    for i in range(n):
        if y[i] < 0.0:
            raise ValueError(f"y0[{i}] must be >= 0, got {y[i]}")
    z = np.concatenate([x, v, y, w, [0.0, 0.0]])
    solver = _Solver(mdl, rtol, atol, float(restitution), float(zeno_speed))
    out = solver.run(z, t_end, ts)
    X, Vv, Y, W = out[:, :n], out[:, n : 2 * n], out[:, 2 * n : 3 * n], out[:, 3 * n : 4 * n]
    energy = mdl.energy(ts, X.T, Vv.T, Y.T, W.T)
    n_land = np.zeros(n, dtype=int)
    for imp in solver.impacts:
        n_land[imp["body"]] += 1
    return dict(
        t=ts.copy(),
        x=X.copy(),
        v=Vv.copy(),
        y=Y.copy(),
        w=W.copy(),
        e_d=out[:, 4 * n].copy(),
        work=out[:, 4 * n + 1].copy(),
        energy=energy,
        n_landings=n_land,
        flight_time=solver.flight_time.copy(),
        max_height=np.maximum(solver.max_height, np.max(Y, axis=0, initial=0.0)),
        landings=[(imp["t"], imp["body"]) for imp in solver.impacts],
        impacts=solver.impacts,
        apexes=solver.apexes,
        n_segments=solver.n_segments,
    )
