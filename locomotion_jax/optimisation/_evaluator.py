"""The batched orbit oracle behind the exact optimisers' lockstep solvers (`_lockstep.run_lockstep`):
the paper's model (`_exact`, `gaits._orbit.Oracle`) and chains and mechanisms (`_element_local`,
`gaits._element_orbit.ChainOracle`).

Each lane (a local solver) keeps its warm start: the section state and gait period of its last
solved orbit. Where Newton's method fails from it, the lane runs a transient and tries a
period-1 gait, then a period-2 one (past a period doubling the steady gait repeats every second
actuation period, and its figures are those of two); with `retry` off, the point gets no orbit.
"""

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np


class Evaluator:
    """Answers the lockstep solvers' requests `(lanes, points)` with one batched oracle call.

    - `oracle`: an orbit oracle (`orbits(theta, y0, k, ...)`, `transient(theta, y0, fresh, periods)`,
      `dtype`); `lanes`: its batch size; `transient`: actuation periods of the retry's transient.
    - `make(lane, theta, orbit, k)`: the figures a solver gets at a solved orbit (`k`: its gait
      period); `bad(lane, theta)`: what it gets where no orbit is found (default `None`).
    - `report(calls, figures)`: called after each batched call with the number of calls so far (progress).

    `retry` (an attribute, `True` to begin with): the solvers' requests retry where Newton's method
    fails from a lane's warm start (`solve`); off, such a point gets `bad` at once.
    """

    def __init__(self, oracle: Any, lanes: int, transient: int, make: Callable[[int, np.ndarray, Any, int], Any],
                 bad: Callable[[int, np.ndarray], Any] = lambda lane, theta: None,
                 report: Callable[[int, list], None] = lambda calls, figures: None):  # fmt: skip
        self.oracle, self.lanes, self.transient = oracle, lanes, transient
        self.make, self.bad, self.report = make, bad, report
        self.y: dict[int, Any] = {}
        self.k: dict[int, int] = {}
        self.calls = 0
        self.retry = True

    def solve(self, theta: np.ndarray, y0: np.ndarray, k: np.ndarray, fresh: np.ndarray | None = None,
              rested: bool = False, **options: Any) -> tuple[Any, np.ndarray]:  # fmt: skip
        """Orbits of a full batch (`lanes` rows; numpy arrays in an `Orbit`) and their gait periods,
        from the warm starts `y0` with the periods `k`; where Newton fails, again after a transient
        (from rest where `fresh`), as a period-1 and then a period-2 gait.

        `rested`: every `y0` already is the state after the transient from rest and every `k` is 1,
        so that the retry's transient and its period-1 solve would repeat the first attempt bit for
        bit; the retry tries the period-2 gait alone. Without `rested` there is no retry where
        `self.retry` is off. `options` go to the oracle's `orbits` (the paper's `gradient=False`:
        the figures alone)."""
        dtype = self.oracle.dtype
        th = jnp.asarray(theta, dtype)
        run = lambda y, kk: jax.tree_util.tree_map(
            np.asarray, self.oracle.orbits(th, jnp.asarray(y, dtype), jnp.asarray(kk, jnp.int32), **options)
        )
        orb = run(y0, k)
        k = np.array(k)
        if not orb.ok.all() and (rested or self.retry):
            if rested:
                y1, tries = y0, (2,)
            else:
                fresh = np.zeros(len(k), bool) if fresh is None else fresh
                periods = jnp.asarray(self.transient, jnp.int32)
                restart = jnp.asarray(fresh | ~orb.ok)
                y1 = np.asarray(self.oracle.transient(th, jnp.asarray(y0, dtype), restart, periods))
                tries = (1, 2)
            for kk in tries:
                if orb.ok.all():
                    break
                again = run(y1, np.full_like(k, kk))
                take = ~orb.ok & again.ok
                orb = jax.tree_util.tree_map(lambda a, b: np.where(take.reshape((-1,) + (1,) * (a.ndim - 1)), b, a),
                                             orb, again)  # fmt: skip
                k = np.where(take, kk, k)
        self.calls += 1
        return orb, k

    def __call__(self, idx: list[int], xs: list[np.ndarray]) -> list[Any]:
        pad = idx + [idx[0]] * (self.lanes - len(idx))
        theta = np.stack([xs[idx.index(i)] for i in pad])
        orb, ks = self.solve(theta, np.stack([self.y[i] for i in pad]), np.array([self.k[i] for i in pad]))
        out = []
        for r, i in enumerate(idx):
            one = jax.tree_util.tree_map(lambda x: x[r], orb)
            if one.ok:
                self.y[i], self.k[i] = one.y, int(ks[r])
                out.append(self.make(i, theta[r], one, int(ks[r])))
            else:
                out.append(self.bad(i, theta[r]))
        self.report(self.calls, out)
        return out
