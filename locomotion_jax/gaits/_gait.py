"""Steady gaits as periodic orbits of the period map (Newton shooting on the exact model).

The forcing is $T$-periodic ($T = 2\\pi/\\omega$) and the dynamics (eqs. 2-9) depend on the
positions only through the gap $u = x_2 - x_1$, so a steady gait is a fixed point of
the $k$-period map $\\Phi_k: (u, v_1, v_2) \\mapsto (u, v_1, v_2)$ taken at the phase
$\\omega t \\equiv 0$, while the centre of mass (eq. 4) drifts by $\\Delta X$ per gait
period $kT$. Each configuration is integrated for a short transient, then Newton's
method solves $\\Phi_k(y) = y$ with the monodromy matrix $M = \\partial\\Phi_k/\\partial y$
from forward-mode differentiation through the exact engine: located events enter with
their implicit-function times, so $M$ includes the saltation of every switch. The
eigenvalues of $M$ are the Floquet multipliers.

Every mechanism runs on one period map and one solver (`_shooting`, `_corrector`) over the
N-body engine: the paper's model as the two-mass chain of
[`Params.physics`][locomotion_jax.Params.physics], whose section state $(u, v_1, v_2)$ is the
chain's (gap, then velocities); its [`Gait`][] is named as the paper names it (`names="paper"`).

A mass stuck at the section has $v_i = 0$ held by friction: its velocity is not a free
unknown (its column of $M$ is zero, and so is its row when it is stuck again one
period later), which makes the multiplier 0 that sticking contributes.
"""

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike
from .._results import PAPER
from ..dynamics._base import AbstractDynamics
from ..dynamics._exact_dynamics import Exact
from ..model import _two_mass as model
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ..run._batch import mechanism_arg, prepare
from ..run._resolution import guard_two_mass
from . import _progress as progress, _shooting as shooting
from ._result import Gait as Gait
from ._select import GaitStatus as GaitStatus


def steady_gait(
    params: Params | Chain | Mechanism,
    *,
    periods: int | Sequence[int] = (1, 2, 3, 4),
    transient: int = 30,
    tol: float | None = None,
    max_iter: int = 12,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str | ArrayLike = "paper",
    dtype: Any = None,
    verbose: bool = False,
) -> Gait:
    """Solve the steady gait of each configuration as a periodic orbit (module docstring).

    After `transient` actuation periods from the start `start`, Newton's method on the
    period map $\\Phi_k$ is tried for each `k` in `periods` in turn, for the configurations
    that no smaller `k` solved with a stable orbit: a period-2 gait is reported with
    `k = 2`, while `periods=1` returns the (unstable) period-1 orbit it doubled from. An
    unstable orbit that the transient itself ended on (no Newton iteration: a gait whose masses
    stay stuck, its multiplier 1) is reported as it is: that state is a fixed point of every
    longer period's map too, no more stable there.

    **Arguments:**

    - `params`: [`Params`][], a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism] (any batch
      shape; a mechanism's section state: [`Gait`][] and the `_shooting` module).
    - `periods`: gait periods to try, in actuation periods.
    - `transient`: actuation periods integrated before the Newton iteration.
    - `tol`: Newton tolerance on $\\|\\Phi_k(y) - y\\|_\\infty / (1 + \\|y\\|_\\infty)$ (default 1e-11
      in float64, 1e-5 in float32).
    - `max_iter`: Newton iterations per `k`.
    - `dynamics`: [`Exact`][] (its `dt`); `waveform`, `contact`, `dtype`: as in [`simulate`][].
    - `start`: as in [`simulate`][] (`"paper"`, `"relaxed"`: at rest), or section states
      $(u, v_1, v_2)$ at phase 0, an array of shape `batch + (3,)` (a chain: gaps then velocities,
      $(u_0, \\dots, u_{N-2}, v_0, \\dots, v_{N-1})$, shape `batch + (2N - 1,)`, as is a mechanism
      without a spring to the wall; an anchored mechanism: positions then velocities, `batch + (2N,)`;
      a mass given $v_i = 0$ starts stuck where eq. 7 allows). A mechanism's named start is its own
      `x0`, `v0`.
    - Under `contact="hop"` (SPEC §10) the period map runs through lift-offs, flights and landings: a
      `Params` is solved as `Chain.from_params(params)` (a gait under the bodies' names); a chain's section
      state is followed by the heights and vertical velocities $(y_1, \\dots, y_N, w_1, \\dots, w_N)$
      (`Gait.state`); a body on the ground at the section has no vertical tangent (a zero
      multiplier), as a plastic landing has none. A given `start` has them too (heights $\\ge 0$):
      a gait's own `state` restarts it.
    - `verbose`: print progress to stderr from the start: a line before the transient and before
      each period's Newton solve (each compiles on its first call), and one when done.

    **Returns:** a [`Gait`][] with batch shape `params.batch_shape`. Configurations without
    a converged orbit carry NaN numbers and their `status`; the others are unaffected.

    !!! Example

        ```python
        g = steady_gait(Params(omega=jnp.array([1.0, 2.0, 8.0])))
        g.mean_speed, g.cost_of_transport, g.multipliers
        ```
    """
    dynamics = Exact() if dynamics is None else dynamics
    if not isinstance(dynamics, Exact):  # the solver differentiates the exact engine's steps
        raise TypeError(f"steady_gait needs Exact dynamics, got {type(dynamics).__name__}.")
    say = progress.reporter(verbose, "steady_gait")
    mechanism = mechanism_arg(params)
    say(f"{int(np.prod(mechanism.batch_shape))} configuration(s): compiling (first call only) and solving, "
        f"transient {transient} periods, gait periods {periods}")  # fmt: skip
    # The mechanism states its problem (configurations, physics, starts); the period map and the solver are one.
    problem = mechanism.gait_problem(dynamics, waveform=waveform, contact=contact, start=start, dtype=dtype)
    # The batch's bucket: the batch sizes of one bucket share the compiled programs.
    gait = shooting.steady_gaits(problem, periods=periods, transient=transient, tol=tol, max_iter=max_iter,
                                 dynamics=dynamics, contact=contact, say=say, bucket=True)  # fmt: skip
    say(f"done: {int(np.sum(np.asarray(gait.converged)))} of {np.size(np.asarray(gait.converged))} converged")
    return gait


def paper_problem(params: Params, dynamics: Exact, waveform: AbstractWaveform | None, contact: str,
                  start: str | ArrayLike, dtype: Any, guarded: bool = True) -> shooting.GaitProblem:  # fmt: skip
    """The paper's model's [`GaitProblem`][locomotion_jax.gaits._shooting.GaitProblem] on the N-body
    period map: each configuration's physics is the two-mass chain of its parameters and waveform
    ([`Params.physics`][locomotion_jax.Params.physics]), its section state $(u, v_1, v_2)$, its
    [`Gait`][] named as the paper names it. Under `contact="hop"`: the problem of the two-mass chain
    `Chain.from_params(params, waveform)` (under the bodies' names, heights in its state).

    `guarded=False` skips the resolution guard: only for a caller that checks the resolution
    itself by a convergence study (the exact optimiser's verification solves at `dt` and `dt/2`)."""
    if contact == "hop":  # flight and landing: the chain's section state carries the heights
        return shooting.bodies_problem(Chain.from_params(params, waveform), dynamics, contact, start, dtype)
    model.check_contact(contact)
    flat, wave, axes, shape = prepare(params, waveform, dtype)
    unresolved = None
    if guarded:
        flat, unresolved = guard_two_mass(dynamics, flat, wave, shape)  # refused alone, skipped in a batch
    y_start = _start_states(start, shape, flat.dtype)
    start = start if isinstance(start, str) else "paper"
    C = configs(flat, wave, axes)
    B = flat.omega.shape[0]
    omega = np.broadcast_to(np.asarray(wave.omega, np.float64), (B,))
    valid = jnp.ones((B,), bool)  # an invalid configuration's physics says so itself (`paper_physics`)
    return shooting.GaitProblem(C, shooting.paper_physics, valid, unresolved, shape, omega, flat.dtype, start, y_start,
                                PAPER)  # fmt: skip


def paper_gait(params: Params, *, dynamics: Exact, transient: int = 30, waveform: AbstractWaveform | None = None,
               start: str = "paper", guarded: bool = True, compact: bool = False,
               patience: int | None = None) -> Gait:  # fmt: skip
    """The exact optimiser's steady gaits of the paper's model: [`steady_gait`][]'s defaults under strict
    contact, with the solver's options (`guarded`: [`paper_problem`][]; `compact`, `patience`:
    `_shooting.newton`, for a caller that solves many batches of one size)."""
    problem = paper_problem(params, dynamics, waveform, "strict", start, None, guarded)
    return shooting.steady_gaits(problem, transient=transient, dynamics=dynamics, contact="strict", compact=compact,
                                 patience=patience)  # fmt: skip


def configs(flat: Params, wave: AbstractWaveform, axes: int | None) -> tuple[Params, AbstractWaveform]:
    """The paper's configurations as one flat batch `(params, waveform)` (a shared waveform repeated)."""
    B = flat.omega.shape[0]
    if axes is None:
        wave = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (B,) + jnp.shape(x)), wave)
    return flat, wave


def _start_states(start: Any, shape: tuple[int, ...], dtype: Any) -> Array | None:
    """`None` for a named start (checked), else the section states flattened to `(size, 3)`."""
    if isinstance(start, str):
        model.initial_gap(Params(), start)
        return None
    y = np.asarray(start, np.float64)
    if y.shape != shape + (3,) or not np.all(np.isfinite(y)):
        raise ValueError(f"start must be 'paper', 'relaxed' or finite section states (u, v1, v2) of shape "
                         f"{shape + (3,)}, got shape {y.shape}.")  # fmt: skip
    return jnp.asarray(y.reshape(-1, 3), dtype)
