"""Differentiation of the exact engine: forward mode everywhere, reverse mode where a loop allows.

The exact engine runs each configuration in a `lax.while_loop` whose length depends on the
run (events cut steps). JAX differentiates such a loop in forward mode (`jax.jvp`,
`jax.jacfwd`) but not in reverse mode (`jax.grad`, `jax.vjp`, `jax.jacrev`), which needs the
iterations stored. Two ways out:

- [`one_direction_at_a_time`][] with a `reverse` function: the engine's forward-mode
  derivative is wrapped in `jax.custom_derivatives.linear_call`, whose transpose (what reverse
  mode evaluates) is a `jax.vjp` of `reverse`, the same computation traced with loops that
  reverse mode traverses (`_queue.reverse_loops`: `measure` and `simulate`). The forward pass
  stays the fast work queue; the backward pass re-runs each configuration in a checkpointed loop.
- Elsewhere (steady gaits' Newton loops, sweeps' chunks) [`forward_only`][], the identity and
  linear, so that forward mode passes through it; transposing it (the first thing reverse mode
  does with an output) raises a `TypeError` that says what to use instead.
"""

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.core  # (jax.core.Tracer) for type checkers
import jax.custom_batching
import jax.numpy as jnp
import numpy as np
from jax._src import core as _core  # eval_jaxpr, for linear_call's batching rule
from jax._src.custom_derivatives import linear_call_p as _linear_call_p
from jax.interpreters import ad, batching, mlir, partial_eval as pe

from .._custom_types import Array


try:
    from jax.extend.core import Primitive
except ImportError:  # older JAX
    from jax.core import Primitive  # type: ignore[attr-defined,no-redef]


REVERSE_MODE_MESSAGE = (
    "this computation of locomotion_jax's exact engine supports forward-mode differentiation only: use "
    "jax.jvp or jax.jacfwd (one forward pass per input direction), not jax.grad, jax.vjp "
    "or jax.jacrev. Its loops (steady gaits' Newton iterations, sweeps' chunks) have lengths decided "
    "while they run, which reverse mode cannot traverse. Reverse mode works through measure and "
    "simulate, and through a chain's steady gait by locomotion_jax.gaits._adjoint.steady_gait."
)

VMAP_REVERSE_MESSAGE = (
    "reverse mode (jax.grad, jax.vjp) through locomotion_jax's measure or simulate under jax.vmap is not "
    "supported: pass the configurations as one batch (the engine runs batches itself) and differentiate "
    "a function of the whole batch, or use jax.jacfwd."
)


def _refuse(cotangent, x):
    del cotangent, x
    raise TypeError(REVERSE_MODE_MESSAGE)


_forward_only_p = Primitive("forward_mode_only")
_forward_only_p.def_impl(lambda x: x)
_forward_only_p.def_abstract_eval(lambda x: x)
mlir.register_lowering(_forward_only_p, mlir.lower_fun(lambda x: x, multiple_results=False))
ad.deflinear2(_forward_only_p, _refuse)
batching.defvectorized(_forward_only_p)


def forward_only(tree: Any) -> Any:
    """The identity on every floating-point leaf of `tree`; reverse mode through it
    raises a `TypeError` recommending `jax.jacfwd` (module docstring)."""

    def one(x):
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.inexact):
            return _forward_only_p.bind(x)
        return x

    return jax.tree_util.tree_map(one, tree)


def is_traced(tree: Any) -> bool:
    """Whether any leaf of `tree` is a JAX tracer (under `jvp`, `vmap`, `jit`, ...)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def concrete_value(x: Any) -> Any:
    """The value under the tracers of eager transformations (`jvp`'s primal, `vmap`'s
    batched value), for host-side bounds; raises `jax.errors.ConcretizationTypeError`
    under `jit`, where there is none."""
    tracer = x
    while isinstance(x, jax.core.Tracer):
        inner = getattr(x, "primal", None)
        if inner is None:
            inner = getattr(x, "val", None)
        if inner is None:
            raise jax.errors.ConcretizationTypeError(x)
        x = inner
    if not isinstance(x, (jax.Array, np.ndarray, np.generic, int, float, complex, bool)):
        raise jax.errors.ConcretizationTypeError(tracer)  # e.g. a `jit` tracer's inner value
    return x


def check_static(name: str, value: Any) -> None:
    """Refuse a traced value for an option that sets the computation's shape or length."""
    if is_traced(value):
        raise TypeError(
            f"{name} is an option of the run, not a model parameter: it cannot be traced or "
            "differentiated. Differentiate with respect to Params fields, waveform coefficients "
            "or a Chain's fields instead."
        )


def jvp_leaves(fn: Callable[[Any], Any], tree: Any, primals: list, tangents: list, active: tuple) -> Any:
    """`jax.jvp` of `fn` at the pytree `tree` of `primals`, where only the `active` leaves
    carry `tangents` (the others are constants of `fn`)."""

    def f_active(xs):
        it = iter(xs)
        return fn(jax.tree_util.tree_unflatten(tree, [next(it) if a else x for x, a in zip(primals, active)]))

    xs = [x for x, a in zip(primals, active) if a]
    ts = [t for t, a in zip(tangents, active) if a]
    return jax.jvp(f_active, (xs,), (ts,))


def _reverse_linear(fn: Callable[[Any], Any], reverse: Callable[[Any], Any], tree, primals: list, ts: list,
                    active: tuple) -> Any:  # fmt: skip
    """The tangent of `fn` at `primals` as a `linear_call`: evaluated, forward mode through `fn`;
    transposed, `jax.vjp` of `reverse` (the same function traced with reverse-traversable loops)
    with respect to the active inputs. Integer outputs get `float0` tangents outside it."""
    shapes = jax.eval_shape(lambda ps: fn(jax.tree_util.tree_unflatten(tree, ps)), primals)
    out_leaves, out_tree = jax.tree_util.tree_flatten(shapes)
    inexact = [jnp.issubdtype(o.dtype, jnp.inexact) for o in out_leaves]

    def with_active(ps, xs):
        it = iter(xs)
        return jax.tree_util.tree_unflatten(tree, [next(it) if a else p for p, a in zip(ps, active)])

    def floats(tree_out):
        return [x for x, f in zip(jax.tree_util.tree_leaves(tree_out), inexact) if f]

    def forward(ps, lin):
        full = [t if a else None for t, a in zip(_expand(lin, active), active)]
        _, tangent = jvp_leaves(fn, tree, ps, full, active)
        return floats(tangent)

    def transpose(ps, cts):
        xs = [p for p, a in zip(ps, active) if a]
        _, vjp = jax.vjp(lambda xs: floats(reverse(with_active(ps, xs))), xs)
        return vjp(list(cts))[0]

    lin = [t for t, a in zip(ts, active) if a]
    tangents = iter(jax.custom_derivatives.linear_call(forward, transpose, list(primals), lin))
    zeros = lambda o: np.zeros(o.shape, jax.dtypes.float0)
    return jax.tree_util.tree_unflatten(
        out_tree, [next(tangents) if f else zeros(o) for o, f in zip(out_leaves, inexact)]
    )


def _batch_linear_call(args, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    """A batching rule for `linear_call` (JAX defines none): `vmap` of its callee's evaluation.

    Reverse mode's `jax.jacrev` maps the transposed call (`_reverse_linear`'s `transpose`) over
    cotangent directions; this evaluates it per direction as one vectorised computation. The
    result is no longer a `linear_call`: a transposition after a `vmap` (`vmap` of `grad`) is
    refused earlier with [`VMAP_REVERSE_MESSAGE`][]."""
    del transpose_thunk, num_callee_consts, num_res
    fun = lambda *a: _core.eval_jaxpr(callee.jaxpr, (), *a)
    outs = jax.vmap(fun, in_axes=list(dims))(*args)  # None: not mapped
    return outs, [0] * len(outs)


if _linear_call_p not in getattr(batching, "fancy_primitive_batchers", {}):  # a JAX with its own rule keeps it
    batching.primitive_batchers[_linear_call_p] = _batch_linear_call


def _expand(lin: list, active: tuple) -> list:
    it = iter(lin)
    return [next(it) if a else None for a in active]


def jacfwd_in_turn(f: Callable[[Array], Any], has_aux: bool = False) -> Callable[[Array], Any]:
    """`jax.jacfwd(f, has_aux=has_aux)` of a function of one vector, its directions pushed
    through in turn on a CPU (a `lax.map` of `jax.jvp`, the primal recomputed for each).

    Pushed together, every tangent of the engine's loop is a `(lanes, p)` array, and beyond 64
    elements per kernel XLA's CPU runtime splits each kernel over its threads (as in
    [`one_direction_at_a_time`][]); in turn, a period map of a 4-mass chain and its 7 directions
    cost 2.8x (array layout) to 5.3x (one entry per body) less, and compile in half the time
    (benchmarks/NOTES.md). Elsewhere `jax.jacfwd` itself. Worth it where the directions are few
    and the batch wide (the steady-gait corrector); the optimisers' orbit oracle, with many
    directions on a few lanes, keeps `jax.jacfwd` (in turn, the paper optimiser's local
    refinement took 4x as long)."""
    if jax.default_backend() != "cpu":
        return jax.jacfwd(f, has_aux=has_aux)

    def jacobian(x: Array) -> Any:
        def one(v):
            if has_aux:
                _, tangent, aux = jax.jvp(f, (x,), (v,), has_aux=True)
                return tangent, aux
            return jax.jvp(f, (x,), (v,))[1], None

        tangents, aux = jax.lax.map(one, jnp.eye(x.shape[0], dtype=x.dtype))
        J = jax.tree_util.tree_map(lambda t: jnp.moveaxis(t, 0, -1), tangents)
        return (J, jax.tree_util.tree_map(lambda a: a[0], aux)) if has_aux else J

    return jacobian


def one_direction_at_a_time(
    fn: Callable[[Any], Any],
    dyn: Any,
    compiled: Callable[[Any, tuple], Callable],
    reverse: Callable[[Any], Any] | None = None,
) -> Any:
    """`fn(dyn)`, differentiated in forward mode one input direction at a time.

    `jax.jacfwd` pushes all `p` directions through at once (a `vmap` of `jvp`): every
    tangent of the engine's loop becomes a `(lanes, p)` array, and beyond 64 elements per
    kernel XLA's CPU runtime splits each kernel over its threads, which costs more than
    the whole computation (`_runs.MICRO_BATCH_CPU`; benchmarks/NOTES.md). Here a `vmap`
    over tangent directions alone (primal inputs unbatched, as in `jacfwd`) runs the
    directions in turn, each a `jvp` with `(lanes,)` tangents; any other `vmap` is the usual
    one. Inputs whose tangent is a symbolic zero stay constants.

    `compiled(tree, active)` is a compiled `(primals, tangents) -> jvp` for concrete values
    (called eagerly: one compilation serves every direction and call); under `jit` several
    directions run in a `lax.map` of `fn`'s `jvp` (slower than eagerly: measured, not
    understood), one as usual.

    `reverse`: `fn` traced with loops that reverse mode traverses, or `None`. With it, reverse
    mode's linearisation (tangents that are partial-evaluation tracers) gets the tangent as a
    `linear_call` whose transpose is `reverse`'s `jax.vjp` (module docstring).
    """
    leaves, tree = jax.tree_util.tree_flatten(dyn)

    @jax.custom_jvp
    def f(*xs):
        return fn(jax.tree_util.tree_unflatten(tree, list(xs)))

    @functools.partial(f.defjvp, symbolic_zeros=True)
    def _f_jvp(primals, tangents):
        active = tuple(not isinstance(t, jax.custom_derivatives.SymbolicZero) for t in tangents)
        ts = [t if a else None for t, a in zip(tangents, active)]
        if reverse is not None and any(isinstance(t, pe.JaxprTracer) for t in ts):
            if any(getattr(p, "batch_dim", None) is not None for p in primals):
                raise TypeError(VMAP_REVERSE_MESSAGE)
            out = fn(jax.tree_util.tree_unflatten(tree, list(primals)))
            return out, _reverse_linear(fn, reverse, tree, list(primals), ts, active)
        run = lambda ps, ts: jvp_leaves(fn, tree, ps, ts, active)
        if not is_traced((primals, ts)):
            return compiled(tree, active)(list(primals), ts)
        directions = jax.custom_batching.custom_vmap(run)

        @directions.def_vmap
        def _rule(axis_size, in_batched, ps, ts):
            p_batched, t_batched = in_batched
            if any(p_batched) or (axis_size == 1 and is_traced((ps, ts))):
                axes = lambda flags: [0 if b else None for b in flags]
                out = jax.vmap(run, in_axes=(axes(p_batched), axes(t_batched)))(ps, ts)
                return out, jax.tree_util.tree_map(lambda _: True, out)
            pick = lambda k: [t[k] if b else t for t, b in zip(ts, t_batched)]
            if not is_traced((ps, ts)):
                outs = [compiled(tree, active)(ps, pick(k)) for k in range(axis_size)]
                primal_out = outs[0][0]
                tangent_out = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *(o[1] for o in outs))
            else:
                mapped = [t for t, b in zip(ts, t_batched) if b]

                def one(xs):
                    it = iter(xs)
                    return run(ps, [next(it) if b else t for t, b in zip(ts, t_batched)])

                primal_out, tangent_out = jax.lax.map(one, mapped)
                primal_out = jax.tree_util.tree_map(lambda x: x[0], primal_out)
            unbatched = jax.tree_util.tree_map(lambda _: False, primal_out)
            return (primal_out, tangent_out), (unbatched, jax.tree_util.tree_map(lambda _: True, tangent_out))

        # A `vmap`'s tracers carry a `batch_dim` (their class is not public).
        if all(getattr(t, "batch_dim", None) is not None for t in ts if t is not None):
            return directions(list(primals), ts)  # jacfwd: the primal comes with the directions
        # Any other transformation (reverse mode's linearisation among them) needs the
        # primal known apart from the tangents.
        return fn(jax.tree_util.tree_unflatten(tree, list(primals))), directions(list(primals), ts)[1]

    return f(*leaves)
