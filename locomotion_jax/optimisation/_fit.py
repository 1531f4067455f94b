"""Parameter identification: fit the exact model to a measured trajectory.

Least squares on the positions of both masses at the measured times,

$$\\min_\\theta \\sum_{s,i} \\big(x_i(t_s; \\theta) - \\hat x_{i,s}\\big)^2 / \\sigma^2,$$

with the model run by the exact engine and its Jacobian by forward-mode
differentiation through the located stick/slip events (README, "Gradients").
The solver is scipy's trust-region reflective least squares (`least_squares`,
method `"trf"`): it takes a materialised Jacobian, which is what forward mode
gives, and keeps each parameter inside its bounds. Standard errors come from the
Gauss-Newton covariance $(J^\\top J)^{-1}$ at the optimum, scaled by the residual
variance unless the noise level `sigma` is given.
"""

from collections.abc import Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._status import Status
from ..dynamics._exact_dynamics import Exact
from ..model._params import PARAM_NAMES, Params
from ..model._waveform import AbstractWaveform
from ..run._simulate import simulate


BOUNDS: dict[str, tuple[float, float]] = {
    "k": (0.0, np.inf),
    "c": (0.0, np.inf),
    "d": (-np.inf, np.inf),
    "lbar": (0.0, np.inf),
    "a": (0.0, np.inf),
    "omega": (0.0, np.inf),
    "mu_s": (0.0, np.inf),
    "mu_k": (0.0, np.inf),
    "mhat": (0.0, 1.0),
}
"""Bounds of each parameter during a fit (the model's validity, eq. 6; `mu_s >= mu_k`
is checked on the result)."""


class FitResult(NamedTuple):
    """What [`fit_trajectory`][] found.

    - `params`: the fitted `Params` (the parameters not fitted as given).
    - `names`, `values`, `stderr`: the fitted parameters, their estimates and standard errors.
    - `covariance`: the estimates' covariance (Gauss-Newton, at the optimum).
    - `residual_rms`: root mean square of the position residuals; `sigma`: the noise level
      used for the errors (given, or estimated from the residuals).
    - `n_evaluations`: model runs (each with its Jacobian); `success`, `message`: the solver's.
    - `status`: the model run's `Status` at the optimum (`OK`, or why the run stopped).
    """

    params: Params
    names: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    residual_rms: float
    sigma: float
    n_evaluations: int
    success: bool
    message: str
    status: int

    def summary(self) -> str:
        """A Markdown table of the estimates with their standard errors."""
        rows = ["| parameter | estimate | standard error |", "|---|---|---|"]
        rows += [f"| {n} | {v:.6g} | {e:.2g} |" for n, v, e in zip(self.names, self.values, self.stderr)]
        return "\n".join(rows)


def _check(t: np.ndarray, x: np.ndarray, params: Params, names: Sequence[str]) -> None:
    if not isinstance(params, Params) or params.batch_shape != ():
        raise ValueError("params must be one configuration (a Params without batch axes).")
    if len(names) == 0 or len(set(names)) != len(names) or not set(names) <= set(PARAM_NAMES):
        raise ValueError(f"names must be distinct parameter names from {PARAM_NAMES}, got {tuple(names)}.")
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or t[0] < 0 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be a non-empty 1-D array of increasing finite times >= 0.")
    if x.shape != (t.size, 2):
        raise ValueError(f"x must have shape (len(t), 2) = ({t.size}, 2) (positions of both masses), got {x.shape}.")
    if np.sum(np.isfinite(x)) <= len(names):
        raise ValueError(f"x needs more finite samples than fitted parameters ({len(names)}).")


def fit_trajectory(
    t: Any,
    x: Any,
    params: Params,
    names: Sequence[str] = ("mu_s", "mu_k", "c", "k"),
    *,
    sigma: float | None = None,
    waveform: AbstractWaveform | None = None,
    dynamics: Exact | None = None,
    contact: str = "strict",
    start: str = "paper",
    max_evaluations: int = 100,
) -> FitResult:
    """Fit model parameters to measured positions of the two masses (least squares).

    **Arguments:**

    - `t`: measurement times (increasing, $\\ge 0$), shape `(S,)`.
    - `x`: measured positions $(x_1, x_2)$ at `t`, shape `(S, 2)`; NaN marks a missing sample.
    - `params`: the starting point of the fit, and the values of the parameters not fitted.
    - `names`: the `Params` fields to fit.
    - `sigma`: the measurement noise's standard deviation, if known; otherwise it is
      estimated from the residuals (the standard errors scale with it).
    - `waveform`, `dynamics`, `contact`, `start`: as in [`simulate`][] (exact dynamics).
    - `max_evaluations`: cap on the model runs.

    **Returns:** a [`FitResult`][].

    **Raises:** `ValueError` for invalid arguments. Runs in float64 precision when JAX's
    `jax_enable_x64` is on (recommended: the Jacobian is then accurate to the engine's
    order, README "Gradients").
    """
    from scipy.optimize import least_squares

    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    names = tuple(names)
    _check(t, x, params, names)
    dynamics = Exact() if dynamics is None else dynamics
    if not isinstance(dynamics, Exact):
        raise TypeError("fit_trajectory needs the Exact dynamics.")
    mask = np.isfinite(x)
    t_end = float(t[-1]) if t[-1] > 0 else 1.0
    base = {n: getattr(params, n) for n in PARAM_NAMES}
    scale = 1.0 if sigma is None else float(sigma)
    if not scale > 0:
        raise ValueError(f"sigma must be > 0, got {sigma!r}.")

    def positions(theta):
        p = Params(**{**base, **{n: theta[i] for i, n in enumerate(names)}}, check=False)
        traj = simulate(p, t_end, t, dynamics=dynamics, waveform=waveform, contact=contact, start=start)
        return jnp.stack([traj.x1, traj.x2], -1), traj.status

    def model_and_jacobian(theta):
        # One forward-mode pass per fitted parameter, all in one compiled call.
        theta = jnp.asarray(theta, params.dtype)
        basis = jnp.eye(len(names), dtype=theta.dtype)
        (xs, status), (jac, _) = jax.vmap(lambda e: jax.jvp(positions, (theta,), (e,)))(basis)
        return np.asarray(xs[0]), int(status[0]), np.moveaxis(np.asarray(jac), 0, -1)

    cache: dict[bytes, tuple] = {}

    def evaluate(theta):
        key = np.asarray(theta, float).tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = model_and_jacobian(theta)
        return cache[key]

    def residual(theta):
        return (evaluate(theta)[0] - x)[mask] / scale

    def jacobian(theta):
        return evaluate(theta)[2][mask] / scale

    lower = np.array([BOUNDS[n][0] for n in names])
    upper = np.array([BOUNDS[n][1] for n in names])
    theta0 = np.clip(np.array([float(base[n]) for n in names]), lower, upper)
    sol = least_squares(
        residual,
        theta0,
        jac=jacobian,  # pyright: ignore[reportArgumentType]  (a callable is accepted)
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=max_evaluations,
    )
    _, status, _ = evaluate(sol.x)
    r, jac = sol.fun, sol.jac
    dof = max(r.size - len(names), 1)
    # Gauss-Newton covariance; a parameter the data do not determine gets an infinite error.
    info = jac.T @ jac
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        cov = np.full(info.shape, np.inf)
    s2 = 1.0 if sigma is not None else float(r @ r) / dof
    cov = cov * s2
    fitted = Params(**{**base, **{n: float(v) for n, v in zip(names, sol.x)}}, check=False)
    rms = float(np.sqrt(np.mean((r * scale) ** 2)))
    return FitResult(
        params=fitted,
        names=names,
        values=np.asarray(sol.x),
        stderr=np.sqrt(np.abs(np.diag(cov))),
        covariance=cov,
        residual_rms=rms,
        sigma=float(np.sqrt(s2) * scale) if sigma is None else float(sigma),
        n_evaluations=int(sol.nfev),
        success=bool(sol.success) and status == Status.OK,
        message=str(sol.message)
        if status == Status.OK
        else f"{sol.message}; the model run ended {Status(status).name}",
        status=status,
    )
