"""Constraints of the actuation optimiser that need no dynamics: the stroke, and input checks.

The stroke $\\max_t |\\ell_0(t) - \\bar\\ell|$ is a norm of the Fourier
coefficients (a maximum of absolute values of linear functions), so the set
$\\{\\text{stroke} \\le a_\\max\\}$ is convex and contains 0. The optimiser keeps its
iterates inside it by radial rescaling, which needs only the exact stroke:
[`stroke`][] locates the maximum on a grid and polishes it with Newton's method.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from ..model import _two_mass as model
from ..model._params import Params


NEWTON_ITERS = 4
GRID_PER_HARMONIC = 32


def _series(cos: Array, sin: Array, phase: Array) -> tuple[Array, Array, Array]:
    """$s(\\phi) = \\sum_n A_n \\cos n\\phi + B_n \\sin n\\phi$ and its first two derivatives."""
    lead = (1,) * phase.ndim  # explicit broadcasting (tests raise on rank promotion)
    n = jnp.arange(1, cos.shape[-1] + 1, dtype=cos.dtype).reshape(lead + cos.shape)
    cos, sin = cos.reshape(lead + cos.shape), sin.reshape(lead + sin.shape)
    arg = phase[..., None] * n
    c, s = jnp.cos(arg), jnp.sin(arg)
    val = jnp.sum(cos * c + sin * s, axis=-1)
    d1 = jnp.sum(n * (sin * c - cos * s), axis=-1)
    d2 = -jnp.sum(n * n * (cos * c + sin * s), axis=-1)
    return val, d1, d2


def stroke(cos: Array, sin: Array) -> Array:
    """Exact $\\max_\\phi |s(\\phi)|$ of one coefficient set (`cos`, `sin`: shape `(N,)`).

    The maximum of $|s|$ on a grid of $32N + 64$ phases over one period brackets
    the true maximiser within one grid cell; four Newton steps on $s'(\\phi) = 0$
    (each clipped to that cell) then give it to rounding. Not differentiated: the
    optimiser uses it only to rescale.
    """
    cos, sin = jax.lax.stop_gradient(cos), jax.lax.stop_gradient(sin)
    n_grid = GRID_PER_HARMONIC * cos.shape[-1] + 64
    h = 2 * math.pi / n_grid
    grid = jnp.arange(n_grid, dtype=cos.dtype) * h
    vals, _, _ = _series(cos, sin, grid)
    j = jnp.argmax(jnp.abs(vals))
    phi = grid[j]
    best = jnp.abs(vals[j])
    for _ in range(NEWTON_ITERS):
        _, d1, d2 = _series(cos, sin, phi)
        step = jnp.where(d2 != 0, -d1 / jnp.where(d2 != 0, d2, 1), 0)
        phi = phi + jnp.clip(step, -h, h)
        best = jnp.maximum(best, jnp.abs(_series(cos, sin, phi)[0]))
    return best


def project_stroke(cos: Array, sin: Array, limit: Array | float) -> tuple[Array, Array]:
    """Radial rescaling onto $\\{\\text{stroke} \\le \\text{limit}\\}$ (identity inside)."""
    scale = jnp.minimum(1, limit / jnp.maximum(stroke(cos, sin), jnp.finfo(cos.dtype).tiny))
    return cos * scale, sin * scale


def rest_normal_force(params: Params, a_max: float) -> float:
    """Smallest normal force (eq. 5) at the relaxed gap for $\\ell_0 \\in [\\bar\\ell - a_\\max, \\bar\\ell + a_\\max]$.

    With both masses at rest at the relaxed gap ($\\ell = \\bar\\ell$) the tension is
    $k(\\bar\\ell - \\ell_0)$; a stroke whose extremes already lift a mass off
    quasi-statically cannot be run at any frequency.
    """
    gap = model.initial_gap(params, "relaxed")
    l0 = params.lbar + jnp.linspace(-a_max, a_max, 201, dtype=params.dtype)
    f = model.spring_forces(params, l0, jnp.zeros_like(l0), jnp.zeros_like(l0), gap + 0 * l0, "strict")
    return float(jnp.minimum(jnp.min(f.N1), jnp.min(f.N2)))


def check_inputs(
    params: Params,
    v_min: float,
    a_max: float,
    direction: int | None,
    harmonics: int,
    omega: float | None,
    margin: float,
) -> tuple[float, int]:
    """Validate a requirement; return `(speed, direction)` with `speed = |v_min| > 0`.

    `v_min` is a speed in the direction `direction` (+1 forward, -1 backward). A
    negative `v_min` is accepted only together with `direction=-1` (then it is the
    signed mean velocity bound $\\bar v \\le v_\\min$); without a direction it is
    ambiguous and rejected.

    **Raises:** `ValueError` naming the offending argument and its valid range.
    """
    if not isinstance(params, Params):
        raise TypeError(f"params must be a locomotion_jax.Params, got {type(params).__name__}.")
    if params.batch_shape != ():
        raise ValueError(f"params must be a single configuration, got batch shape {params.batch_shape}.")
    if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)) or harmonics < 1:
        raise ValueError(f"harmonics must be an integer >= 1, got {harmonics!r}.")
    if direction is not None and direction not in (1, -1):
        raise ValueError(f"direction must be +1 (forward) or -1 (backward), got {direction!r}.")
    if not np.isfinite(v_min) or v_min == 0:
        raise ValueError(f"v_min must be a finite non-zero speed, got {v_min!r}.")
    if v_min < 0:
        if direction is None:
            raise ValueError(
                f"v_min={v_min!r} is negative but no direction was given; pass v_min >= 0 with "
                "direction=-1 (CLI: --direction -1) to require backward motion."
            )
        if direction == 1:
            raise ValueError(f"v_min={v_min!r} is negative but direction=+1; they contradict each other.")
    direction = -1 if v_min < 0 else (1 if direction is None else int(direction))
    lbar = float(params.lbar)
    if not (np.isfinite(a_max) and 0 < a_max < lbar):
        raise ValueError(f"a_max must satisfy 0 < a_max < lbar = {lbar}, got {a_max!r}.")
    m_min = min(float(params.m1), float(params.m2))
    if not (np.isfinite(margin) and 0 <= margin < m_min):
        raise ValueError(f"margin must satisfy 0 <= margin < min(m1, m2) = {m_min}, got {margin!r}.")
    n_rest = rest_normal_force(params, a_max)
    if n_rest <= 0:
        a_lift = m_min * lbar / (float(params.k) * abs(float(params.d)))
        raise ValueError(
            f"a_max={a_max!r} lifts a mass off at rest: at the relaxed gap the smallest normal force over "
            f"l0 in [lbar - a_max, lbar + a_max] is {n_rest:.4g} <= 0; a_max must be below about {a_lift:.4g} "
            "(= min(m1, m2) lbar / (k |d|)) for these parameters."
        )
    if omega is not None and not (np.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be a finite number > 0 (or None to optimise it), got {omega!r}.")
    return abs(float(v_min)), direction
