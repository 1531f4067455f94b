"""What the steady-gait solvers share: the outcome codes, the argument checks, and the choice,
per configuration, among the gait periods tried (the two-mass [`steady_gait`][] and chains)."""

import enum
from typing import Any

import jax
import numpy as np

from .._status import Status


class GaitStatus(enum.IntEnum):
    """Outcome of the periodic-orbit solve of one configuration (beside [`Status`][locomotion_jax.Status]).

    An `enum.IntEnum`, like `Status`: `GaitStatus(int(g.status))` names a code, and the
    members compare equal to the integer codes stored in a gait's results and in sweeps.

    - `CONVERGED`: $\\|\\Phi_k(y) - y\\|_\\infty \\le$ `tol` $(1 + \\|y\\|_\\infty)$ for the reported `k`.
    - `NOT_CONVERGED`: no period in `periods` converged within `max_iter` Newton
      iterations (a chaotic or quasi-periodic motion, a longer period, a switching
      structure that changes under every step, a singular $M - I$, or the step cap
      `Exact.max_steps` hit); its numbers are NaN.
    - `LIFTOFF`: a normal force reached zero under the strict reading (transient or orbit).
    - `INVALID`: parameters outside their valid range (nothing was integrated), or no
      forcing period ($\\omega \\le 0$: a gait is periodic in $2\\pi/\\omega$).
    - `UNRESOLVED`: the step of [`Exact`][locomotion_jax.Exact] dynamics does not resolve one of
      the configuration's time scales (`Status.UNRESOLVED`: the forcing's highest harmonic, a
      natural period, a damping or friction time); nothing was integrated. One configuration
      alone is refused with a `ValueError` instead. Also a transient in which a tilted spring's
      ends pass each other faster than the step resolves (`Status.UNRESOLVED`; on the period map
      of a Newton iterate, such a step leaves the solve `NOT_CONVERGED` for that period, as
      other failures of an iterate do, and longer periods are still tried).
    - `COLLISION`: two neighbouring bodies met (`Status.COLLISION`) in the transient or on the
      period map from the last Newton iterate; no orbit is reported, since the model does not
      cover masses passing through each other.
    """

    CONVERGED = 0
    NOT_CONVERGED = 1
    LIFTOFF = 2
    INVALID = 3
    UNRESOLVED = 4
    COLLISION = 5


def unresolved(base: np.ndarray, mask: Any) -> np.ndarray:
    """`base` (the codes of the configurations not to solve, -1 elsewhere) with `UNRESOLVED` where
    `mask` (the resolution guard's, `None`: none)."""
    return base if mask is None else np.where(np.asarray(mask), GaitStatus.UNRESOLVED, base)


def periodic(omega: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Flat mask (size of the batch `shape`) of the configurations whose forcing has a period:
    finite $\\omega > 0$ (`omega`: one value, or one per configuration of the flat batch)."""
    size = int(np.prod(shape, dtype=np.int64))
    return np.broadcast_to(np.isfinite(omega) & (omega > 0), (size,))


def check(periods, transient, tol, max_iter) -> tuple[int, ...]:
    ks = (periods,) if isinstance(periods, int) else tuple(periods)
    if not ks or any(not isinstance(k, int) or isinstance(k, bool) or k < 1 for k in ks):
        raise ValueError(f"periods must be a positive int or a non-empty sequence of them, got {periods!r}.")
    if not (isinstance(transient, int) and not isinstance(transient, bool) and transient >= 0):
        raise ValueError(f"transient must be an int >= 0 (actuation periods), got {transient!r}.")
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ValueError(f"max_iter must be an int >= 1, got {max_iter!r}.")
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}.")
    return ks


def multipliers(r: dict) -> np.ndarray:
    """Eigenvalues of the monodromy matrix by decreasing modulus (on the host: a general
    eigensolver is not available on every JAX backend); NaN where not converged."""
    ok = r["status"] == GaitStatus.CONVERGED
    M = r["M"]
    out = np.full(M.shape[:-1], np.nan + 0j)
    if np.any(ok):
        ev = np.linalg.eigvals(M[ok])
        out[ok] = np.take_along_axis(ev, np.argsort(-np.abs(ev), axis=-1), -1)
    return out


def still_open(r: dict) -> np.ndarray:
    """Configurations a longer period may still improve: not converged, or unstable on an orbit
    that Newton's method reached by iterating. Where it took none (the transient ended on the
    orbit, as a gait whose masses stay stuck does), the start is a fixed point of every longer
    period's map as well, there with the powers of the same multipliers: no more stable, and
    `better` would keep the orbit found."""
    unstable = (r["status"] == GaitStatus.CONVERGED) & ~r["stable"] & (np.asarray(r["it"]) > 0)
    return (r["status"] == GaitStatus.NOT_CONVERGED) | unstable


def ratio(e: Any, dist: Any, ok: np.ndarray) -> np.ndarray:
    """Energy per unit distance; `inf` for a converged gait that does not move: no net distance, or
    no energy dissipated (a net distance over a period needs a slip, which dissipates; what is left
    is rounding, e.g. a capsule stuck all period whose internal mass swings)."""
    still = (dist == 0) | (e == 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok & still, np.inf, e / np.where(still, 1, dist))


def expand(flag: np.ndarray, like: np.ndarray) -> np.ndarray:
    return flag.reshape(flag.shape + (1,) * (np.ndim(like) - flag.ndim))


def judge(r: dict, base: np.ndarray, k: int, lifted: np.ndarray) -> dict:
    """Complete a Newton solve's host results `r` (`out`, `done`, `M`, `residual`) for period
    `k`: status (`base` where the configuration was not solved: its final code, else -1),
    lift-off, the reported `k`, multipliers and stability."""
    out = r["out"]
    failed = np.where(out.status == Status.COLLISION, GaitStatus.COLLISION, GaitStatus.NOT_CONVERGED)
    solved = np.where(out.status == Status.LIFTOFF, GaitStatus.LIFTOFF,
                      np.where(r["done"], GaitStatus.CONVERGED, failed))  # fmt: skip
    r["status"] = np.where(base < 0, solved, base).astype(np.int32)
    r["lifted"] = lifted
    r["residual"] = np.where(base < 0, r["residual"], np.nan)
    r["k"] = np.where(r["status"] == GaitStatus.CONVERGED, k, 0)
    r["multipliers"] = multipliers(r)
    r["stable"] = (r["status"] == GaitStatus.CONVERGED) & (np.max(np.abs(np.nan_to_num(r["multipliers"])), axis=-1) < 1)
    return r


def better(best: dict | None, r: dict) -> dict:
    """Per configuration, `r` where it improves on `best`: an unstable orbit gives way to a
    stable one of a longer period (the attractor past a period doubling), a failed solve to any
    converged one."""
    if best is None:
        return r
    converged = r["status"] == GaitStatus.CONVERGED
    failed = best["status"] == GaitStatus.NOT_CONVERGED
    unstable = (best["status"] == GaitStatus.CONVERGED) & ~best["stable"]
    take = (failed & converged) | (unstable & converged & r["stable"])
    return jax.tree_util.tree_map(lambda a, b: np.where(expand(take, a), b, a), best, r)
