"""Basins of attraction of coexisting steady gaits: which gait each initial condition ends on.

For one configuration, every start $(u, v_1, v_2)$ at phase $\\omega t \\equiv 0$ of a grid is
integrated for a transient and its steady gait solved by Newton's method ([`steady_gait`][] with
`start` the grid, one vmapped batch). Gaits are told apart by their period, mean speed and cost of
transport (a period-$k$ gait reached at another phase of its cycle has another section state but
the same averages); starts without a converged gait are labelled -1.
"""

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike
from ..dynamics._base import AbstractDynamics
from ..model._mechanism import AbstractMechanism
from ..model._waveform import AbstractWaveform
from ._gait import Gait, steady_gait
from ._shooting import reduced_size


class Basins(eqx.Module):
    """The basin map of one configuration over a grid of starts (grid shape `G`).

    - `label`: shape `G`: the index into `gaits` of the gait each start ends on; -1 where none
      converged (chaos, a long transient, lift-off: `per_start.status` says which).
    - `gaits`: the distinct gaits ([`Gait`][]; batch `(n,)`), by
      increasing mean speed.
    - `count`: shape `(n,)`: the starts in each basin.
    - `per_start`: the [`Gait`][] of every start, shape `G`.
    """

    label: Array
    gaits: Gait
    count: Array
    per_start: Gait


def basins(
    params: AbstractMechanism,
    starts: ArrayLike,
    *,
    periods: int | Sequence[int] = (1, 2, 3, 4),
    transient: int = 30,
    rtol: float = 1e-7,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    dtype: Any = None,
    verbose: bool = False,
) -> Basins:
    """Which steady gait each start converges to, for one configuration.

    **Arguments:**

    - `params`: one configuration (batch shape `()`) of any mechanism: a [`Params`][], a
      [`Chain`][locomotion_jax.Chain].
    - `starts`: section states at phase 0, shape `G + (2N - 1,)` (e.g. a grid of gaps and
      velocities): $(u, v_1, v_2)$ for the paper's model, the gaps then the velocities
      $(u_0, \\dots, u_{N-2}, v_0, \\dots, v_{N-1})$ for a chain; under `contact="hop"` followed by the
      heights and vertical velocities (shape `G + (4N - 1,)`, as [`steady_gait`][]'s `start`). A mass
      given $v_i = 0$ starts stuck where eq. (7) allows.
    - `periods`, `transient`, `dynamics`, `waveform`, `contact`, `dtype`: as in [`steady_gait`][].
    - `rtol`: gaits whose mean speeds and costs of transport agree to `rtol` (relative, over
      $1 + |x|$) and have the same period are the same gait.
    - `verbose`: print progress to stderr from the start (the stages of [`steady_gait`][]).

    **Returns:** [`Basins`][].

    !!! Example

        ```python
        u, v = np.meshgrid(np.linspace(2.9, 3.0, 8), np.linspace(-0.3, 0.3, 8), indexing="ij")
        b = basins(Params(omega=4.9), np.stack([u, v, -v], axis=-1))
        b.label, b.gaits.mean_speed, b.count
        ```
    """
    if not isinstance(params, AbstractMechanism) or params.batch_shape != ():
        raise ValueError("params must be one configuration (a mechanism of batch shape ()).")
    P = params.physics()
    n, hop = P.n_bodies, contact == "hop"
    size = reduced_size(P) + (2 * n if hop else 0)
    y = np.asarray(starts, np.float64)
    if y.ndim < 1 or y.shape[-1] != size or y.size == 0:
        what = "(u, v1, v2" if n == 2 and not P.anchored else f"(gaps u_0..u_{n - 2}, velocities v_0..v_{n - 1}"
        what = f"(positions x_0..x_{n - 1}, velocities v_0..v_{n - 1}" if P.anchored else what
        what += ", heights, vertical velocities)" if hop else ")"
        raise ValueError(f"starts must have shape grid + ({size},) {what}, got {y.shape}.")
    if not (np.isfinite(rtol) and rtol > 0):
        raise ValueError(f"rtol must be a finite number > 0, got {rtol!r}.")
    grid = y.shape[:-1]
    # The one configuration repeated over the grid (new leading batch axes on every field).
    batch = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(jnp.asarray(x), grid + jnp.shape(x)), params)
    g = steady_gait(batch, start=y, periods=periods, transient=transient, dynamics=dynamics, waveform=waveform,
                    contact=contact, dtype=dtype, verbose=verbose)  # fmt: skip
    label, reps = _classify(np.asarray(g.converged), np.asarray(g.k), np.asarray(g.mean_speed),
                            np.asarray(g.cost_of_transport), rtol)  # fmt: skip
    flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[len(grid) :]), g)
    gaits = jax.tree_util.tree_map(lambda x: x[np.asarray(reps, int)], flat)
    count = np.array([np.sum(label == i) for i in range(len(reps))], np.int32)
    return Basins(label=jnp.asarray(label, jnp.int32), gaits=gaits, count=jnp.asarray(count), per_start=g)


def _classify(ok, k, speed, cost, rtol) -> tuple[np.ndarray, list[int]]:
    """Labels of the converged starts by (k, speed, cost) within `rtol`; the representatives'
    flat indices, ordered by mean speed."""
    label = np.full(ok.shape, -1)
    flat = np.flatnonzero(ok.ravel())
    close = lambda a, b: abs(a - b) <= rtol * (1 + abs(b))
    reps: list[int] = []
    for i in flat[np.argsort(speed.ravel()[flat], kind="stable")]:
        for n, r in enumerate(reps):
            same_cost = close(cost.flat[i], cost.flat[r]) or (np.isinf(cost.flat[i]) and np.isinf(cost.flat[r]))
            if k.flat[i] == k.flat[r] and close(speed.flat[i], speed.flat[r]) and same_cost:
                label.flat[i] = n
                break
        else:
            label.flat[i] = len(reps)
            reps.append(int(i))
    return label, reps
