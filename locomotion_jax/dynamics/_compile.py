"""How the exact engine's batched loops are compiled.

`jax.jit` with static arguments named, plus XLA options for the host CPU.
`jax.jit` (unlike `equinox.filter_jit`) returns as soon as the work is
dispatched, so a caller can prepare the next chunk while a device computes.

Called under a transformation (`jax.jvp`, `jax.jacfwd`, `vmap`), the engine is
compiled without the options (JAX accepts them on a top-level `jit` only). With
`reverse=True` (a function whose loops are `_queue.run_queue`'s: `measure`,
`simulate`) reverse mode differentiates it: the backward pass traces the function
again inside `_queue.reverse_loops`. Otherwise its outputs pass through
[`_forward.forward_only`][], so reverse mode is refused with a clear message.
"""

import functools
import inspect
from collections.abc import Callable, Sequence

import jax

from ._forward import forward_only, is_traced, jvp_leaves, one_direction_at_a_time
from ._queue import reverse_loops


COMPILER_OPTIONS: dict[str, str] = {"xla_cpu_prefer_vector_width": "512"}
"""XLA options of the engine's compilations.

XLA's CPU backend asks LLVM for 256-bit vectors by default; on a CPU with AVX-512
the loop body's elementwise kernels (64 lanes each) then run in half as many
instructions at 512 bits: 1.15x on the exact engine, same results (benchmarks/NOTES.md).
It is a preference: LLVM keeps to the vector width the CPU has, and backends
other than the CPU do not read `xla_cpu_*` options."""


def engine_jit(fn: Callable, static_argnames: Sequence[str], reverse: bool = False) -> Callable:
    """`jax.jit(fn)` with [`COMPILER_OPTIONS`][] and the given static arguments (module
    docstring: under a transformation, a plain `jit`; reverse mode with `reverse`, refused
    without).
    The returned function has the jitted one's `lower`, `eval_shape` and `_cache_size`."""
    static = tuple(static_argnames)
    top = jax.jit(fn, static_argnames=static, compiler_options=COMPILER_OPTIONS)
    nested = jax.jit(fn, static_argnames=static)

    @functools.wraps(fn)  # the signature, for `static_argnames`
    def traced_reversible(*args, **kwargs):
        with reverse_loops():  # read while tracing: this `jit`'s cache only ever holds these loops
            return fn(*args, **kwargs)

    # Compiled once and cached like `nested`, so that repeated reverse-mode calls reuse the program.
    reversible = jax.jit(traced_reversible, static_argnames=static)

    signature = inspect.signature(fn)

    @functools.cache
    def compiled_jvp(fixed: tuple, tree, active: tuple) -> Callable:
        # One direction's jvp as a top-level computation (with the options), for eager calls.
        run = lambda ps, ts: jvp_leaves(lambda d: fn(**dict(fixed), **d), tree, ps, ts, active)
        return jax.jit(run, compiler_options=COMPILER_OPTIONS)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if not is_traced((args, kwargs)):
            return top(*args, **kwargs)
        bound = signature.bind(*args, **kwargs)
        fixed = tuple((k, v) for k, v in bound.arguments.items() if k in static)
        dyn = {k: v for k, v in bound.arguments.items() if k not in static}
        compiled = lambda tree, active: compiled_jvp(fixed, tree, active)
        run = lambda d: nested(**dict(fixed), **d)
        if not reverse:
            return forward_only(one_direction_at_a_time(run, dyn, compiled))

        traversable = lambda d: reversible(**dict(fixed), **d)
        return one_direction_at_a_time(run, dyn, compiled, traversable)

    call.lower = top.lower  # pyright: ignore[reportAttributeAccessIssue]
    call.eval_shape = top.eval_shape  # pyright: ignore[reportAttributeAccessIssue]
    call._cache_size = top._cache_size  # pyright: ignore[reportAttributeAccessIssue]
    return call
