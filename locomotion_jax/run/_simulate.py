"""`simulate`: trajectories saved at requested times (memory grows with the saves only)."""

from typing import Any

import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike
from .._results import Trajectory
from ..dynamics._base import AbstractDynamics
from ..dynamics._forward import check_static
from ..model import _two_mass as model
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ._batch import check_hop_dynamics, dynamics_arg, mechanism_arg, unflatten
from ._resolution import flag


def simulate(
    params: "Params | Chain | Mechanism",
    t_end: float,
    save_at: ArrayLike | None = None,
    *,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str = "paper",
    initial: tuple | None = None,
    dtype: Any = None,
) -> Trajectory:
    """Integrate the two-mass model or a chain from $t = 0$ to `t_end`, saving at `save_at`.

    **Arguments:**

    - `params`: the mechanism, one configuration or a batch: [`Params`][] (the paper's
      two-mass model) or a [`Chain`][] of N masses (which carries its own waveforms).
    - `t_end`: final time (> 0).
    - `save_at`: increasing times in `[0, t_end]`; default 1001 equally spaced
      times. Memory grows with `len(save_at)`, not with the number of steps.
    - `dynamics`: [`Exact`][locomotion_jax.Exact] (default), [`Smoothed`][locomotion_jax.Smoothed],
      or any other [`AbstractDynamics`][].
    - `waveform`: actuation $\\ell_0(t)$; default the sinusoid of eq. (13) from `params`.
    - `contact`: `"strict"` (default: stop at lift-off) or `"paper"` ($n_i = |N_i|$,
      flagged), or `"hop"` (flight and landing, SPEC §10; `Params`, a `Chain`, or a `Mechanism`
      without carried bodies, Exact dynamics; docs/model.md). `start`: `"paper"` (eq. 14, default) or `"relaxed"`.
    - `initial`: instead of `start`, the state at $t = 0$: a tuple `(x1, v1, x2, v2)` of
      arrays broadcastable to the batch shape, with $x_1 < x_2$ (a mass at rest sticks if
      eq. (7) allows). Forward-mode derivatives with respect to it work as with respect
      to a parameter. For a chain: a tuple `(x, v)` of positions and velocities, each
      broadcastable to the batch shape plus one value per mass, positions increasing along
      the chain.
    - `dtype`: cast parameters to this floating dtype (default: theirs).

    **Returns:** a [`Trajectory`][] with batch shape `params.batch_shape`, for the paper's model as for a
    chain or any other mechanism (one class: the fields have a trailing body axis).

    With [`Exact`][locomotion_jax.Exact] dynamics (both engines) the batch runs through the work queue of
    `measure` (`_saves.run_saves`), at about `measure`'s cost over the same run plus
    one iteration per save (benchmarks/simulate_vs_measure.py). [`Smoothed`][locomotion_jax.Smoothed] dynamics
    run diffrax's `diffeqsolve` under `vmap`, as `measure` does with them: the solve is
    one loop of diffrax's own, which a work queue cannot take step by step.

    **Raises:** `TypeError` for a `params` or `dynamics` of the wrong type; `ValueError` for
    invalid arguments (before any computation); an invalid
    `initial` state is refused where its values are known, and flagged `INVALID` in its
    own result under `jit`.

    !!! Example

        ```python
        traj = simulate(Params(omega=2.0), t_end=20.0)
        traj.X[-1], traj.mode[:10]
        ```
    """
    dynamics = dynamics_arg(dynamics)
    model.check_contact(contact, hop=True)  # the mechanism refuses "hop" where it does not support it
    check_hop_dynamics(contact, dynamics)
    model.initial_gap(Params(), start)  # validates `start`
    check_static("t_end", t_end)
    check_static("save_at", save_at)
    if not np.isfinite(t_end) or t_end <= 0:
        raise ValueError(f"t_end must be a finite number > 0, got {t_end!r}.")
    if save_at is None:
        save_at = np.linspace(0.0, float(t_end), 1001)
    save_np = np.asarray(save_at, dtype=float)
    if save_np.ndim != 1 or save_np.size == 0:
        raise ValueError(f"save_at must be a non-empty 1-D array, got shape {save_np.shape}.")
    if np.any(np.diff(save_np) < 0) or save_np[0] < 0 or save_np[-1] > t_end or not np.all(np.isfinite(save_np)):
        raise ValueError("save_at must be finite, non-decreasing and inside [0, t_end].")
    # The mechanism flattens itself (what differs between mechanisms travels in the batch).
    batch, unresolved, shape = mechanism_arg(params).flat_batch(
        dynamics, waveform=waveform, dtype=dtype, initial=initial, contact=contact, start=start
    )
    save = jnp.asarray(save_np, batch.dtype)
    out = flag(dynamics.simulate(batch, save, float(t_end), contact, start), unresolved)
    start = "initial" if initial is not None else start
    return Trajectory(**unflatten(out, shape), start=start, contact=contact, names=batch.names)
