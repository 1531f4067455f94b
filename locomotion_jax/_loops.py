"""A `lax.while_loop` for loops whose end differs from lane to lane under `vmap`.

Under `vmap`, a `while_loop` whose predicate is batched carries every value batched (a lane that
has ended keeps its values while the others run). JAX's batching rule finds which carried values
are batched by a fixpoint: it batches the loop's body once for the batched values of the initial
carry, again wherever the body made more of them batched, and then once more with all of them
batched. Nested loops multiply these passes (the engine's step loop inside a gait's period loop
inside Newton's method): with this loop the tracing of the paper optimiser's sinusoid baseline
and first orbit batch took 34.1 s instead of 51.5 (`benchmarks/NOTES.md`). `lane_while_loop` makes every
initial value batched wherever one is, so that the first pass is the last: the same batched
program, traced once.
"""

from collections.abc import Callable
from functools import reduce
from typing import Any

import jax
import jax.numpy as jnp


def along_lanes(tree: Any) -> Any:
    """`tree`'s values unchanged, each made to depend on all of them: under `vmap` every leaf is
    batched if any is (outside `vmap` the same values, for a compare and a select per leaf at the
    loop's entry, which XLA keeps)."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    arrays = [jnp.asarray(x) for x in leaves]
    firsts = [jnp.ravel(x)[0] for x in arrays if x.size]
    if not firsts:
        return tree
    # `x == x` is a per-lane boolean (false for a NaN, which does not matter: both branches are x).
    lane = reduce(jnp.logical_and, [x == x for x in firsts])
    same = [jax.lax.select(jnp.broadcast_to(lane, x.shape), x, x) for x in arrays]
    return jax.tree_util.tree_unflatten(treedef, same)


def lane_while_loop(cond: Callable[[Any], Any], body: Callable[[Any], Any], init: Any) -> Any:
    """`jax.lax.while_loop(cond, body, init)` for a loop that ends lane by lane under `vmap`
    (module docstring): the same result, the body batched once."""
    return jax.lax.while_loop(cond, body, along_lanes(init))
