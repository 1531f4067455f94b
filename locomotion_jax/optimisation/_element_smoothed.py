"""The smoothed local stage of the chain's and the mechanism's optimisers (`optimise(...,
method="smoothed")`): the paper's model's smoothed method (`_optimise`, SPEC §7) over the Fourier
coefficients of every actuated signal.

From the starts of the baseline screen (a chain's travelling waves, a mechanism's sinusoids) Adam
minimises, for every start at once under `vmap`, the augmented Lagrangian of the smoothed model's
cost of transport with the speed and normal-force constraints (`_optimise.terms`, `_run_stage`),
its gradients by reverse mode through a checkpointed fixed-step rollout
(`_objective.element_rollout`), with a continuation in $\\varepsilon$. The bound on every signal
holds at every iterate (radial rescaling of its coefficients, `_optimise.project`). Each lane's
best iterate that is feasible on the smoothed model is its candidate; the candidates go to the
same verification on the exact model's steady gaits as the exact method's (`_element_local.verify`),
which keeps the cheapest candidate that meets every constraint there, the baseline included.

Unlike the paper's model's smoothed method, the stage has no exact-feedback correction rounds:
the verification decides.
"""

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import _element_local as local
from ._objective import make_plan
from ._optimise import _optimizer, _Problem, _run_stage, element_rollout
from ._optimum import Settings
from ._shapes import normalise_phase


def refine(base: Any, starts: list[local.Start], a_max: float, v_min: float, direction: int, lo: float, hi: float,
           settings: Any, say: Callable[[str], None]) -> tuple[list[np.ndarray], list[dict]]:  # fmt: skip
    """Refine `starts` (one per lane; their Fourier coefficients and frequencies) on the smoothed
    model: the module docstring's method with the fields of `settings.smoothed` (a [`Settings`][]:
    `eps_schedule`, `outer`, `inner`, `learning_rate`, `lr_decay`, `phase1_threshold`, `rho0`,
    `rho_growth`, `rho_max`, `speed_slack`, `temperature`, `transient`, `measured`, `backprop`,
    `omega_range`, `verbose`; the others are the paper's model's) and the normal-force margin
    `settings.margin`. The base frequency stays in `[lo, hi]` and within `omega_range` of the
    starts'. Returns each lane's decision vector (`_element_local.pack`: units of $a_\\max$, the
    time origin moved so that the first signal's $A_1$ is 0) and the log of the stages' blocks."""
    s: Settings = settings.smoothed
    dtype = base.dtype
    n = len(starts)
    omegas = [st.omega for st in starts]
    lo_s, hi_s = max(lo, min(omegas) / s.omega_range), min(hi, max(omegas) * s.omega_range)
    centre = math.exp(float(np.mean(np.log(omegas))))
    theta = {
        "cos": jnp.asarray(np.stack([st.cos for st in starts]) / a_max, dtype),
        "sin": jnp.asarray(np.stack([st.sin for st in starts]) / a_max, dtype),
        "log_omega": jnp.asarray(np.log(omegas), dtype),
    }
    opt_state = jax.vmap(_optimizer().init)(theta)
    lam = jnp.zeros((n, 2), dtype)
    rho = jnp.full((n, 2), s.rho0, dtype)
    v_target = jnp.full((n,), v_min * (1 + s.speed_slack), dtype)
    margin = jnp.full((n,), settings.margin, dtype)
    masses = [float(1 / m) for m in np.asarray(jnp.stack(base.physics().im), np.float64)]

    def problem(eps: float) -> _Problem:
        # Every stage shares the finest stage's compiled loop (`make_plan`'s `eps_min`).
        plan = make_plan(masses, lo_s, centre, eps, s.transient, s.measured, s.backprop, eps_min=min(s.eps_schedule))
        log_lo, log_hi = jnp.asarray(math.log(lo_s), dtype), jnp.asarray(math.log(hi_s), dtype)
        return _Problem(base, jnp.asarray(a_max, dtype), jnp.asarray(direction, dtype), log_lo, log_hi, plan,
                        s.temperature, hi > lo, element_rollout)  # fmt: skip

    state = (theta, opt_state, lam, rho, v_target, margin)
    log: list[dict] = []
    best = theta  # replaced by the first stage (`eps_schedule` is never empty)
    say(f"refining {n} starts on the smoothed model (compiling its rollout: first call only)...")
    for stage, eps in enumerate(s.eps_schedule):
        state, best = _run_stage(state, problem(eps), eps, s.learning_rate * s.lr_decay**stage, s, s.outer, log)
    return decisions(best), log


def decisions(best: dict[str, Any]) -> list[np.ndarray]:
    """Each lane's decision vector (`_element_local.pack`) of the iterates `best` (`cos`, `sin`:
    `(n, S, H)` in units of $a_\\max$; `log_omega`: `(n,)`), its time origin moved so that the
    first signal's $A_1$, which the decision vector leaves out, is 0: the same gait."""
    xs = []
    for cos, sin, log_omega in zip(np.asarray(best["cos"], np.float64), np.asarray(best["sin"], np.float64),
                                   np.asarray(best["log_omega"], np.float64)):  # fmt: skip
        xs.append(local.pack(*normalise_phase(cos, sin), math.exp(float(log_omega))))
    return xs
