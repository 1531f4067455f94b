"""`sweep` into a Zarr store: chunks shared out between processes, each written as it is done.

Every process (one, or several under `jax.distributed`) runs the same loop over the
chunks not yet done: it takes a chunk by locking it (`_zarr_store.ZarrStore.claim`),
computes it on its own devices, writes it to its region of the store and marks it
done. Process `p` of `P` tries chunks `p, p + P, p + 2P, ...` first, so processes
meet only at the end, then any chunk left: one held by a process that died is free
again (its lock went with it) and is taken over. A process returns once every chunk
is done, by whichever process. Processes exchange nothing but the store: no chunk
waits for another process, and a sweep left unfinished, by any number of
processes, is resumed by running it again, with any number of processes.

Chunks are blocks of the grid in C order (`_zarr_store.block_shape`); the
configurations of a chunk run as one padded batch, exactly as in a NetCDF sweep,
so the values do not depend on the store, the chunking or the number of processes.
"""

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ..dynamics._base import AbstractDynamics
from ..model._params import PARAM_NAMES
from . import _peers, _sharding as sharding
from ._dataset import dataset_fields, DESCRIPTIONS, sweep_attrs
from ._grid import RATIO
from ._zarr_store import block_shape, Blocks, ZarrStore


POLL_SECONDS = 0.5
"""How often a process whose chunks are all done checks on the chunks other processes hold."""


def sweep_to_zarr(
    grid,
    spec: dict[str, Any],
    path: Path,
    chunk_size: int,
    *,
    z: float,
    horizon: float,
    window: float,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    dtype: np.dtype,
    max_steps: int,
    overwrite: bool,
    progress: bool,
):
    """The body of `sweep(path="....zarr")` (arguments as there; `grid` a `_grid.Grid`).

    **Returns:** the finished store, opened lazily (`xarray.open_zarr`).
    """
    mesh = sharding.batch_mesh(local=True)  # each process computes whole chunks on its own devices
    ndev = sharding.device_count(mesh)
    n_proc = jax.process_count()
    derived = ("omega",) if RATIO in grid.values or RATIO in grid.fixed else ()

    def inputs(blocks: Blocks, index: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The chunk's parameter values (NaN-padded to the compiled size) and the unpadded ones."""
        vals = grid.config_values(blocks.configs(index))
        padded = sharding.padded_size(blocks.max_size, ndev, dtype)
        pad = lambda v: np.concatenate([v, np.full(padded - v.size, np.nan)])
        return {n: pad(vals[n]) for n in PARAM_NAMES}, vals

    def run(blocks: Blocks, index: int, fn=sharding.dispatch_chunk):
        return fn(inputs(blocks, index)[0], dtype, z, horizon, window, dynamics, contact, start, mesh)

    blocks = Blocks(grid.shape, block_shape(grid.shape, chunk_size))
    # Traced here, in every process, and reused by the chunks (a store made with another
    # block size costs one more trace): the processes start computing together.
    dtypes = run(blocks, 0, sharding.chunk_dtypes)

    def create() -> ZarrStore:
        if path.exists() and not overwrite:
            return ZarrStore.open(path, spec)
        variables = {k: (dtypes[k], {"description": DESCRIPTIONS.get(k, k)}) for k in dataset_fields(contact)}
        variables |= {k: (np.dtype(np.float64), {"description": DESCRIPTIONS[k]}) for k in derived}
        dims = grid.names if grid.mode == "grid" else ("config",)
        coords = {n: (n if grid.mode == "grid" else "config", grid.values[n]) for n in grid.names}
        attrs = sweep_attrs(grid, spec, dynamics, max_steps, ndev * n_proc, "natural")
        return ZarrStore.create(path, spec, dims, grid.shape, blocks.block, variables, coords, attrs, overwrite)

    def collect(blocks: Blocks, index: int, out: Any, n: int) -> dict[str, np.ndarray]:
        return sharding.fetch(out, n) | {k: inputs(blocks, index)[1][k] for k in derived}

    return fill_store(path, spec, create, grid.size, run, collect, progress)


def fill_store(
    path: Path,
    spec: dict[str, Any],
    create: Callable[[], ZarrStore],
    total: int,
    compute: Callable[[Blocks, int], Any],
    collect: Callable[[Blocks, int, Any, int], dict[str, np.ndarray]],
    progress: bool,
):
    """Fill the Zarr store at `path` chunk by chunk, with every process of the run (module
    docstring): `create()` creates the store or opens the one there (process 0, or the only
    process), `compute(blocks, index)` starts chunk `index`'s work (asynchronously, where it can)
    and `collect(blocks, index, out, n)` returns its `n` configurations' results as host arrays,
    written to the chunk's region. Any mechanism's sweep fills its store this way.

    **Returns:** the finished store, opened lazily (`xarray.open_zarr`).
    """
    from ._sweep import STATS

    me, n_proc = jax.process_index(), jax.process_count()
    if n_proc == 1:
        store = create()
    else:  # process 0 creates (or replaces) the store while the others wait, then all open it
        error = None
        if me == 0:
            try:
                create()
            except Exception as err:  # raised after the barrier: the others must not wait for ever
                error = err
        _barrier("locomotion_jax.sweep: store created")
        if error is not None:
            raise error
        store = ZarrStore.open(path, spec)  # each process checks the specification itself

    blocks = store.blocks
    size = lambda i: int(np.prod([r.stop - r.start for r in blocks.region(i)]))
    done = store.done()
    STATS["chunks_loaded"] += len(done)
    order = list(range(me, blocks.n_chunks, n_proc)) + [i for i in range(blocks.n_chunks) if i % n_proc != me]
    queue = [i for i in order if i not in done]
    from tqdm.auto import tqdm

    bar = tqdm(
        total=total,
        initial=sum(size(i) for i in done),
        unit="config",
        unit_scale=True,
        desc="sweep" if n_proc == 1 else f"sweep (process {me} of {n_proc})",
        disable=not progress,
        smoothing=0.1,
    )

    def finish(index: int, out: Any, claim) -> None:
        try:
            # Written, then marked done: an interruption before the mark loses only this chunk.
            store.write(index, collect(blocks, index, out, size(index)))
        finally:
            claim.release()
        bar.update(size(index))

    pending = None
    taken: dict[int, str] = {}
    try:
        while queue:
            for index in queue:
                if store.is_done(index):
                    continue
                claim = store.claim(index)
                if claim is None:  # a live process is computing it
                    continue
                if store.is_done(index):  # finished between our check and our lock
                    claim.release()
                    continue
                if claim.previous is not None:  # its earlier holder stopped before finishing it
                    taken[index] = claim.previous
                out = compute(blocks, index)
                STATS["chunks_computed"] += 1
                # Dispatch is asynchronous: the devices work on this chunk while the
                # host writes the previous one.
                if pending is not None:
                    finish(*pending)
                pending = (index, out, claim)
            if pending is not None:
                finish(*pending)
                pending = None
            queue = [i for i in queue if not store.is_done(i)]
            if queue:  # held by other processes: wait for them to finish, or to die and free them
                bar.set_postfix_str(f"{len(queue)} chunks computed elsewhere", refresh=True)
                time.sleep(POLL_SECONDS)
    finally:
        if pending is not None:
            pending[2].release()
        bar.close()
    if n_proc > 1:
        _end_with_lost_peers(me, n_proc, taken)
    return store.dataset()


def _end_with_lost_peers(me: int, n_proc: int, taken: dict[int, str]) -> None:
    """Under `jax.distributed`, once the store is complete: if this process took over chunks from
    holders that stopped, say which (and which processes the coordination service counts lost:
    not alone, since a peer that finished and left is not alive either)."""
    if taken:
        print(_peers.report_takeover(me, n_proc, taken, _peers.lost_peers(n_proc, me)), file=sys.stderr, flush=True)
    if me == 0:
        _peers.wait_for_peers_to_leave(n_proc)


def _barrier(name: str) -> None:
    from jax.experimental import multihost_utils

    multihost_utils.sync_global_devices(name)
