"""Newton's method on the period map with the parameter as an unknown (continuation's corrector).

For a gait of period $kT$ the unknowns are $z = (y, \\zeta)$: the section state $y$ of
[`steady_gait`][] (length $S$: $(u, v_1, v_2)$ for the paper's model, a chain's gaps and velocities)
and the parameter $\\lambda = \\lambda_0 + s\\,\\zeta$ in units of a scale $s$. The corrector solves

$$\\Phi_k(y; \\lambda) - y = 0, \\qquad c \\cdot (z - z_\\text{ref}) = 0,$$

the fixed point on the hyperplane through $z_\\text{ref}$ normal to $c$: with $c$ the tangent of
the branch this is pseudo-arclength continuation's corrector; with $c = e_\\zeta$ it solves at a
fixed parameter ([`steady_gait`][]).
The Jacobian $[\\,\\partial\\Phi_k/\\partial y,\\ \\partial\\Phi_k/\\partial\\zeta\\,]$
comes from one forward-mode pass ($S + 1$ tangents) through the N-body exact engine, event times by
the implicit function theorem: its first $S$ columns are the monodromy matrix. The same pass
differentiates the switching test functions of the period (the slip margin and the smallest normal
force, [`Gait`][]), whose gradients say on which side of a switching surface a point lies.

Where the Newton system is singular the fixed points are a family, not an isolated orbit: a body
that stays stuck all period in a mechanism tied to the wall holds anywhere within its stick range
(its position's row of $\\partial\\Phi_k/\\partial y - I$ is zero, a multiplier 1). There the step is
the least-squares step of least norm (`_newton_step`), which goes to the nearest member of the
family instead of dividing by zero.

The period map is the same for every mechanism (`_shooting.period_map` of the configuration's
physics); what a mechanism supplies is a flat batch of configurations (a pytree with a leading
batch axis) and `physics_of(c) -> (physics, valid)` for one configuration. The parameter is a
[`Selector`][]: a boolean mask over the leaves of one configuration, traced, so that one
compilation serves every parameter. For [`Params`][] it is a field or, for a [`Fourier`][]
waveform, a coefficient `"cosN"`/`"sinN"` of harmonic `N` (from 1); for a [`Chain`][] or a
[`Mechanism`][locomotion_jax.Mechanism], any scalar entry of its leaves, named by the leaf's
attribute (`"omega"`, `"mu_s"`, `"m[1]"`: see [`parse_leaf`][]).
"""

import re
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array
from .._loops import lane_while_loop
from .._status import Status
from ..dynamics._compile import engine_jit
from ..dynamics._forward import jacfwd_in_turn
from ..model._params import PARAM_NAMES, Params
from ..model._waveform import AbstractWaveform, Fourier, Sinusoid
from ._orbit import tolerance_scale
from ._shooting import _Period, period_map


Selector = Any
"""A pytree like one configuration, with a boolean array of the leaf's shape at each leaf: the
entries that the parameter sets."""


class Spec(NamedTuple):
    """A continuation parameter of the paper's model: a `Params` field (`harmonic` -1) or a waveform
    coefficient (`name` "cos" or "sin", `harmonic` from 0)."""

    name: str
    harmonic: int

    @property
    def label(self) -> str:
        return self.name if self.harmonic < 0 else f"{self.name}{self.harmonic + 1}"


def parse(parameter: str, waveform: AbstractWaveform | None) -> Spec:
    """The [`Spec`][] of `parameter` for [`Params`][]; `ValueError` naming the valid choices."""
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


_WAVE_FIELDS = ("omega", "lbar", "a")


def _one(C: Any) -> Any:
    """One configuration's leaves (the flat batch's without its leading axis), as shapes."""
    return jax.tree_util.tree_map(lambda x: np.zeros(np.shape(x)[1:], bool), C)


def no_selection(C: Any) -> Selector:
    """The selector of no parameter (every mask False) for configurations like the flat batch `C`."""
    return jax.tree_util.tree_map(jnp.asarray, _one(C))


def paper_selector(spec: Spec, C: tuple[Params, AbstractWaveform]) -> Selector:
    """The masks of `spec` over a configuration `(params, waveform)` of the paper's model: the
    `Params` field and the waveform's field of that name where it has one (`omega`, `lbar`, `a`),
    or the Fourier coefficient."""
    params, wave = _one(C)
    if spec.harmonic >= 0:
        coef = getattr(wave, spec.name).copy()
        coef[..., spec.harmonic] = True
        wave = _replace(wave, spec.name, coef)
    else:
        params = _replace(params, spec.name, np.ones((), bool))
        if spec.name in _WAVE_FIELDS and hasattr(wave, spec.name):
            wave = _replace(wave, spec.name, np.ones((), bool))
    return jax.tree_util.tree_map(jnp.asarray, (params, wave))


def _replace(tree: Any, name: str, value: Any) -> Any:
    import equinox as eqx

    return eqx.tree_at(lambda t: getattr(t, name), tree, value)


def _leaf_names(path) -> str:
    """A leaf's attribute path, `".waves.omega"`, with `[i]` for an item of a tuple (`".links[0].k"`)."""
    return "".join(f".{k.name}" if isinstance(k, jax.tree_util.GetAttrKey)
                   else f"[{k.idx}]" if isinstance(k, jax.tree_util.SequenceKey) else "" for k in path)  # fmt: skip


def parse_leaf(parameter: str, C: Any, kind: str) -> Selector:
    """The selector of `parameter` over the configurations `C` of a mechanism (a flat batch).

    `parameter` names the leaves whose attribute path ends with it (`"omega"`, `"mu_s"`,
    `"friction.mu_s"`; `[i]` an item of a tuple: a mechanism's `"links[0].k"`,
    `"friction[0].mu_s_fwd"`), every entry of them; or, with an index after a leaf, `"m[1]"`, the
    entry of that index along its last axis. Every selected entry takes the parameter's value, so
    where several are selected they must be equal at the start ([`value`][] checks)."""
    if not isinstance(parameter, str):
        raise TypeError(f"parameter must be a str, got {type(parameter).__name__}.")
    leaves, tree = jax.tree_util.tree_flatten_with_path(_one(C))
    names = [_leaf_names(p) for p, _ in leaves]
    ends = lambda path: [i for i, n in enumerate(names) if n.endswith("." + path)]
    ok = re.fullmatch(r"[A-Za-z_][\w.\[\]]*", parameter) is not None
    # A whole leaf by the end of its path first; else a leaf and the index of one entry.
    m = re.fullmatch(r"(.+)\[(\d+)\]", parameter)
    whole = ends(parameter) if ok else []
    hit = whole or ([] if m is None or not ok else ends(m.group(1)))
    if not hit:
        valid = ", ".join(sorted({n.rsplit(".", 1)[-1] for n in names if n}))
        raise ValueError(
            f"unknown parameter {parameter!r} of a {kind}; valid: a leaf ({valid}), with [i] for one entry of "
            "a per-body or per-spring array (e.g. 'm[1]'), a path for one element (e.g. 'links[0].k')."
        )
    masks = [x for _, x in leaves]
    for i in hit:
        mask = np.zeros_like(masks[i])
        if whole:
            mask[...] = True
        else:
            assert m is not None
            j = int(m.group(2))
            if mask.ndim == 0 or not 0 <= j < mask.shape[-1]:
                size = "is a scalar" if mask.ndim == 0 else f"has entries 0..{mask.shape[-1] - 1}"
                raise ValueError(f"parameter {parameter!r}: the leaf {names[i].lstrip('.')!r} {size}.")
            mask[..., j] = True
        masks[i] = mask
    return jax.tree_util.tree_unflatten(tree, [jnp.asarray(x) for x in masks])


def value(C: Any, sel: Selector, parameter: str) -> np.ndarray:
    """The parameter's value per configuration of the flat batch `C` (host, float64); `ValueError`
    where the entries it selects differ in a configuration (name one with an index)."""
    vals = []
    for x, mask in zip(jax.tree_util.tree_leaves(C), jax.tree_util.tree_leaves(sel)):
        mask = np.asarray(mask)
        if mask.any():
            x = np.asarray(x, np.float64)
            vals.append(np.broadcast_to(x, (x.shape[0],) + mask.shape)[:, mask])
    allv = np.concatenate(vals, axis=1)
    if np.any(allv != allv[:, :1]):
        raise ValueError(
            f"parameter {parameter!r} selects entries of different values ({allv[0].tolist()} in the first "
            "configuration): name one with an index, e.g. 'm[1]'."
        )
    return allv[:, 0]


def with_value(c: Any, sel: Selector, lam: Array) -> Any:
    """One configuration `c` with the entries selected by `sel` set to `lam`."""
    return jax.tree_util.tree_map(lambda x, m: jnp.where(m, lam.astype(x.dtype), x), c, sel)


class Solved(NamedTuple):
    """The corrector's result for one configuration."""

    z: Array  # (y, zeta)
    J: Array  # (S + 2, S + 1): the derivatives of (Phi, margin, n_min) in (y, zeta)
    out: _Period
    done: Array  # converged
    valid: Array  # the parameters at z are valid
    it: Array


def _newton_step(A: Array, F: Array) -> Array:
    """$A^{-1} F$; where that is not finite ($A$ singular), the least-squares solution of least norm."""
    step = jnp.linalg.solve(A, F)
    return jnp.where(jnp.all(jnp.isfinite(step)), step, jnp.linalg.lstsq(A, F)[0])


def _correct_one(
    c, physics_of, sel, contact, dt, k, lam0, scale, z0, zref, cvec, go, tol, max_iter, max_steps, patience
) -> Solved:
    """Newton's method on the module docstring's system from `z0` (skipped where `go` is False).

    A configuration stops, unconverged, once `patience` iterations in a row have not halved the
    smallest residual $\\max|\\Phi_k(y) - y|$ reached so far: in the superlinear phase every
    iteration does, and in a batch that runs in lockstep a stalled configuration would hold the
    others up to `max_iter`. `patience >= max_iter` never stops one early."""
    dtype = z0.dtype
    n = z0.shape[0] - 1
    k = jnp.where(go, k, 0)  # a configuration not solved here integrates nothing
    shift = jnp.concatenate([jnp.eye(n, dtype=dtype), jnp.zeros((n, 1), dtype)], axis=1)

    def phi(z):
        P, valid = physics_of(with_value(c, sel, lam0 + scale * z[n]))
        out = period_map(P, contact, dt, max_steps, k, z[:n])
        # The switching test functions' gradients come with the monodromy (to cross a switching surface).
        return jnp.concatenate([out.y, jnp.stack([out.margin, out.n_min])]), (out, valid)

    def evaluate(z):
        J, (out, valid) = jacfwd_in_turn(phi, has_aux=True)(z)
        bad = (out.status != Status.OK) | ~valid | ~jnp.all(jnp.isfinite(z)) | ~jnp.all(jnp.isfinite(J[:n]))
        return J, out, valid, bad

    def residual(z, out):
        return jnp.max(jnp.abs(out.y - z[:n]))

    def small(z, out):
        return residual(z, out) <= tol * (1 + tolerance_scale(z[:n], z0[:n]))

    # A start off the hyperplane is a valid point only after a step onto it.
    on = jnp.abs(cvec @ (z0 - zref)) <= tol * (1 + jnp.max(jnp.abs(z0)))

    def cond(s):
        _, _, _, _, it, done, failed, _, since, started = s
        return ~started | (~done & ~failed & (it < max_iter) & (since < patience))

    def body(s):
        # The first pass evaluates the start; each later one takes a Newton step first. One call
        # site of the differentiated period map: it is traced and compiled once.
        z, J, out, _, it, _, _, best, since, started = s
        A = jnp.concatenate([J[:n] - shift, cvec[None]], axis=0)
        F = jnp.concatenate([out.y - z[:n], (cvec @ (z - zref))[None]])
        z1 = jnp.where(started, z - _newton_step(A, F), z)
        J1, out1, valid1, bad = step(z1)
        r1 = residual(z1, out1)
        since1 = jnp.where(started, jnp.where(r1 <= best / 2, 0, since + 1), 0)
        done1 = small(z1, out1) & ~bad & (started | (go & on))
        failed1 = bad | (~started & ~go)
        return (z1, J1, out1, valid1, jnp.where(started, it + 1, it), done1, failed1, jnp.minimum(best, r1), since1,
                jnp.asarray(True))  # fmt: skip

    step = jax.jit(evaluate)  # traced once: `eval_shape` below and the loop's body share its trace
    J0, out0, valid0, _ = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(step, z0))
    zero, no = jnp.zeros((), jnp.int32), jnp.asarray(False)
    init = (z0, J0, out0, valid0, zero, no, no, jnp.asarray(jnp.inf, dtype), zero, no)
    z, J, out, valid, it, done, _, _, _, _ = lane_while_loop(cond, body, init)
    return Solved(z=z, J=J, out=out, done=done & go, valid=valid, it=it)


def _correct_batch(C, physics_of, sel, contact, dt, k, lam0, scale, z0, zref, c, go, tol, max_iter, max_steps,
                   patience):  # fmt: skip
    def one(c1, k1, l1, s1, z1, r1, v1, g1):
        return _correct_one(c1, physics_of, sel, contact, dt, k1, l1, s1, z1, r1, v1, g1, tol, max_iter, max_steps,
                            patience)  # fmt: skip

    return jax.vmap(one)(C, k, lam0, scale, z0, zref, c, go)


correct_batch = engine_jit(_correct_batch, ("physics_of", "contact"))
"""The corrector, batched: one compilation per batch size, kind of configuration and settings,
whatever the parameter (the selector is traced), the gait period, the step `dt` and the
iteration limits."""
