"""Forward-mode differentiation only: a clear refusal of reverse mode.

The exact engine runs each configuration in a `lax.while_loop` whose length
depends on the run (events cut steps). JAX differentiates such a loop in forward
mode (`jax.jvp`, `jax.jacfwd`), not in reverse mode (`jax.grad`, `jax.vjp`,
`jax.jacrev`): that would need every iteration stored. [`forward_only`][] is the
identity, and linear, so forward mode passes through it; transposing it (the
first thing reverse mode does with an output) raises a `TypeError` that says
what to use instead.
"""

from typing import Any

import jax
import jax.core  # (jax.core.Tracer) for type checkers
import jax.numpy as jnp
from jax.interpreters import ad, batching, mlir


try:
    from jax.extend.core import Primitive
except ImportError:  # older JAX
    from jax.core import Primitive  # type: ignore[attr-defined,no-redef]


REVERSE_MODE_MESSAGE = (
    "locomotion_jax's exact engine supports forward-mode differentiation only: use "
    "jax.jvp or jax.jacfwd (one forward pass per input direction), not jax.grad, jax.vjp "
    "or jax.jacrev. Its time loop has a length decided while it runs (located stick/slip "
    "events), which reverse mode cannot traverse without storing every step."
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
    while isinstance(x, jax.core.Tracer):
        inner = getattr(x, "primal", None)
        if inner is None:
            inner = getattr(x, "val", None)
        if inner is None:
            raise jax.errors.ConcretizationTypeError(x)
        x = inner
    return x


def check_static(name: str, value: Any) -> None:
    """Refuse a traced value for an option that sets the computation's shape or length."""
    if is_traced(value):
        raise TypeError(
            f"{name} is an option of the run, not a model parameter: it cannot be traced or "
            "differentiated. Differentiate with respect to Params fields, waveform coefficients "
            "or a Chain's fields instead."
        )
