"""A multi-process sweep that outlives one of its processes ends cleanly (issue 29).

When a process of a `jax.distributed` sweep into a Zarr store dies, the others take over its
chunks (`_zarr_sweep`) and finish the store. JAX stood in the way of a clean end: its
coordination client aborts every process (SIGABRT, exit 134) once it learns that one was lost,
from its error polling or at the shutdown barrier of `jax.distributed.shutdown()` at exit, even
after the store was complete. With JAX's `jax_enable_recoverability` set before
`jax.distributed.initialize` (the CLI's `--distributed` sets it) the survivors exit as their
program does (0 for the CLI's `sweep`); each says which chunks it took over ([`report_takeover`][]).
"""

import jax


def lost_peers(n_proc: int, me: int) -> list[int]:
    """The other processes the coordination service no longer counts alive (`[]` where it cannot
    tell: one process, no `jax.distributed`, or a JAX without `get_live_nodes`)."""
    if n_proc <= 1:
        return []
    try:
        from jax._src import distributed

        client = distributed.global_state.client
        if client is None:
            return []
        live = client.get_live_nodes(list(range(n_proc)))
    except Exception:  # the service itself may be gone with process 0: nothing more to learn here
        return []
    return [p for p in range(n_proc) if p != me and p not in live]


def report_takeover(me: int, n_proc: int, taken: dict[int, str], lost: list[int]) -> str:
    """The survivor's message: which chunks it took over, from whom, and the processes lost."""
    chunks = "; ".join(f"{i} (held by {holder})" for i, holder in sorted(taken.items())) or "none"
    gone = ", ".join(str(p) for p in lost) or "not known to the coordination service"
    message = (
        f"locomotion_jax.sweep: process {me} of {n_proc}: the store is complete. Chunks taken over from "
        f"processes that stopped: {chunks}. Processes lost: {gone}."
    )
    if not getattr(jax.config, "jax_enable_recoverability", False):
        message += (
            " JAX may abort this process at exit (its shutdown barrier waits for the lost ones): set "
            'jax.config.update("jax_enable_recoverability", True) before jax.distributed.initialize() '
            "(the CLI's --distributed does)."
        )
    return message
