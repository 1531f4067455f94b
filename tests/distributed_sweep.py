"""One process of a multi-process sweep, for tests/test_distributed.py (and by hand).

    python tests/distributed_sweep.py STORE --process-id I --processes P --port PORT [--die-after N] [--chain]

Starts `jax.distributed` with its coordinator on 127.0.0.1:PORT (process 0 hosts
it; with `--processes 1` nothing is started), one CPU device per process, float64,
and runs `lj.sweep(AXES, path=STORE, ...)`. It prints one JSON line: the chunks this
process computed and found done. With `--die-after N` the process kills itself
(SIGKILL) while writing its chunk N + 1: half of a chunk on disk, its lock held,
no completion mark, as a crash or `scancel` leaves them. With `--chain` the sweep is a map of
`worm`, a 3-mass chain on anisotropic bristles, `lj.sweep(CHAIN_AXES, mechanism=worm, ...)`.
"""

import argparse
import json
import os
import signal
import sys
from pathlib import Path
from typing import Any

import numpy as np


AXES = {"omega": np.linspace(1.0, 24.0, 8), "a": np.linspace(0.02, 0.1, 4)}
"""The test sweep: 32 configurations, in chunks of 4 (8 chunks)."""

SETTINGS: dict[str, Any] = dict(horizon=30.0, window=25.0, chunk_size=4, progress=False)

CHAIN_AXES = {"omega": np.linspace(2.0, 6.0, 4), "a": np.array([0.05, 0.1])}
"""The chain's test sweep: 8 configurations, in chunks of 2 (4 chunks)."""

CHAIN_SETTINGS: dict[str, Any] = dict(z=1e9, horizon=20.0, window=10.0, t_start=10.0, chunk_size=2, progress=False)


def worm(omega, a):
    """The 3-mass worm on anisotropic bristles, one per swept (omega, a)."""
    import locomotion_jax as lj

    wave = lj.TravellingWave(np.asarray(a), np.asarray(omega), 2 * np.pi / 3)
    return lj.Chain(masses=np.ones(3), d=0.0, friction=lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7), waveforms=wave,
                    check=False)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("store")
    parser.add_argument("--process-id", type=int, default=0)
    parser.add_argument("--processes", type=int, default=1)
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--die-after", type=int, default=None)
    parser.add_argument("--chain", action="store_true")
    args = parser.parse_args()
    # Before JAX starts: one CPU device per process (two processes share the 2-core CI machine).
    os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=1"
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import jax

    jax.config.update("jax_enable_x64", True)
    if args.processes > 1:
        # A lost process must not take the others with it (the CLI's --distributed does the same).
        jax.config.update("jax_enable_recoverability", True)
        jax.distributed.initialize(
            f"127.0.0.1:{args.port}",
            num_processes=args.processes,
            process_id=args.process_id,
            initialization_timeout=120,
            heartbeat_timeout_seconds=10,
            shutdown_timeout_seconds=30,
        )
    import locomotion_jax as lj
    from locomotion_jax.maps import _sweep, _zarr_store

    cache = os.environ.get("DISTRIBUTED_SWEEP_CACHE")
    if cache:  # the test's processes share their compilations
        lj.enable_compilation_cache(cache)
    if args.die_after is not None:
        write, written = _zarr_store.ZarrStore.write, []

        def write_then_die(self, index, results):
            if len(written) == args.die_after:
                name = next(iter(results))
                region = self.blocks.region(index)
                shape = tuple(r.stop - r.start for r in region)
                self.group[name][region] = np.asarray(results[name]).reshape(shape)
                os.kill(os.getpid(), signal.SIGKILL)
            written.append(index)
            write(self, index, results)

        _zarr_store.ZarrStore.write = write_then_die
    if args.chain:
        lj.sweep(CHAIN_AXES, mechanism=worm, path=args.store, **CHAIN_SETTINGS)
    else:
        lj.sweep(AXES, path=args.store, **SETTINGS)
    stats = {k: _sweep.STATS[k] for k in ("chunks_computed", "chunks_loaded")}
    print(json.dumps({"process": jax.process_index(), "processes": jax.process_count(), **stats}), flush=True)


if __name__ == "__main__":
    main()
