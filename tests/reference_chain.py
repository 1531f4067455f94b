"""Independent float64 reference solver for chains of N masses with stick-slip friction.

Written only from SPEC.md (sections 1-5 and 8) and CHAIN_CONVENTIONS.md.  It imports
nothing from the ``locomotion_jax`` package nor from ``tests/reference.py`` (the
two-mass reference it is checked against), only numpy and scipy.

Model (0-based indices: masses i = 0..N-1, spring j joins masses j and j+1)
----------------------------------------------------------------------------
``u_j = x_{j+1} - x_j``, ``l_j = sqrt(u_j^2 + d_j^2)``, ``T_j = k_j (l_j - l0_j)``,
``fx_j = T_j u_j / l_j``, ``fy_j = T_j d_j / l_j``.  Horizontal force on mass i
``F_i = fx_i - fx_{i-1} + f_i - f_{i-1}``, signed normal force ``N_i = m_i - fy_i + fy_{i-1}``
(missing springs count zero).  Actuation per spring, a Fourier series with base
frequency ``omega``: ``s_j(t) = sum_n A[j, n-1] cos(n omega t) + B[j, n-1] sin(n omega t)``;
the "length" actuator sets ``l0_j = lbar_j + s_j`` and ``f_j = 0``, the "force" actuator
``l0_j = lbar_j`` and ``f_j = s_j``.  Contact "strict": ``n_i = N_i``, the run stops at the
first ``N_i = 0`` (lift-off, time located); "paper": ``n_i = |N_i|``, integrated through
and flagged.  Friction per mass, anisotropic Coulomb: a stuck mass holds while
``-mu_s_bwd n_i <= F_i <= mu_s_fwd n_i``; a mass slipping in direction ``sigma = sgn v_i``
obeys ``m_i v_i' = F_i - c_i v_i - sigma mu_dir(|v_i|) n_i`` with the constant kinetic
coefficient of that direction (Coulomb) or the Stribeck law
``mu_dir(|v|) = mu_k_dir + (mu_s_dir - mu_k_dir) exp(-(|v| / v_s)^2)``.

Method
------
Event-driven integration of the exact hybrid dynamics, one DOP853 integration per
segment of constant friction mode (the set of stuck masses, the slip direction of each
slipping mass and, for paper contact, the sign of each normal force).  The stepper is
``scipy.integrate.DOP853``, the one behind ``solve_ivp(method="DOP853")``, driven one step
at a time: after every accepted step all switching functions of the mode are evaluated
as one vector on 16 points of the step's dense output (the step end included), so that
a function that dips below zero and comes back inside a step (a grazing crossing, which
``solve_ivp``'s end-of-step sign test would miss) is seen as well.  The first crossing
over all functions is located with ``brentq`` on the dense output, and the segment ends
there.

Switching functions (each is >= 0 while the mode is valid):

* each stuck mass: its two static limits ``mu_s_fwd n_i - F_i`` and ``F_i + mu_s_bwd n_i``;
* each slipping mass: ``sigma_i v_i`` (it reaches zero);
* each normal force: ``N_i`` (strict) or ``side_i N_i`` (paper, every crossing ends a segment);
* when measuring: ``z - |X - X_ref|`` (the target distance, ``tau_z``).

After every event EVERY mass is re-decided from the state: the mass that triggered it
switches, and any other mass within a tiny tolerance of its own switching surface switches
with it (symmetric chains switch several masses at one instant).  A slipping mass that
reaches ``v_i = 0`` has its velocity set exactly to zero, sticks if the static condition
holds there, else slips on in the direction of ``F_i``; a stuck mass beyond a static
limit starts to slip in that direction from ``v_i = 0``.  A function that is zero at the
start of a segment (``v_i`` of a mass that has just started, ``N_i`` just after a paper-contact
crossing) is divided by ``t - t0`` (its value at ``t0`` is its rate there), so that a quick
return across zero is located instead of being reported at ``t0``.

Guards: the step is capped at 1/8 of the shortest period (actuation harmonics and the free
chain's highest natural frequency), the number of segments is capped, a long run of
zero-length segments raises ``RuntimeError`` (Zeno / chattering), and every segment starts
with a check that no switching function is clearly negative (a missed event fails loudly).

The state is augmented with the dissipated energy ``e_d`` (integral of
``sum mu_dir(|v_i|) n_i |v_i| + c_i v_i^2``) and the actuator work ``w`` (integral of the
actuator power ``sum_j -T_j dl0_j/dt + sum_j f_j (v_j - v_{j+1})``), so that the balance
``w = e_d + e(t2) - e(t1)`` is a real check of the integration.  Both are integrated from zero
in each segment and added to their totals at its end, so that the step-size control holds
them to the tolerance relative to the segment's increment, not to a growing total.

The model assumes the masses stay in order (``x_0 < ... < x_{N-1}``); the solver does not
enforce it but reports ``min_gap``, the smallest gap met (near a resonance a lightly damped
chain can pass masses through each other, which a valid configuration must not do).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np
from scipy.integrate import DOP853, OdeSolution
from scipy.interpolate import BSpline
from scipy.linalg import eigh
from scipy.optimize import brentq


__all__ = [
    "chain_config",
    "travelling_wave",
    "lowest_natural_frequency",
    "default_t_start",
    "reference_chain_simulate",
    "reference_chain_measure",
]

# Tolerances of the re-decision of the masses that did not trigger an event: forces and
# velocities are O(1); located events leave residuals of ~1e-12 at t ~ 1e3.
_TOL_FORCE = 1e-10
_TOL_VEL = 1e-10
# Consistency check at each segment start: a switching function below -_TOL_CHECK means a missed event.
_TOL_CHECK = 1e-8
# Zeno / chattering guards.
_MAX_SEGMENTS = 1_000_000
_MAX_TINY_SEGMENTS = 200  # consecutive segments shorter than _TINY_DT (1 + |t|)
_TINY_DT = 1e-12
# Sampling of each step's dense output for the event search.
_N_SUB = 16
# Total stuck time above which a mass counts as stuck "for a positive time" (regime).
_STUCK_POSITIVE = 1e-6

# Row blocks of the switching-function array (each block has N rows, then the target row).
_STICK_FWD, _STICK_BWD, _VEL, _NORMAL, _TARGET = range(5)
_ROW_KIND = {
    _STICK_FWD: "stick_fwd",
    _STICK_BWD: "stick_bwd",
    _VEL: "v_zero",
    _NORMAL: "normal_zero",
    _TARGET: "target",
}


# --------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------
def travelling_wave(n_springs: int, a: float, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Fourier coefficients of the travelling wave ``s_j(t) = a sin(omega t - j phi)``.

    ``A[j, 0] = -a sin(j phi)``, ``B[j, 0] = a cos(j phi)``.  Returns ``(A, B)``, each of shape ``(n_springs, 1)``.
    """
    j = np.arange(n_springs, dtype=float)
    return (-a * np.sin(j * phi))[:, None], (a * np.cos(j * phi))[:, None]


def _per(name: str, value, size: int, what: str) -> np.ndarray:
    """Broadcast a scalar, or check a sequence, to a float array of ``size`` (per mass or per spring)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(size, float(arr))
    if arr.shape != (size,):
        raise ValueError(f"{name} must be a scalar or have one value per {what} ({size}), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    return arr


def _coefficients(name: str, value, n_springs: int) -> np.ndarray:
    """Fourier coefficients as ``(n_springs, H)``; a 1-D ``(H,)`` array is used for every spring."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1:
        arr = np.broadcast_to(arr, (n_springs, arr.size)).copy()
    if arr.ndim != 2 or arr.shape[0] != n_springs or arr.shape[1] < 1:
        raise ValueError(f"{name} must have shape (H,) or ({n_springs}, H) with H >= 1, got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


def chain_config(
    masses: Sequence[float],
    k=50.0,
    d=0.5,
    lbar=3.0,
    c=0.01,
    omega: float = 2.0,
    wave_A=None,
    wave_B=None,
    a: float | None = None,
    phi: float | None = None,
    actuator: str = "length",
    mu_s_fwd=0.7,
    mu_s_bwd=None,
    mu_k_fwd=0.5,
    mu_k_bwd=None,
    friction: str = "coulomb",
    v_s=None,
    spline=None,
) -> dict:
    """Normalised configuration of a chain (CHAIN_CONVENTIONS.md).

    Scalars broadcast to per-mass (``c``, friction coefficients, ``v_s``) or per-spring
    (``k``, ``d``, ``lbar``) arrays.  The actuation is either the Fourier coefficients
    ``wave_A``, ``wave_B`` (shape ``(N-1, H)``, or ``(H,)`` for every spring; a missing one is
    zero) or the travelling wave ``a sin(omega t - j phi)`` (``phi`` defaults to 0); with
    neither, the paper's ``a = 0.05``, ``phi = 0``.  ``mu_s_bwd``/``mu_k_bwd`` default to the
    forward values (isotropic).  ``friction`` is ``"coulomb"`` or ``"stribeck"`` (needs ``v_s > 0``).
    ``spline``: control values ``c[j, i]``, shape ``(N-1, M)`` with ``M >= 4``, in place of the Fourier
    actuation: ``s_j`` is the periodic uniform cubic B-spline in the phase ``omega t`` whose basis
    function of ``c[j, i]`` is centred at the phase ``2 pi i / M``.

    Returns a dict with ``m, c, mu_s_fwd, mu_s_bwd, mu_k_fwd, mu_k_bwd, v_s`` (N,), ``k, d, lbar``
    (N-1,), ``A, B`` (N-1, H), ``omega``, ``actuator``, ``friction``.

    Raises:
        ValueError: naming the parameter (and index) that is out of range.
    """
    m = np.asarray(masses, dtype=float)
    if m.ndim != 1 or m.size < 2:
        raise ValueError(f"masses must be a 1-D sequence of at least 2 values, got shape {m.shape}")
    n = m.size
    ns = n - 1
    for i, mi in enumerate(m):
        if not (math.isfinite(mi) and mi > 0.0):
            raise ValueError(f"masses[{i}] must be > 0, got {mi}")
    cfg: dict = dict(m=m)
    cfg["c"] = _per("c", c, n, "mass")
    cfg["k"] = _per("k", k, ns, "spring")
    cfg["d"] = _per("d", d, ns, "spring")
    cfg["lbar"] = _per("lbar", lbar, ns, "spring")
    for j in range(ns):
        if cfg["k"][j] <= 0.0:
            raise ValueError(f"k[{j}] must be > 0, got {cfg['k'][j]}")
        if cfg["lbar"][j] <= 0.0:
            raise ValueError(f"lbar[{j}] must be > 0, got {cfg['lbar'][j]}")
        if abs(cfg["d"][j]) >= cfg["lbar"][j]:
            raise ValueError(f"d[{j}] must satisfy |d| < lbar[{j}] = {cfg['lbar'][j]}, got {cfg['d'][j]}")
    for i in range(n):
        if cfg["c"][i] < 0.0:
            raise ValueError(f"c[{i}] must be >= 0, got {cfg['c'][i]}")
    if not (math.isfinite(omega) and omega >= 0.0):
        raise ValueError(f"omega must be >= 0, got {omega}")
    cfg["omega"] = float(omega)

    if a is not None or phi is not None:
        if wave_A is not None or wave_B is not None:
            raise ValueError("give either a/phi (travelling wave) or wave_A/wave_B (Fourier coefficients), not both")
        A, B = travelling_wave(ns, 0.05 if a is None else float(a), 0.0 if phi is None else float(phi))
    elif wave_A is None and wave_B is None:
        A, B = travelling_wave(ns, 0.05, 0.0)
    else:
        A = None if wave_A is None else _coefficients("wave_A", wave_A, ns)
        B = None if wave_B is None else _coefficients("wave_B", wave_B, ns)
        if A is None:
            A = np.zeros_like(B)
        if B is None:
            B = np.zeros_like(A)
        if A.shape != B.shape:
            raise ValueError(f"wave_A and wave_B must have the same shape, got {A.shape} and {B.shape}")
    cfg["A"], cfg["B"] = A, B
    cfg["spline"] = None
    if spline is not None:
        ctrl = np.asarray(spline, dtype=float)
        if ctrl.ndim != 2 or ctrl.shape[0] != ns or ctrl.shape[1] < 4 or not np.all(np.isfinite(ctrl)):
            raise ValueError(f"spline must be finite control values of shape (N-1, M >= 4), got {ctrl.shape}")
        cfg["spline"] = ctrl
        cfg["A"], cfg["B"] = np.zeros((ns, 1)), np.zeros((ns, 1))

    if actuator not in ("length", "force"):
        raise ValueError(f"actuator must be 'length' or 'force', got {actuator!r}")
    cfg["actuator"] = actuator

    cfg["mu_s_fwd"] = _per("mu_s_fwd", mu_s_fwd, n, "mass")
    cfg["mu_s_bwd"] = _per("mu_s_bwd", mu_s_fwd if mu_s_bwd is None else mu_s_bwd, n, "mass")
    cfg["mu_k_fwd"] = _per("mu_k_fwd", mu_k_fwd, n, "mass")
    cfg["mu_k_bwd"] = _per("mu_k_bwd", mu_k_fwd if mu_k_bwd is None else mu_k_bwd, n, "mass")
    for direction in ("fwd", "bwd"):
        ms, mk = cfg[f"mu_s_{direction}"], cfg[f"mu_k_{direction}"]
        for i in range(n):
            if mk[i] < 0.0:
                raise ValueError(f"mu_k_{direction}[{i}] must be >= 0, got {mk[i]}")
            if ms[i] < mk[i]:
                raise ValueError(f"need mu_s_{direction}[{i}] >= mu_k_{direction}[{i}], got {ms[i]} < {mk[i]}")
    if friction == "coulomb":
        if v_s is not None:
            raise ValueError("v_s is only used with friction='stribeck'")
        cfg["v_s"] = None
    elif friction == "stribeck":
        if v_s is None:
            raise ValueError("friction='stribeck' needs v_s > 0")
        cfg["v_s"] = _per("v_s", v_s, n, "mass")
        for i in range(n):
            if cfg["v_s"][i] <= 0.0:
                raise ValueError(f"v_s[{i}] must be > 0, got {cfg['v_s'][i]}")
    else:
        raise ValueError(f"friction must be 'coulomb' or 'stribeck', got {friction!r}")
    cfg["friction"] = friction
    return cfg


def lowest_natural_frequency(cfg: dict) -> float:
    """Lowest natural frequency of the linearised chain with one mass held fixed, minimised over that mass.

    Stiffness ``k_j`` between neighbours (the geometry factor ignored, as in the paper's
    eqs. 11-12).  For N = 2 this is ``min(sqrt(k/m1), sqrt(k/m2))``.
    """
    m, k = cfg["m"], cfg["k"]
    n = m.size
    K = np.zeros((n, n))
    for j, kj in enumerate(k):
        K[j, j] += kj
        K[j + 1, j + 1] += kj
        K[j, j + 1] -= kj
        K[j + 1, j] -= kj
    best = math.inf
    for held in range(n):
        keep = [i for i in range(n) if i != held]
        lam = eigh(K[np.ix_(keep, keep)], np.diag(m[keep]), eigvals_only=True)
        best = min(best, math.sqrt(float(lam[0])))
    return best


def default_t_start(cfg: dict) -> float:
    """``80 * 2 pi / omega_min`` with ``omega_min`` of :func:`lowest_natural_frequency`."""
    return 80.0 * 2.0 * math.pi / lowest_natural_frequency(cfg)


def _highest_free_frequency(cfg: dict) -> float:
    """Highest natural frequency of the free linearised chain (for the step cap)."""
    m, k = cfg["m"], cfg["k"]
    n = m.size
    K = np.zeros((n, n))
    for j, kj in enumerate(k):
        K[j : j + 2, j : j + 2] += kj * np.array([[1.0, -1.0], [-1.0, 1.0]])
    lam = eigh(K, np.diag(m), eigvals_only=True)
    return math.sqrt(max(float(lam[-1]), 0.0))


# --------------------------------------------------------------------------------------
# Model: forces on arrays of samples
# --------------------------------------------------------------------------------------
class _Chain:
    """The smooth parts of the model, evaluated on ``S`` samples at once.

    Positions and velocities come as ``(N, S)`` arrays and times as ``(S,)``; parameters are
    stored as column vectors so that everything broadcasts over the sample axis.
    """

    def __init__(self, cfg: dict, contact: str):
        if contact not in ("strict", "paper"):
            raise ValueError(f"contact must be 'strict' or 'paper', got {contact!r}")
        self.cfg = cfg
        self.strict = contact == "strict"
        self.n = cfg["m"].size
        col = lambda v: np.asarray(v, dtype=float)[:, None]  # noqa: E731
        self.m, self.c = col(cfg["m"]), col(cfg["c"])
        self.k, self.d, self.lbar = col(cfg["k"]), col(cfg["d"]), col(cfg["lbar"])
        self.d2 = self.d * self.d
        self.mu_s_fwd, self.mu_s_bwd = col(cfg["mu_s_fwd"]), col(cfg["mu_s_bwd"])
        self.mu_k_fwd, self.mu_k_bwd = col(cfg["mu_k_fwd"]), col(cfg["mu_k_bwd"])
        self.stribeck = cfg["friction"] == "stribeck"
        self.v_s = col(cfg["v_s"]) if self.stribeck else None
        self.omega = float(cfg["omega"])
        self.A, self.B = np.asarray(cfg["A"], dtype=float), np.asarray(cfg["B"], dtype=float)
        harm = np.arange(1, self.A.shape[1] + 1, dtype=float)
        self.harm_omega = (harm * self.omega)[:, None]  # (H, 1)
        self.A_rate = self.A * harm[None, :] * self.omega  # d/dt of A cos: -A n omega sin
        self.B_rate = self.B * harm[None, :] * self.omega
        self.force_actuator = cfg["actuator"] == "force"
        # Spline actuation: per spring (M, s(u), s'(u)) with u = M phase / (2 pi) in [0, M); the basis
        # function i (knots i - 3 .. i + 1) is centred at u = i - 1 and carries c[(i - 1) mod M].
        self.splines = None
        if cfg.get("spline") is not None:
            self.splines = []
            for ctrl in cfg["spline"]:
                M = ctrl.size
                b = BSpline(np.arange(-3.0, M + 4.0), ctrl[(np.arange(M + 3) - 1) % M], 3, extrapolate=False)
                self.splines.append((M, b, b.derivative()))
        self.total_mass = float(np.sum(cfg["m"]))
        self.m_flat = np.asarray(cfg["m"], dtype=float)
        # Incidence matrix: (D @ h)_i = h_i - h_{i-1}, terms of missing springs zero.
        self.D = np.zeros((self.n, self.n - 1))
        self.D[np.arange(self.n - 1), np.arange(self.n - 1)] = 1.0
        self.D[np.arange(1, self.n), np.arange(self.n - 1)] = -1.0

    def signal(self, t: float) -> tuple[list[float], list[float]]:
        """``s_j(t)`` and ``ds_j/dt`` per spring at one time, in Python floats."""
        if self.splines is None:
            s, sd = self.actuation(np.array([t]))
            return s[:, 0].tolist(), sd[:, 0].tolist()
        out, rate = [], []
        for M, b, db in self.splines:
            u = (self.omega * t * M / (2.0 * math.pi)) % M
            out.append(float(b(u)))
            rate.append(float(db(u)) * self.omega * M / (2.0 * math.pi))
        return out, rate

    def actuation(self, t: np.ndarray):
        """``s_j(t)`` and ``ds_j/dt`` as ``(N-1, S)`` arrays."""
        if self.splines is not None:
            pairs = [self.signal(float(ti)) for ti in np.atleast_1d(t)]
            return np.array([p[0] for p in pairs]).T, np.array([p[1] for p in pairs]).T
        ph = self.harm_omega * t[None, :]
        cs, sn = np.cos(ph), np.sin(ph)
        return self.A @ cs + self.B @ sn, self.B_rate @ cs - self.A_rate @ sn

    def forces(self, t: np.ndarray, x: np.ndarray):
        """Forces of CHAIN_CONVENTIONS.md at times ``t`` (S,) and positions ``x`` (N, S).

        Returns ``(F, Nrm, T, l, l0, l0dot, f)``: horizontal force on each mass (N, S), signed
        normal force (N, S), and per spring (N-1, S) the tension, length, rest length, its rate
        and the internal actuator force.
        """
        s, sdot = self.actuation(t)
        if self.force_actuator:
            l0 = np.broadcast_to(self.lbar, s.shape)
            l0dot = np.zeros_like(s)
            f = s
        else:
            l0 = self.lbar + s
            l0dot = sdot
            f = None
        u = x[1:] - x[:-1]
        ell = np.sqrt(u * u + self.d2)
        T = self.k * (ell - l0)
        h = T * u / ell if f is None else T * u / ell + f
        F = self.D @ h  # h_i - h_{i-1}
        Nrm = self.m - self.D @ (T * self.d / ell)  # m_i - fy_i + fy_{i-1}
        if f is None:
            f = np.zeros_like(s)
        return F, Nrm, T, ell, l0, l0dot, f

    def mass_forces(self, t: float, x: np.ndarray, i: int) -> tuple[float, float]:
        """``(F_i, N_i)`` of one mass at one time, from its (at most two) springs, in Python floats."""
        cfg = self.cfg
        F, Nrm = 0.0, float(cfg["m"][i])
        for j, sign in ((i - 1, -1.0), (i, 1.0)):  # spring j acts on mass j (+) and on mass j + 1 (-)
            if j < 0 or j >= self.n - 1:
                continue
            if self.splines is not None:
                s = self.signal(t)[0][j]
            else:
                s = 0.0
                for h in range(self.A.shape[1]):
                    wt = self.harm_omega[h, 0] * t
                    s += self.A[j, h] * math.cos(wt) + self.B[j, h] * math.sin(wt)
            u = float(x[j + 1] - x[j])
            d = float(cfg["d"][j])
            ell = math.sqrt(u * u + d * d)
            if self.force_actuator:
                T = float(cfg["k"][j]) * (ell - float(cfg["lbar"][j]))
                hx = T * u / ell + s
            else:
                T = float(cfg["k"][j]) * (ell - float(cfg["lbar"][j]) - s)
                hx = T * u / ell
            F += sign * hx
            Nrm -= sign * T * d / ell
        return F, Nrm

    def normal_rate(self, t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``dN_i/dt`` (N,) at one state: ``fy_j = k_j d_j (1 - l0_j / l_j)`` differentiated."""
        tt = np.array([t])
        _, _, _, ell, l0, l0dot, _ = self.forces(tt, x[:, None])
        u = (x[1:] - x[:-1])[:, None]
        udot = (v[1:] - v[:-1])[:, None]
        ldot = u * udot / ell
        fydot = (self.k * self.d * (l0 * ldot / (ell * ell) - l0dot / ell))[:, 0]
        return -(self.D @ fydot)

    def kinetic_mu(self, direction: np.ndarray, speed: np.ndarray) -> np.ndarray:
        """Kinetic coefficient ``mu_dir(|v|)`` (N, S) for slip directions (N, 1) and speeds ``|v|`` (N, S)."""
        fwd = direction > 0
        mu_k = np.where(fwd, self.mu_k_fwd, self.mu_k_bwd)
        if not self.stribeck:
            return np.broadcast_to(mu_k, speed.shape)
        mu_s = np.where(fwd, self.mu_s_fwd, self.mu_s_bwd)
        return mu_k + (mu_s - mu_k) * np.exp(-((speed / self.v_s) ** 2))

    def energy(self, t: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``e = sum m_i v_i^2/2 + sum k_j (l_j - l0_j)^2/2`` at each sample (S,)."""
        _, _, _, ell, l0, _, _ = self.forces(t, x)
        return 0.5 * np.sum(self.m * v * v, axis=0) + 0.5 * np.sum(self.k * (ell - l0) ** 2, axis=0)

    def initial_positions(self, start: str) -> np.ndarray:
        """``"paper"``: ``x_0 = 0``, gaps ``lbar_j``; ``"relaxed"``: gaps ``sqrt(l0_j(0)^2 - d_j^2)``."""
        lbar, d = self.cfg["lbar"], self.cfg["d"]
        if start == "paper":
            gaps = lbar.copy()
        elif start == "relaxed":
            l0 = lbar.copy()
            if not self.force_actuator:
                l0 = l0 + self.actuation(np.zeros(1))[0][:, 0]
            if np.any(l0 * l0 <= d * d):
                j = int(np.argmax(l0 * l0 <= d * d))
                raise ValueError(f"relaxed start needs l0_{j}(0) > |d_{j}|, got l0={l0[j]}, d={d[j]}")
            gaps = np.sqrt(l0 * l0 - d * d)
        else:
            raise ValueError(f"start must be 'paper' or 'relaxed', got {start!r}")
        return np.concatenate(([0.0], np.cumsum(gaps)))


# --------------------------------------------------------------------------------------
# Hybrid solver
# --------------------------------------------------------------------------------------
class _Segment:
    """One segment of constant friction mode: its time range, mode and (optionally) dense output."""

    __slots__ = ("t0", "t1", "stuck", "sol", "acc0")

    def __init__(self, t0: float, t1: float, stuck: np.ndarray, sol, acc0: np.ndarray):
        self.t0, self.t1, self.stuck, self.sol = t0, t1, stuck.copy(), sol
        self.acc0 = acc0  # (e_d, w) at t0: the dense output integrates them from zero


class _ChainSolver:
    """Event-driven integrator of the exact stick/slip chain (see the module docstring).

    State ``y = (x_0..x_{N-1}, v_0..v_{N-1}, e_d, w)``; mode: ``stuck`` (N,) bools, ``sdir`` (N,)
    slip directions (+1/-1), ``side`` (N,) signs of the normal forces (paper contact).
    """

    def __init__(self, chain: _Chain, start: str, rtol: float, atol: float, keep_dense: bool = True):
        self.ch = chain
        n = chain.n
        self.n = n
        self.rtol, self.atol = rtol, atol
        self.keep_dense = keep_dense
        self.t = 0.0
        self.y = np.zeros(2 * n + 2)
        self.y[:n] = chain.initial_positions(start)
        self.stuck = np.zeros(n, dtype=bool)
        self.sdir = np.ones(n)
        self.side = np.ones(n)
        self.segments: list[_Segment] = []
        self.events: list[tuple[float, str]] = []
        self.n_switches = 0
        self.liftoff = False
        self.t_liftoff = math.inf
        self.stopped = False
        self._tiny_run = 0
        self._h: float | None = None  # last accepted step size
        # Smallest gap x_{i+1} - x_i seen on the event-search samples (the model assumes x_0 < ... < x_{N-1}).
        self.min_gap = float(np.min(np.diff(self.y[:n])))
        # Functions that start on zero at self.t: {row: rate at self.t}.
        self._restart: dict[int, float] = {}
        w_act = chain.omega * (chain.A.shape[1] if chain.splines is None else max(sp[0] for sp in chain.splines))
        w_fast = max(w_act, _highest_free_frequency(chain.cfg), 1e-3)
        self.max_step = 2.0 * math.pi / w_fast / 8.0
        self._frac = np.arange(1, _N_SUB + 1) / _N_SUB

        F, Nrm = self._forces_now()
        if np.any(Nrm <= 0.0):
            self.liftoff, self.t_liftoff = True, 0.0
            if chain.strict:
                self.stopped = True
        self.side = np.where(Nrm > 0.0, 1.0, -1.0)
        n_i = self._normal(Nrm)
        # Initial modes, all masses at rest: stuck if the static condition holds, else slip along F_i.
        for i in range(n):
            if -chain.cfg["mu_s_bwd"][i] * n_i[i] <= F[i] <= chain.cfg["mu_s_fwd"][i] * n_i[i]:
                self.stuck[i] = True
            else:
                self.sdir[i] = 1.0 if F[i] > 0.0 else -1.0
        self._arm_velocity_restarts([i for i in range(n) if not self.stuck[i]])

    # -- small helpers ---------------------------------------------------------------------
    def _normal(self, Nrm: np.ndarray) -> np.ndarray:
        """Normal force used by friction: ``N`` (strict) or ``|N|`` (paper)."""
        return Nrm if self.ch.strict else np.abs(Nrm)

    def _forces_now(self):
        F, Nrm, *_ = self.ch.forces(np.array([self.t]), self.y[: self.n, None])
        return F[:, 0], Nrm[:, 0]

    @property
    def X(self) -> float:
        return float(self.ch.m_flat @ self.y[: self.n] / self.ch.total_mass)

    def _row(self, block: int, i: int) -> int:
        return block * self.n + i

    # -- right-hand side of the current mode ----------------------------------------------
    def _make_rhs(self):
        """``x_i' = v_i``; slipping ``m_i v_i' = F_i - c_i v_i - sigma_i mu_dir(|v_i|) n_i``; stuck ``v_i' = 0``.

        Within a segment ``sgn v_i = sigma_i`` and ``sgn N_i = side_i`` are fixed, so ``|v_i|``
        and ``|N_i|`` are written ``sigma_i v_i`` and ``side_i N_i``: the right-hand side is smooth
        up to and slightly past the event that ends the segment, which keeps the dense output
        accurate there.  Augmented: ``e_d' = sum mu n |v| + c v^2``, ``w' = sum -T l0' + f (v_j - v_{j+1})``.

        The forces are those of :meth:`_Chain.forces` (which the switching functions use on many
        samples at once), written here for one sample in plain Python floats with the mode's
        constants folded in: DOP853 calls this ~16 times per step, and on arrays of a few elements
        numpy's per-call overhead exceeds the arithmetic (measured 7-15 us per call for N = 2-8,
        against 45-50 us for the same formulas vectorised with numpy).
        """
        ch, n = self.ch, self.n
        cfg = ch.cfg
        slip = [0.0 if s else 1.0 for s in self.stuck]
        sdir = self.sdir.tolist()
        q = [1.0] * n if ch.strict else self.side.tolist()
        m, c = cfg["m"].tolist(), cfg["c"].tolist()
        k, d, lbar = cfg["k"].tolist(), cfg["d"].tolist(), cfg["lbar"].tolist()
        fwd = self.sdir > 0
        mu_k_arr = np.where(fwd, cfg["mu_k_fwd"], cfg["mu_k_bwd"])
        mu_k = mu_k_arr.tolist()
        mu_drop = (np.where(fwd, cfg["mu_s_fwd"], cfg["mu_s_bwd"]) - mu_k_arr).tolist()
        inv_vs2 = (1.0 / cfg["v_s"] ** 2).tolist() if ch.stribeck else None
        # Friction in the equation of motion is -sigma mu n with n = q N: fold sigma q into one factor.
        sq = [sdir[i] * q[i] for i in range(n)]
        hw = ch.harm_omega[:, 0].tolist()
        A, B = ch.A.tolist(), ch.B.tolist()
        A_rate, B_rate = ch.A_rate.tolist(), ch.B_rate.tolist()
        harmonics = range(len(hw))
        springs, masses = range(n - 1), range(n)
        force_act = ch.force_actuator

        splined = ch.splines is not None

        def rhs(t, y):
            cs = [math.cos(w * t) for w in hw]
            sn = [math.sin(w * t) for w in hw]
            sig, sig_rate = ch.signal(t) if splined else ([], [])
            yl = y.tolist()
            x = yl[:n]
            v = [yl[n + i] * slip[i] for i in masses]
            F = [0.0] * n
            N = m.copy()
            power = 0.0
            for j in springs:
                Aj, Bj = A[j], B[j]
                s = 0.0
                if splined:
                    s = sig[j]
                else:
                    for h in harmonics:
                        s += Aj[h] * cs[h] + Bj[h] * sn[h]
                u = x[j + 1] - x[j]
                ell = math.sqrt(u * u + d[j] * d[j])
                if force_act:
                    T = k[j] * (ell - lbar[j])
                    hx = T * u / ell + s
                    power += s * (v[j] - v[j + 1])
                else:
                    T = k[j] * (ell - lbar[j] - s)
                    hx = T * u / ell
                    Ar, Br = A_rate[j], B_rate[j]
                    if splined:
                        power -= T * sig_rate[j]
                    for h in harmonics:
                        power -= T * (Br[h] * cs[h] - Ar[h] * sn[h])
                fy = T * d[j] / ell
                F[j] += hx
                F[j + 1] -= hx
                N[j] -= fy
                N[j + 1] += fy
            acc = [0.0] * n
            e_rate = 0.0
            for i in masses:
                vi = v[i]
                mu = mu_k[i]
                if inv_vs2 is not None:
                    mu += mu_drop[i] * math.exp(-vi * vi * inv_vs2[i])
                fric = mu * sq[i] * N[i]  # sigma_i mu n_i
                acc[i] = slip[i] * (F[i] - c[i] * vi - fric) / m[i]
                e_rate += fric * vi + c[i] * vi * vi  # mu n_i |v_i| + c_i v_i^2
            return np.array(v + acc + [e_rate, power])

        return rhs

    # -- switching functions ----------------------------------------------------------------
    def _switching(self, t: np.ndarray, Y: np.ndarray, t0: float, X_ref, z) -> np.ndarray:
        """All switching functions of the current mode at samples ``t`` (S,), ``Y`` (2N+2, S).

        Returns ``(4N+1, S)``: blocks stick_fwd, stick_bwd, v_zero, normal_zero (N rows each)
        and the target row; rows that do not apply to the mode are ``+inf``.
        Functions that start on zero at ``t0`` are divided by ``t - t0`` (their rate at ``t0``).
        """
        ch, n = self.ch, self.n
        x, v = Y[:n], Y[n : 2 * n]
        F, Nrm, *_ = ch.forces(t, x)
        nn = Nrm if ch.strict else self.side[:, None] * Nrm
        G = np.full((4 * n + 1, t.size), np.inf)
        st = self.stuck
        G[0:n][st] = (ch.mu_s_fwd * nn - F)[st]
        G[n : 2 * n][st] = (F + ch.mu_s_bwd * nn)[st]
        G[2 * n : 3 * n][~st] = (self.sdir[:, None] * v)[~st]
        G[3 * n : 4 * n] = nn
        if X_ref is not None:
            X = (ch.m_flat @ x) / ch.total_mass
            G[4 * n] = z - np.abs(X - X_ref)
        if self._restart:
            dt = t - t0
            for row, rate in self._restart.items():
                G[row] = np.where(dt > 0.0, G[row] / np.where(dt > 0.0, dt, 1.0), rate)
        return G

    def _arm_velocity_restarts(self, masses: list[int]):
        """Mark ``sigma_i v_i`` of masses that (re)start from ``v_i = 0`` at ``self.t`` as restart functions."""
        if not masses:
            return
        acc = self._make_rhs()(self.t, self.y)[self.n : 2 * self.n]
        for i in masses:
            self._restart[self._row(_VEL, i)] = float(self.sdir[i] * acc[i])

    # -- one segment ----------------------------------------------------------------------------
    def _segment(self, t_target: float, X_ref, z):
        """Integrate the current mode from ``self.t`` until the first event or ``t_target``.

        Returns the row of the switching function that ended the segment, or ``None`` at ``t_target``.
        """
        t0 = self.t
        rhs = self._make_rhs()
        G0 = self._switching(np.array([t0]), self.y[:, None], t0, X_ref, z)[:, 0]
        if np.any(G0 < -_TOL_CHECK):
            row = int(np.argmin(G0))
            raise RuntimeError(
                f"state beyond a switching surface at t={t0} ({_ROW_KIND[row // self.n]} "
                f"of mass {row % self.n}, value {G0[row]:.3e}): an event was missed"
            )
        # Start with the previous segment's step size: a fresh step-size selection at every
        # switch would cost a ramp-up per segment (the controller still rejects a step too long).
        first_step = None if self._h is None else min(self._h, self.max_step, t_target - t0)
        # e_d and w are integrated from zero in each segment (their totals at t0 kept aside), so
        # that their error control is relative to the segment's increment, not to the running total.
        acc0 = self.y[2 * self.n :].copy()
        y0 = self.y.copy()
        y0[2 * self.n :] = 0.0
        solver = DOP853(
            rhs,
            t0,
            y0,
            t_bound=t_target,
            rtol=self.rtol,
            atol=self.atol,
            max_step=self.max_step,
            first_step=first_step,
        )
        ts, interps = [t0], []
        g_prev = G0
        hit_row, t_hit, y_hit = None, t_target, None
        while solver.status == "running":
            msg = solver.step()
            if solver.status == "failed":
                raise RuntimeError(f"DOP853 failed at t={solver.t}: {msg}")
            assert solver.t_old is not None and solver.y_old is not None  # set by every step taken
            ta, tb = solver.t_old, solver.t
            p = solver.dense_output()
            grid = ta + (tb - ta) * self._frac
            grid[-1] = tb
            Y = p(grid)
            Y[:, -1] = solver.y
            G = self._switching(grid, Y, t0, X_ref, z)
            self.min_gap = min(self.min_gap, float(np.min(Y[1 : self.n] - Y[: self.n - 1])))
            neg = G < 0.0
            if neg.any():
                rows = np.nonzero(neg.any(axis=1))[0]
                first_neg = np.argmax(neg[rows], axis=1)
                kmin = int(first_neg.min())
                best = math.inf
                # The earliest crossing lies in the first sample interval with a negative value.
                for row in rows[first_neg == kmin]:
                    t_root = self._locate(p, int(row), kmin, grid, G, g_prev, ta, t0, X_ref, z)
                    if t_root < best:
                        best, hit_row = t_root, int(row)
                t_hit = best
                y_hit = p(t_hit) if t_hit > ta else solver.y_old.copy()
                if t_hit > ta:
                    ts.append(t_hit)
                    interps.append(p)
                break
            ts.append(tb)
            interps.append(p)
            g_prev = G[:, -1]
            self._h = solver.h_abs
        if hit_row is None:
            t_hit, y_hit = solver.t, solver.y.copy()
        if t_hit > t0:
            sol = OdeSolution(np.array(ts), interps) if self.keep_dense else None
            self.segments.append(_Segment(t0, t_hit, self.stuck, sol, acc0))
        self.t, self.y = float(t_hit), np.array(y_hit, dtype=float)
        self.y[2 * self.n :] += acc0
        self._restart = {}
        return hit_row

    def _row_value(self, row: int, t: float, y: np.ndarray, t0: float, X_ref, z) -> float:
        """Switching function ``row`` at one time: the value :meth:`_switching` gives in that row,
        computed in Python floats from the (at most two) springs it involves (``brentq`` calls this)."""
        n = self.n
        block, i = divmod(row, n)
        if block == _TARGET:
            return z - abs(float(self.ch.m_flat @ y[:n]) / self.ch.total_mass - X_ref)
        if block == _VEL:
            g = self.sdir[i] * y[n + i]
        else:
            F, Nrm = self.ch.mass_forces(t, y[:n], i)
            nn = Nrm if self.ch.strict else self.side[i] * Nrm
            cfg = self.ch.cfg
            if block == _STICK_FWD:
                g = cfg["mu_s_fwd"][i] * nn - F
            elif block == _STICK_BWD:
                g = F + cfg["mu_s_bwd"][i] * nn
            else:
                g = nn
        if row in self._restart:
            return g / (t - t0) if t > t0 else self._restart[row]
        return float(g)

    def _locate(self, p, row, kmin, grid, G, g_prev, ta, t0, X_ref, z) -> float:
        """First zero of switching function ``row`` in ``(grid[kmin-1], grid[kmin]]`` (brentq on the dense output)."""
        if kmin > 0:
            tl, gl = grid[kmin - 1], G[row, kmin - 1]
        else:
            tl, gl = ta, g_prev[row]
        if gl <= 0.0:
            return float(tl)

        def g(t):
            return self._row_value(row, t, p(t), t0, X_ref, z)

        eps = 4 * np.finfo(float).eps
        # A float without `full_output` (scipy's stubs return every variant's type).
        return float(cast(float, brentq(g, tl, grid[kmin], xtol=eps * max(1.0, abs(tl)), rtol=eps)))

    # -- re-decision after an event ---------------------------------------------------------
    def _log(self, kind: str, switch: bool = True):
        self.events.append((self.t, kind))
        if switch:
            self.n_switches += 1

    def _redecide(self, forced_row: int):
        """Apply the transition rules to EVERY mass at the current state.

        The mass whose function ended the segment switches unconditionally; any other mass
        switches if it lies within a tiny tolerance of its own switching surface (stuck: a
        static limit; slipping: ``v_i = 0`` with the acceleration pointing back).
        """
        ch, n = self.ch, self.n
        cfg = ch.cfg
        F, Nrm = self._forces_now()
        nn = self._normal(Nrm)
        acc = self._make_rhs()(self.t, self.y)[n : 2 * n]
        block, forced = divmod(forced_row, n)
        restarted = []
        for i in range(n):
            hi, lo = cfg["mu_s_fwd"][i] * nn[i], -cfg["mu_s_bwd"][i] * nn[i]
            if self.stuck[i]:
                up = (block == _STICK_FWD and forced == i) or hi - F[i] <= _TOL_FORCE
                down = (block == _STICK_BWD and forced == i) or F[i] - lo <= _TOL_FORCE
                if up or down:
                    # Both limits at once only when n_i ~ 0 and F_i ~ 0: follow the force.
                    new = 1.0 if (up and not down) or (up and down and F[i] >= 0.0) else -1.0
                    self.stuck[i] = False
                    self.sdir[i] = new
                    self.y[n + i] = 0.0
                    restarted.append(i)
                    self._log(f"m{i} stick->slip {'fwd' if new > 0 else 'bwd'}")
            else:
                s, v = self.sdir[i], self.y[n + i]
                if (block == _VEL and forced == i) or (s * v <= _TOL_VEL and s * acc[i] < 0.0):
                    self.y[n + i] = 0.0  # exactly on the switching surface
                    if lo <= F[i] <= hi:
                        self.stuck[i] = True
                        self._log(f"m{i} slip->stick")
                    else:
                        new = 1.0 if F[i] > hi else -1.0
                        restarted.append(i)
                        if new != s:
                            self.sdir[i] = new
                            self._log(f"m{i} reverse", switch=False)
        self._arm_velocity_restarts(restarted)

    # -- main loop --------------------------------------------------------------------------------
    def advance(self, t_target: float, X_ref: float | None = None, z: float | None = None) -> str:
        """Integrate to ``t_target``; returns ``"time"``, ``"liftoff"`` (strict stop) or ``"target"``."""
        if self.stopped:
            return "liftoff"
        n = self.n
        while self.t < t_target:
            if len(self.segments) >= _MAX_SEGMENTS:
                raise RuntimeError(f"segment cap {_MAX_SEGMENTS} exceeded at t={self.t} (chattering?)")
            t0 = self.t
            row = self._segment(t_target, X_ref, z)
            if row is None:
                return "time"
            self._tiny_run = self._tiny_run + 1 if self.t - t0 < _TINY_DT * (1.0 + abs(t0)) else 0
            if self._tiny_run > _MAX_TINY_SEGMENTS:
                raise RuntimeError(f"Zeno/chattering: {self._tiny_run} zero-length segments at t={self.t}")
            block, i = divmod(row, n)
            if block == _TARGET:
                return "target"
            if block == _NORMAL:
                if not self.liftoff:
                    self.liftoff, self.t_liftoff = True, self.t
                self._log(f"m{i} normal {'off' if self.side[i] > 0 else 'on'}", switch=False)
                if self.ch.strict:
                    self.stopped = True
                    return "liftoff"
                self.side[i] = -self.side[i]
                self._redecide(row)
                rate = self.ch.normal_rate(self.t, self.y[:n], self.y[n : 2 * n] * (~self.stuck))
                self._restart[row] = float(self.side[i] * rate[i])
                continue
            self._redecide(row)
        return "time"

    # -- sampling ----------------------------------------------------------------------------------
    def sample(self, ts: np.ndarray):
        """Augmented state (2N+2, S) and stuck flags (S, N) at times ``ts`` within the integrated range."""
        out = np.empty((2 * self.n + 2, ts.size))
        stuck = np.empty((ts.size, self.n), dtype=bool)
        if not self.segments:
            out[:] = self.y[:, None]
            stuck[:] = self.stuck
            return out, stuck
        starts = np.array([s.t0 for s in self.segments])
        idx = np.clip(np.searchsorted(starts, ts, side="right") - 1, 0, len(self.segments) - 1)
        for kseg in np.unique(idx):
            sel = idx == kseg
            seg = self.segments[kseg]
            out[:, sel] = seg.sol(np.clip(ts[sel], seg.t0, seg.t1))
            out[2 * self.n :, sel] += seg.acc0[:, None]
            stuck[sel] = seg.stuck
        # A stuck mass is exactly at rest.
        out[self.n : 2 * self.n][stuck.T] = 0.0
        return out, stuck

    def stuck_time(self, ta: float, tb: float) -> np.ndarray:
        """Total time each mass is stuck within ``[ta, tb]`` (N,)."""
        tot = np.zeros(self.n)
        for seg in self.segments:
            lo, hi = max(seg.t0, ta), min(seg.t1, tb)
            if hi > lo:
                tot += (hi - lo) * seg.stuck
        return tot


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------
def reference_chain_simulate(
    cfg: dict,
    t_end: float,
    save_at=None,
    contact: str = "strict",
    start: str = "paper",
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> dict:
    """Simulate the exact hybrid chain on ``[0, t_end]`` and sample it at ``save_at``.

    Args:
        cfg: a dict from :func:`chain_config`.
        t_end: final time (> 0).
        save_at: 1-D times in ``[0, t_end]`` (default ``np.linspace(0, t_end, 1001)``).
        contact: ``"strict"`` (stop at the first lift-off) or ``"paper"`` (``n_i = |N_i|``, flagged).
        start: ``"paper"`` (gaps ``lbar_j``) or ``"relaxed"``.
        rtol, atol: DOP853 tolerances.

    Returns:
        dict with ``t`` (S,), ``x, v`` (S, N), ``stuck`` (S, N) bools, ``e_d, w, e, X`` (S,),
        ``liftoff`` (bool), ``t_liftoff`` (inf if none), ``status`` (``"liftoff"`` if any normal
        force reached zero, else ``"ok"``), ``valid_until`` (the strict stop time, else ``t_end``;
        later samples repeat the state there), ``n_switches``, ``n_segments``, ``events``
        (list of ``(t, kind)``) and ``min_gap``, the smallest ``x_{i+1} - x_i`` met (the model
        assumes the masses stay in order; a non-positive value means they passed each other).
    """
    chain = _Chain(cfg, contact)
    t_end = float(t_end)
    ts = np.linspace(0.0, t_end, 1001) if save_at is None else np.atleast_1d(np.asarray(save_at, dtype=float))
    if ts.ndim != 1 or np.any(ts < 0.0) or np.any(ts > t_end):
        raise ValueError(f"save_at must be a 1-D array of times in [0, t_end={t_end}]")
    solver = _ChainSolver(chain, start, rtol, atol)
    solver.advance(t_end)
    valid_until = solver.t if solver.stopped else t_end
    ts_eval = np.minimum(ts, valid_until)
    Y, stuck = solver.sample(ts_eval)
    n = chain.n
    x, v = Y[:n], Y[n : 2 * n]
    return dict(
        t=ts.copy(),
        x=x.T.copy(),
        v=v.T.copy(),
        stuck=stuck,
        e_d=Y[2 * n].copy(),
        w=Y[2 * n + 1].copy(),
        e=chain.energy(ts_eval, x, v),
        X=(chain.m_flat @ x) / chain.total_mass,
        liftoff=bool(solver.liftoff),
        t_liftoff=float(solver.t_liftoff),
        status="liftoff" if solver.liftoff else "ok",
        valid_until=float(valid_until),
        n_switches=int(solver.n_switches),
        n_segments=len(solver.segments),
        events=list(solver.events),
        min_gap=solver.min_gap,
    )


def reference_chain_measure(
    cfg: dict,
    z: float = 5.0,
    t_start: float | None = None,
    horizon: float = 2000.0,
    window: float = 25.0,
    contact: str = "strict",
    start: str = "paper",
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> dict:
    """Measurements of CHAIN_CONVENTIONS.md ("Measurement") on the exact hybrid chain.

    * ``t_start``: given, or :func:`default_t_start` (80 periods of the lowest natural frequency
      with one mass held fixed, minimised over the held mass).
    * ``tau_z``: first time after ``t_start`` at which ``|X - X(t_start)| = z`` (an event);
      ``e_z`` the dissipated energy over it.  Not reached by ``t_start + horizon`` (or a strict
      lift-off first): ``reached = False``, ``tau_z = e_z = inf``.
    * ``t_end``: the crossing if reached, else the horizon end (or the strict lift-off time);
      ``mean_speed = (X(t_end) - X(t_start)) / (t_end - t_start)`` (NaN if ``t_end <= t_start``);
      ``e_d``, ``work`` and ``delta_e = e(t_end) - e(t_start)`` over ``[t_start, t_end]``
      (``work = e_d + delta_e``).
    * ``regime`` over ``[t_start, t_start + window]``: ``"SSL"`` if any mass is stuck for a positive
      time (total above 1e-6), else ``"SL"``; ``None`` if a strict lift-off ended the run before the
      window did.  ``stick_fraction`` (N,): stuck time of each mass / window (NaN then).

    Returns a dict with the keys above and ``reached, liftoff, t_liftoff, t_start, t_end, n_segments, min_gap``
    (the smallest gap ``x_{i+1} - x_i`` met over the whole run).
    """
    chain = _Chain(cfg, contact)
    t_start = default_t_start(cfg) if t_start is None else float(t_start)
    if not (t_start >= 0.0 and horizon > 0.0 and window > 0.0 and z > 0.0):
        raise ValueError("need t_start >= 0, horizon > 0, window > 0 and z > 0")
    solver = _ChainSolver(chain, start, rtol, atol, keep_dense=False)
    n = chain.n
    nan, inf = math.nan, math.inf
    out: dict[str, Any] = dict(
        tau_z=inf,
        e_z=inf,
        reached=False,
        regime=None,
        mean_speed=nan,
        stick_fraction=np.full(n, nan),
        e_d=nan,
        work=nan,
        delta_e=nan,
        t_start=t_start,
        t_end=nan,
    )

    def energy_now() -> float:
        y = solver.y
        return float(chain.energy(np.array([solver.t]), y[:n, None], y[n : 2 * n, None])[0])

    if solver.advance(t_start) == "time":
        X_s, ed_s, w_s, e_s = solver.X, float(solver.y[2 * n]), float(solver.y[2 * n + 1]), energy_now()
        reason = solver.advance(t_start + horizon, X_ref=X_s, z=z)
        t_end = solver.t
        out.update(
            t_end=t_end,
            e_d=float(solver.y[2 * n]) - ed_s,
            work=float(solver.y[2 * n + 1]) - w_s,
            delta_e=energy_now() - e_s,
        )
        if t_end > t_start:
            out["mean_speed"] = (solver.X - X_s) / (t_end - t_start)
        if reason == "target":
            out.update(tau_z=t_end - t_start, e_z=out["e_d"], reached=True)
        t_window = t_start + window
        if solver.t < t_window:
            solver.advance(t_window)
        if solver.t >= t_window:
            stuck = solver.stuck_time(t_start, t_window)
            out.update(regime="SSL" if np.any(stuck > _STUCK_POSITIVE) else "SL", stick_fraction=stuck / window)
    out.update(
        liftoff=bool(solver.liftoff),
        t_liftoff=float(solver.t_liftoff),
        n_segments=len(solver.segments),
        min_gap=solver.min_gap,
    )
    return out
