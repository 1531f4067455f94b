"""Newton's method on the period map with the parameter as an unknown (continuation's corrector).

For a gait of period $kT$ the unknowns are $z = (u, v_1, v_2, \\zeta)$: the section state of
[`steady_gait`][] and the parameter $\\lambda = \\lambda_0 + s\\,\\zeta$ in units of a scale $s$.
The corrector solves

$$\\Phi_k(y; \\lambda) - y = 0, \\qquad c \\cdot (z - z_\\text{ref}) = 0,$$

the fixed point on the hyperplane through $z_\\text{ref}$ normal to $c$: with $c$ the tangent of
the branch this is pseudo-arclength continuation's corrector; with $c = e_\\zeta$ it solves at a
fixed parameter. The Jacobian $[\\,\\partial\\Phi_k/\\partial y,\\ \\partial\\Phi_k/\\partial\\zeta\\,]$
comes from one forward-mode pass (four tangents) through the exact engine, event times by the
implicit function theorem as in [`steady_gait`][]: its first three columns are the monodromy
matrix. The same pass differentiates the switching test functions of the period (the slip
margin and the smallest normal force, [`Gait`][]), whose gradients say on which side of a
switching surface a point lies.

A parameter is a field of [`Params`][] or, for a [`Fourier`][] waveform, a coefficient
`"cosN"`/`"sinN"` of harmonic `N` (from 1).
"""

import re
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from .._status import Status
from ..dynamics import _exact as exact
from ..dynamics._compile import engine_jit
from ..model._params import PARAM_NAMES, Params, safe_params
from ..model._waveform import AbstractWaveform, Fourier, Sinusoid
from . import _period as period


class Spec(NamedTuple):
    """A continuation parameter: a `Params` field (`harmonic` -1) or a waveform coefficient
    (`name` "cos" or "sin", `harmonic` from 0)."""

    name: str
    harmonic: int

    @property
    def label(self) -> str:
        return self.name if self.harmonic < 0 else f"{self.name}{self.harmonic + 1}"


def parse(parameter: str, waveform: AbstractWaveform | None) -> Spec:
    """The [`Spec`][] of `parameter`; `ValueError` naming the valid choices."""
    if not isinstance(parameter, str):
        raise TypeError(f"parameter must be a str, got {type(parameter).__name__}.")
    m = re.fullmatch(r"(cos|sin)(\d+)", parameter)
    if m:
        if not isinstance(waveform, Fourier):
            raise ValueError(f"parameter {parameter!r} is a Fourier coefficient: it needs waveform=Fourier(...).")
        n = int(m.group(2))
        if not 1 <= n <= waveform.harmonics:
            raise ValueError(f"parameter {parameter!r}: the waveform has harmonics 1..{waveform.harmonics}.")
        return Spec(m.group(1), n - 1)
    if parameter not in PARAM_NAMES:
        raise ValueError(
            f"unknown parameter {parameter!r}; valid: {', '.join(PARAM_NAMES)}, or cosN/sinN of a Fourier waveform."
        )
    if parameter == "a" and waveform is not None and not isinstance(waveform, Sinusoid):
        raise ValueError("parameter 'a' is the sinusoid's amplitude (eq. 13); with a Fourier waveform use cosN/sinN.")
    return Spec(parameter, -1)


def value(params: Params, wave: AbstractWaveform, spec: Spec) -> Array:
    """The parameter's value (the waveform's, where it has one); not broadcast to the batch."""
    if spec.harmonic >= 0:
        return getattr(wave, spec.name)[..., spec.harmonic]
    if spec.name in _WAVE_FIELDS and hasattr(wave, spec.name):
        return getattr(wave, spec.name)
    return getattr(params, spec.name)


_WAVE_FIELDS = ("omega", "lbar", "a")


class Selector(eqx.Module):
    """Which entries of the parameters and the waveform the parameter sets, as masks: a traced value,
    so that one compilation serves every parameter (and none, for [`steady_gait`][])."""

    params: Array  # (len(PARAM_NAMES),) bool
    wave: Array  # (3,) bool: the waveform's omega, lbar, a (where it has them)
    cos: Array | None  # (N,) bool: a Fourier waveform's coefficients
    sin: Array | None


def selector(spec: Spec | None, wave: AbstractWaveform) -> Selector:
    """The masks of `spec` for waveforms like `wave` (all False for `None`)."""
    fourier = isinstance(wave, Fourier)
    n = wave.harmonics if isinstance(wave, Fourier) else 0
    onehot = lambda size, i: np.arange(size) == i
    name = None if spec is None else spec.name
    h = -1 if spec is None else spec.harmonic
    coef = h >= 0
    return Selector(
        params=jnp.asarray(onehot(len(PARAM_NAMES), PARAM_NAMES.index(name) if name in PARAM_NAMES else -1)),
        wave=jnp.asarray([f == name and not coef for f in _WAVE_FIELDS]),
        cos=jnp.asarray(onehot(n, h if name == "cos" else -1)) if fourier else None,
        sin=jnp.asarray(onehot(n, h if name == "sin" else -1)) if fourier else None,
    )


def with_value(params: Params, wave: AbstractWaveform, sel: Selector, lam: Array):
    """`params` and `wave` of one configuration with the selected entries set to `lam`."""
    params = Params(**{n: jnp.where(sel.params[i], lam, getattr(params, n)) for i, n in enumerate(PARAM_NAMES)},
                    check=False)  # fmt: skip
    for i, name in enumerate(_WAVE_FIELDS):
        if hasattr(wave, name):
            wave = eqx.tree_at(lambda w: getattr(w, name), wave, jnp.where(sel.wave[i], lam, getattr(wave, name)))
    if sel.cos is not None and sel.sin is not None and isinstance(wave, Fourier):
        wave = eqx.tree_at(lambda w: (w.cos, w.sin), wave,
                           (jnp.where(sel.cos, lam, wave.cos), jnp.where(sel.sin, lam, wave.sin)))  # fmt: skip
    return params, wave


class Solved(NamedTuple):
    """The corrector's result for one configuration."""

    z: Array  # (u, v1, v2, zeta)
    J: Array  # (5, 4): the derivatives of (Phi, margin, n_min) in (y, zeta)
    out: period.Period
    done: Array  # converged
    valid: Array  # the parameters at z are valid
    it: Array


def _correct_one(params, wave, sel, contact, dt, k, lam0, scale, z0, zref, c, go, tol, max_iter, max_steps) -> Solved:
    """Newton's method on the module docstring's system from `z0` (skipped where `go` is False)."""
    dtype = params.dtype
    k = jnp.where(go, k, 0)  # a configuration not solved here integrates nothing
    shift = jnp.concatenate([jnp.eye(3, dtype=dtype), jnp.zeros((3, 1), dtype)], axis=1)

    def phi(z):
        p, w = with_value(params, wave, sel, lam0 + scale * z[3])
        p, valid = safe_params(p, w)
        out = period.period_map(p, w, exact.consts(p, w), contact, dt, max_steps, k, z[:3])
        # The switching test functions' gradients come with the monodromy (to cross a switching surface).
        return jnp.concatenate([out.y, jnp.stack([out.margin, out.n_min])]), (out, valid)

    def evaluate(z):
        J, (out, valid) = jax.jacfwd(phi, has_aux=True)(z)
        bad = (out.status != Status.OK) | ~valid | ~jnp.all(jnp.isfinite(z)) | ~jnp.all(jnp.isfinite(J[:3]))
        return J, out, valid, bad

    def small(z, out):
        return jnp.max(jnp.abs(out.y - z[:3])) <= tol * (1 + jnp.max(jnp.abs(z[:3])))

    def cond(s):
        _, _, _, _, it, done, failed = s
        return ~done & ~failed & (it < max_iter)

    def body(s):
        z, J, out, _, it, _, _ = s
        A = jnp.concatenate([J[:3] - shift, c[None]], axis=0)
        F = jnp.concatenate([out.y - z[:3], (c @ (z - zref))[None]])
        z1 = z - jnp.linalg.solve(A, F)
        J1, out1, valid1, bad = evaluate(z1)
        return z1, J1, out1, valid1, it + 1, small(z1, out1) & ~bad, bad

    J0, out0, valid0, bad0 = evaluate(z0)
    # A start off the hyperplane is a valid point only after a step onto it.
    on = jnp.abs(c @ (z0 - zref)) <= tol * (1 + jnp.max(jnp.abs(z0)))
    init = (z0, J0, out0, valid0, jnp.zeros((), jnp.int32), go & on & small(z0, out0) & ~bad0, ~go | bad0)
    z, J, out, valid, it, done, _ = jax.lax.while_loop(cond, body, init)
    return Solved(z=z, J=J, out=out, done=done & go, valid=valid, it=it)


def _correct_batch(
    params, wave, wave_axes, sel, contact, dt, k, lam0, scale, z0, zref, c, go, tol, max_iter, max_steps
):
    def one(p, w, k1, l1, s1, z1, r1, c1, g1):
        return _correct_one(p, w, sel, contact, dt, k1, l1, s1, z1, r1, c1, g1, tol, max_iter, max_steps)

    return jax.vmap(one, in_axes=(0, wave_axes) + (0,) * 7)(params, wave, k, lam0, scale, z0, zref, c, go)


correct_batch = engine_jit(_correct_batch, ("wave_axes", "contact"))
"""The corrector, batched: one compilation per batch size, waveform type and settings, whatever the
parameter (the selector is traced) and the gait period."""
