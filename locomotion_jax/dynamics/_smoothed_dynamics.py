"""`Smoothed`: smoothed friction integrated by diffrax (SPEC §3), as an `AbstractDynamics`.

`eps` is an array (traced: a continuation in `eps` does not recompile); the solver's
settings are static. The runs are diffrax's `diffeqsolve` under `vmap` (`_smooth` for
the two-mass model, `_chain_smooth` for chains): one loop of diffrax's own, which the
exact engines' work queue cannot take step by step.
"""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.sharding import Mesh

from .._custom_types import Array, ArrayLike
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform, Sinusoid
from . import _chain_smooth, _smooth
from ._base import AbstractDynamics


_EXACT_ONLY = (
    "t_start= and initial= are supported by the Exact dynamics only; the smoothed model uses "
    "Params.t_start and the start= positions."
)


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

    def simulate_two_mass(
        self,
        params: Params,
        wave: AbstractWaveform,
        wave_axes: int | None,
        save_at: Array,
        t_end: float,
        contact: str,
        start: str,
        initial: Array | None,
    ) -> dict[str, Array]:
        if initial is not None:
            raise ValueError("initial= is supported by the Exact dynamics only.")
        return _smooth.simulate_smoothed(params, wave, wave_axes, save_at, contact, start, self)

    def measure_two_mass(
        self,
        params: Params,
        wave: AbstractWaveform,
        wave_axes: int | None,
        z: float,
        horizon: float,
        window: float,
        contact: str,
        start: str,
        t_start: Array | None,
        initial: Array | None,
    ) -> dict[str, Array]:
        if t_start is not None or initial is not None:
            raise ValueError(_EXACT_ONLY)
        return _smooth.measure_smoothed(params, wave, wave_axes, z, horizon, window, contact, start, self)

    def simulate_chain(
        self,
        chain: Chain | Mechanism,
        valid: Array,
        save_at: Array,
        t_end: float,
        contact: str,
        start: str,
        initial: Array | None = None,
    ) -> dict[str, Array]:
        if initial is not None:
            raise ValueError("initial= is supported by the Exact dynamics only.")
        chain = _chain_only(chain)
        return _chain_smooth.simulate_batch(chain, valid, save_at, contact, start, self.astype(chain.dtype))

    def measure_chain(
        self,
        chain: Chain | Mechanism,
        valid: Array,
        t_start: Array,
        z: float,
        horizon: float,
        window: float,
        contact: str,
        start: str,
        initial: Array | None = None,
    ) -> dict[str, Array]:
        if initial is not None:
            raise ValueError("initial= is supported by the Exact dynamics only.")
        chain = _chain_only(chain)
        z_, h_, w_ = (jnp.asarray(v, chain.dtype) for v in (z, horizon, window))
        dyn = self.astype(chain.dtype)
        return _chain_smooth.measure_batch(chain, valid, t_start, z_, h_, w_, contact, start, dyn)

    def measure_chunk(
        self,
        params: Params,
        zhw: Array,
        contact: str,
        start: str,
        max_steps: int,
        mesh: Mesh,
        lanes: int | None,
    ) -> dict[str, Array]:
        # diffrax's closure conversion rejects shard_map's per-device types, so the
        # smoothed model is left to jit's automatic partitioning of the sharded batch
        # (correct, but every device iterates until the slowest configuration is done).
        z, horizon, window = zhw[0], zhw[1], zhw[2]
        wave = Sinusoid.from_params(params)
        one = lambda q, w: _smooth.measure_one(q, w, z, horizon, window, contact, start, self)
        if not lanes or lanes >= params.omega.shape[0]:
            return jax.vmap(one)(params, wave)
        # Sub-batches in sequence, each vmapped: a sub-batch's while_loop stops with
        # its own slowest configuration, and its state stays in cache.
        return jax.lax.map(lambda args: one(*args), (params, wave), batch_size=lanes)

    def step_cap(self, t_total: float) -> int:
        return 0  # each diffrax solve is capped by `max_steps`

    def nominal_step(self) -> float | None:
        return None  # adaptive steps

    def describe(self) -> dict[str, Any]:
        return {
            "dynamics": "smoothed",
            "eps": float(jnp.max(self.eps)),
            "rtol": self.rtol,
            "atol": self.atol,
            "solver": self.solver,
        }

    def spec(self) -> dict[str, Any]:
        return self.describe()


def _chain_only(chain: Chain | Mechanism) -> Chain:
    """The smoothed engine's N-body path runs chains (its friction is smoothed per chain); a
    `Mechanism` (SPEC §9) runs on the exact dynamics only, for now."""
    if not isinstance(chain, Chain):
        raise NotImplementedError(f"Smoothed dynamics run a Chain; run a {type(chain).__name__} with Exact().")
    return chain
