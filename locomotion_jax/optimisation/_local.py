"""One local run of an exact optimiser (the paper's model's, `_exact`; chains' and mechanisms',
`_element_local`): a search from a start, and the bookkeeping of its evaluations around it.

The search (a descent of `_descent`, or a scipy method) asks for the figures at its points; the run
answers repeated asks of the last point from a one-entry cache, records every answer in a trace,
and keeps the cheapest point that meets every constraint. The objective has jumps where a held
mass starts to slip, so a line-search or trust-region iterate may wander past its best point: the
run reports that point, not the search's last.
"""

import math
from collections.abc import Callable
from typing import Any

import numpy as np


RUNNERS_UP = (0.0, 0.25, 0.5, 0.75)
"""Where a run's runners-up lie in its sequence of points that meet every constraint (fractions of
it, in the order of evaluation; `local_run(runners_up=True)`)."""


def local_run(
    x0: np.ndarray,
    search: Callable[[Callable[[np.ndarray], Any], np.ndarray], dict],
    stroke_ok: Callable[[np.ndarray], bool],
    log: list,
    runners_up: bool = False,
) -> Callable[[Callable[[np.ndarray], Any]], Any]:
    """One local run from `x0`, as a solver for [`run_lockstep`][locomotion_jax.optimisation._lockstep.run_lockstep].

    **Arguments:**

    - `search(at, x0)`: runs the local method from `x0`, asking `at(x)` for the figures at `x`
      (`_figures.Figures`; `None` or one with `ok` false where no orbit was found); returns what
      the log records of it (a dict, e.g. its `message`).
    - `stroke_ok(x)`: whether `x` is within the stroke limit.
    - `log`: the run appends `{**search's dict, "evaluations", "trace"}` to it, `trace` holding
      `f`, `cot`, `c_speed`, `c_normal`, `ok` of each evaluation.
    - `runners_up`: also return earlier points (below).

    **Returns** `solve(ask)`, which runs the search with `ask(x)` answering the figures, and returns
    the cheapest point evaluated that meets every constraint (the speed, the normal-force margin and
    the stroke, the last to 1e-9), else the one with the smallest violation. With `runners_up`, the
    pair of that point and its runners-up, each `(cost of transport, point)`: the points at the
    fractions `RUNNERS_UP` of the run's sequence of points that meet every constraint (none if no
    point does). The cheapest point often lies at a jump, where the gait is fragile (a held mass's
    force grazes its static limit, so that the engine's step or a perturbation decides when it
    slips); an earlier point, further from the jump, is a fallback for the verification.
    """

    def solve(ask: Callable[[np.ndarray], Any]) -> Any:
        cache: dict[bytes, Any] = {}
        trace: list[dict] = []
        best: dict[str, Any] = {"key": (math.inf, math.inf), "x": np.array(x0, float)}
        held_points: list[tuple[float, np.ndarray]] = []

        def at(x: np.ndarray) -> Any:
            key = np.asarray(x).tobytes()
            if key not in cache:
                cache.clear()  # the searches ask for the last point again, never an older one
                fig = cache[key] = ask(np.array(x, float))
                if fig is None:
                    return fig
                c_speed, c_normal = float(fig.c[0]), float(fig.c[1])
                trace.append({"f": float(fig.f), "cot": float(fig.cot), "c_speed": c_speed, "c_normal": c_normal,
                              "ok": bool(fig.ok)})  # fmt: skip
                if fig.ok:
                    held = min(c_speed, c_normal) >= 0 and stroke_ok(x)
                    rank = (0.0, fig.cot) if held else (1.0, -min(c_speed, 0.0) - min(c_normal, 0.0))
                    if rank < best["key"]:
                        best["key"], best["x"] = rank, np.array(x, float)
                    if held:
                        held_points.append((fig.cot, np.array(x, float)))
            return cache[key]

        entry = search(at, np.array(x0, float))
        log.append({**entry, "evaluations": len(trace), "trace": trace})
        if not runners_up:
            return best["x"]
        if best["key"][0] != 0.0:
            return best["x"], []
        picks = sorted({int(f * len(held_points)) for f in RUNNERS_UP})
        return best["x"], [held_points[i] for i in picks if held_points[i][1].tobytes() != best["x"].tobytes()]

    return solve
