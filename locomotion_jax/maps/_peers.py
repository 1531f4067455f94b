"""A multi-process sweep that outlives one of its processes ends cleanly (issue 29).

When a process of a `jax.distributed` sweep into a Zarr store dies, the others take over its
chunks (`_zarr_sweep`) and finish the store. JAX stood in the way of a clean end: its
coordination client aborts every process (SIGABRT, exit 134) once it learns that one was lost,
from its error polling or at the shutdown barrier of `jax.distributed.shutdown()` at exit, even
after the store was complete. With JAX's `jax_enable_recoverability` set before
`jax.distributed.initialize` (the CLI's `--distributed` sets it) the survivors exit as their
program does (0 for the CLI's `sweep`); each says which chunks it took over ([`report_takeover`][]).
"""

import time

import jax


def _live(n_proc: int) -> "list[int] | None":
    """The processes the coordination service counts alive, or `None` where it cannot tell (no
    `jax.distributed`, a JAX without `get_live_nodes`, or the service itself gone with process 0)."""
    try:
        from jax._src import distributed

        client = distributed.global_state.client
        if client is None:
            return None
        return list(client.get_live_nodes(list(range(n_proc))))
    except Exception:
        return None


def lost_peers(n_proc: int, me: int) -> list[int]:
    """The other processes the coordination service no longer counts alive (`[]` where it cannot
    tell: one process, no `jax.distributed`, or a JAX without `get_live_nodes`)."""
    live = _live(n_proc) if n_proc > 1 else None
    if live is None:
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


LEAVE_TIMEOUT_SECONDS = 60.0
"""How long process 0 waits at the end for its peers to leave (see [`wait_for_peers_to_leave`][])."""


def wait_for_peers_to_leave(n_proc: int, timeout: float = LEAVE_TIMEOUT_SECONDS, poll: float = 0.05) -> None:
    """Process 0 hosts JAX's coordination service. With `jax_enable_recoverability`, shutdown is
    no barrier, so a process 0 that exited first would take the service with it, and a peer still
    disconnecting would abort (SIGABRT) although the store is complete. So process 0 waits until
    the service no longer counts any peer alive (each finished and left, or was lost), or `timeout`."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        live = _live(n_proc) if n_proc > 1 else None
        if live is None or all(p == 0 for p in live):
            return
        time.sleep(poll)
