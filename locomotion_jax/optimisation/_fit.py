"""Parameter identification: fit the exact model to a measured trajectory.

Least squares on the positions of the bodies (the paper's model: both masses; a chain:
every mass) at the measured times,

$$\\min_\\theta \\sum_{s,i} \\big(x_i(t_s; \\theta) - \\hat x_{i,s}\\big)^2 / \\sigma^2,$$

with the model run by the exact engine and its Jacobian by forward-mode
differentiation through the located stick/slip events (README, "Gradients").
The solver is scipy's trust-region reflective least squares (`least_squares`,
method `"trf"`): it takes a materialised Jacobian, which is what forward mode
gives, and keeps each parameter inside its bounds. Standard errors come from the
Gauss-Newton covariance $(J^\\top J)^{-1}$ at the optimum, scaled by the residual
variance unless the noise level `sigma` is given.
"""

import re
from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._status import Status
from ..dynamics._exact_dynamics import Exact
from ..model._mechanism import AbstractMechanism
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
    "m": (0.0, np.inf),
    "v_s": (0.0, np.inf),
}
"""Bounds of each parameter during a fit, by its field's name (the last part of a dotted name;
any friction coefficient `mu_*` is $\\ge 0$; a field not listed is unbounded): the model's
validity (eq. 6). `mu_s >= mu_k` and the rest of the validity are checked on the result's run."""


def _bounds(name: str) -> tuple[float, float]:
    last = name.rsplit(".", 1)[-1]
    return BOUNDS.get(last, (0.0, np.inf) if last.startswith("mu_") else (-np.inf, np.inf))


def _field(mechanism: Any, name: str) -> Any:
    """The field `name` of the mechanism: an attribute, dotted for a nested one
    (`"friction.mu_k_fwd"`), with `[i]` for an item of a tuple (a [`Mechanism`][locomotion_jax.Mechanism]'s
    `"links[0].k"`, `"friction[0].mu_k_fwd"`); a bare name that the mechanism lacks is looked up in
    its friction law (`"mu_k"` of a chain with `Coulomb` friction)."""
    obj = mechanism
    parts = name.split(".")
    if len(parts) == 1 and not hasattr(mechanism, name) and hasattr(getattr(mechanism, "friction", None), name):
        parts = ["friction", name]
    for part in parts:
        m = re.fullmatch(r"([A-Za-z]\w*)(?:\[(\d+)\])?", part)
        if m is None or not hasattr(obj, m.group(1)):
            raise ValueError(
                f"names: {name!r} is not a field of the {type(mechanism).__name__} (a dotted name reaches a "
                "nested one, e.g. 'friction.mu_k_fwd', and [i] an item of a tuple, e.g. 'links[0].k')."
            )
        obj = getattr(obj, m.group(1))
        if m.group(2) is not None:
            i = int(m.group(2))
            if not isinstance(obj, tuple) or i >= len(obj):
                size = f"has items 0..{len(obj) - 1}" if isinstance(obj, tuple) else "is not a tuple"
                raise ValueError(f"names: {name!r}: {m.group(1)!r} {size}.")
            obj = obj[i]
    return obj


class FitResult(NamedTuple):
    """What [`fit_trajectory`][] found.

    - `params`: the fitted mechanism (the parameters not fitted as given).
    - `names`, `values`, `stderr`: the fitted parameters, their estimates and standard errors (a
      field with several entries, such as a chain's `k` given per spring, gives one per entry: `k[0]`, ...).
    - `covariance`: the estimates' covariance (Gauss-Newton, at the optimum).
    - `residual_rms`: root mean square of the position residuals; `sigma`: the noise level
      used for the errors (given, or estimated from the residuals).
    - `n_evaluations`: model runs (each with its Jacobian); `success`, `message`: the solver's.
    - `status`: the model run's `Status` at the optimum (`OK`, or why the run stopped).
    """

    params: AbstractMechanism
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


def _check(t: np.ndarray, x: np.ndarray, mechanism: AbstractMechanism, names: Sequence[str]) -> int:
    """Refuse bad arguments with a message naming them; the mechanism's number of bodies."""
    if not isinstance(mechanism, AbstractMechanism) or mechanism.batch_shape != ():
        raise ValueError("params must be one configuration (a mechanism without batch axes).")
    if len(names) == 0 or len(set(names)) != len(names):
        raise ValueError(f"names must be distinct parameter names, got {tuple(names)}.")
    for name in names:
        leaf = _field(mechanism, name)
        if not (isinstance(leaf, jax.Array | np.ndarray) and jnp.issubdtype(leaf.dtype, jnp.floating)):
            raise ValueError(f"names: {name!r} is not a floating-point field of the {type(mechanism).__name__}.")
    n = mechanism.physics().n_bodies
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or t[0] < 0 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be a non-empty 1-D array of increasing finite times >= 0.")
    if x.shape != (t.size, n):
        raise ValueError(
            f"x must have shape (len(t), {n}) = ({t.size}, {n}) (positions of the {n} bodies), got {x.shape}."
        )
    return n


def fit_trajectory(
    t: Any,
    x: Any,
    params: AbstractMechanism,
    names: Sequence[str] = ("mu_s", "mu_k", "c", "k"),
    *,
    sigma: float | None = None,
    waveform: AbstractWaveform | None = None,
    dynamics: Exact | None = None,
    contact: str = "strict",
    start: str = "paper",
    max_evaluations: int = 100,
) -> FitResult:
    """Fit a mechanism's parameters to measured positions of its bodies (least squares).

    **Arguments:**

    - `t`: measurement times (increasing, $\\ge 0$), shape `(S,)`.
    - `x`: measured positions of the N bodies at `t`, shape `(S, N)` (the paper's model:
      $(x_1, x_2)$); NaN marks a missing sample.
    - `params`: the mechanism, one configuration (a [`Params`][locomotion_jax.Params], a
      [`Chain`][locomotion_jax.Chain], ...): the starting point of the fit, and the values of
      the parameters not fitted.
    - `names`: the fields to fit: of a `Params`, its parameter names; of another mechanism,
      its floating-point fields, dotted for nested ones (`"k"`, `"c"`, `"friction.mu_k_fwd"`;
      a bare friction coefficient such as `"mu_k"` is looked up in the friction law), with `[i]`
      for an item of a tuple (a [`Mechanism`][locomotion_jax.Mechanism]'s `"links[0].k"`,
      `"friction[0].mu_k_fwd"`). A field with several entries (a chain's `k` given per spring) is
      fitted entry by entry.
    - `sigma`: the measurement noise's standard deviation, if known; otherwise it is
      estimated from the residuals (the standard errors scale with it).
    - `waveform`, `dynamics`, `contact`, `start`: as in [`simulate`][] (exact dynamics;
      `waveform` for the paper's model only, a chain carries its own).
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
    if np.sum(np.isfinite(x)) <= sum(np.size(_field(params, n)) for n in names):
        raise ValueError("x needs more finite samples than fitted parameters.")
    mask = np.isfinite(x)
    t_end = float(t[-1]) if t[-1] > 0 else 1.0
    scale = 1.0 if sigma is None else float(sigma)
    if not scale > 0:
        raise ValueError(f"sigma must be > 0, got {sigma!r}.")
    leaves = [jnp.asarray(_field(params, n)) for n in names]
    sizes = [leaf.size for leaf in leaves]
    labels = tuple(
        n if leaf.size == 1 else f"{n}[{', '.join(map(str, i))}]"
        for n, leaf in zip(names, leaves)
        for i in np.ndindex(*leaf.shape)
    )
    edges = np.cumsum([0, *sizes])

    def build(theta):
        # Bypasses the constructor's checks (traced values); the run flags an invalid one.
        vals = [jnp.reshape(theta[a:b], leaf.shape).astype(leaf.dtype) for a, b, leaf in zip(edges, edges[1:], leaves)]
        return eqx.tree_at(lambda m: [_field(m, n) for n in names], params, vals)

    def positions(theta):
        traj = simulate(build(theta), t_end, t, dynamics=dynamics, waveform=waveform, contact=contact, start=start)
        return traj.x, traj.status

    def model_and_jacobian(theta):
        # One forward-mode pass per fitted parameter, all in one compiled call.
        theta = jnp.asarray(theta, params.dtype)
        basis = jnp.eye(theta.size, dtype=theta.dtype)
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

    lower = np.concatenate([np.full(size, _bounds(n)[0]) for n, size in zip(names, sizes)])
    upper = np.concatenate([np.full(size, _bounds(n)[1]) for n, size in zip(names, sizes)])
    theta0 = np.clip(np.concatenate([np.ravel(np.asarray(leaf, float)) for leaf in leaves]), lower, upper)
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
    dof = max(r.size - len(labels), 1)
    # Gauss-Newton covariance; a parameter the data do not determine gets an infinite error.
    info = jac.T @ jac
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        cov = np.full(info.shape, np.inf)
    s2 = 1.0 if sigma is not None else float(r @ r) / dof
    cov = cov * s2
    fitted = build(jnp.asarray(sol.x, params.dtype))
    rms = float(np.sqrt(np.mean((r * scale) ** 2)))
    return FitResult(
        params=fitted,
        names=labels,
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
