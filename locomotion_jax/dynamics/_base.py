"""Choice of dynamics: the exact hybrid model or its smoothed counterpart.

Abstract/final pattern (equinox): callers dispatch on the concrete class.
Python numbers here are static (changing them recompiles); `Smoothed.eps` is an
array, so a continuation in `eps` does not recompile.
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike
from ._forward import check_static


class AbstractDynamics(eqx.Module):
    """Base class of the dynamics strategies."""

    @abc.abstractmethod
    def describe(self) -> dict:
        """Attributes recorded with every result (for provenance)."""


class Exact(AbstractDynamics):
    """Exact hybrid stick/slip dynamics (eqs. 7, 9) with located switches.

    **Arguments:**

    - `dt`: nominal RK4 step (fourth order; see README for accuracy vs `dt`).
    - `max_steps`: hard cap on integrator iterations (trial steps included);
      `None` picks one from the horizon.
    """

    dt: float = eqx.field(static=True, default=0.01)
    max_steps: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        check_static("Exact.dt", self.dt)
        if not (isinstance(self.dt, (int, float)) and 0 < self.dt <= 0.1):
            raise ValueError(f"Exact.dt must be a number in (0, 0.1], got {self.dt!r}.")
        if self.max_steps is not None and not (isinstance(self.max_steps, int) and self.max_steps > 0):
            raise ValueError(f"Exact.max_steps must be a positive int or None, got {self.max_steps!r}.")

    def describe(self) -> dict:
        return {"dynamics": "exact", "dt": self.dt}


class Smoothed(AbstractDynamics):
    """Smoothed friction integrated by diffrax (SPEC §3); differentiable.

    Friction on a mass with normal force $n$ and velocity $v$:

    $$f(v) = -n\\,\\big[\\mu_k + (\\mu_s - \\mu_k)\\, e^{-(v/v_s)^2}\\big] \\tanh(v/\\varepsilon),
    \\qquad v_s = \\sqrt{\\varepsilon},$$

    a regularised sign with a Stribeck-like static bump. As $\\varepsilon \\to 0$,
    $v_s \\to 0$ and $v_s / \\varepsilon \\to \\infty$, so the peak friction tends to
    $\\mu_s n$ and the sliding friction to $\\mu_k n$: the exact law.

    **Arguments:**

    - `eps`: regularisation velocity $\\varepsilon > 0$ (traced).
    - `rtol`, `atol`: tolerances of diffrax's PID step-size controller.
    - `max_steps`: diffrax's step cap.
    - `solver`: `"tsit5"` (explicit, default) or `"kvaerno5"` (implicit, for very small `eps`).
    """

    eps: Array
    rtol: float = eqx.field(static=True, default=1e-7)
    atol: float = eqx.field(static=True, default=1e-9)
    max_steps: int = eqx.field(static=True, default=2_000_000)
    solver: str = eqx.field(static=True, default="tsit5")

    def __init__(
        self,
        eps: ArrayLike = 1e-3,
        rtol: float = 1e-7,
        atol: float = 1e-9,
        max_steps: int = 2_000_000,
        solver: str = "tsit5",
    ):
        self.eps = jnp.asarray(eps)
        self.rtol, self.atol, self.max_steps, self.solver = rtol, atol, max_steps, solver
        if solver not in ("tsit5", "kvaerno5"):
            raise ValueError(f"Smoothed.solver must be 'tsit5' or 'kvaerno5', got {solver!r}.")
        if not (rtol > 0 and atol > 0):
            raise ValueError(f"Smoothed.rtol and atol must be > 0, got {rtol!r}, {atol!r}.")
        try:
            bad = bool(jnp.any(~(self.eps > 0)))
        except Exception:  # traced eps: checked by the caller's status instead
            bad = False
        if bad:
            raise ValueError(f"Smoothed.eps must be > 0, got {eps!r}.")

    def describe(self) -> dict:
        return {
            "dynamics": "smoothed",
            "eps": float(jnp.max(self.eps)),
            "rtol": self.rtol,
            "atol": self.atol,
            "solver": self.solver,
        }
