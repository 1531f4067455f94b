"""`sweep`: parameter maps of `measure` at scale, chunked, sharded, resumable.

The grid is flattened and cut into chunks of equal (padded) size, so one
compilation serves every chunk and memory is bounded by the chunk size, not the
grid. Each chunk is split over all devices (`_sharding`), written to disk as soon
as it is done (`_store`), and counted on a progress bar from the host.

With `order="cost"` the configurations are first sorted by expected cost (a short
pilot run of each, `_schedule`), so each chunk, and each device's share of it,
holds configurations of similar duration: a loop runs until its slowest
configuration is done, and one reaching $z$ late does not keep a chunk of fast
ones busy. The results are put back in grid order, identical to a natural-order
sweep; the permutation is stored with the chunks, so a resumed sweep cuts the
same chunks.

Under `jax.distributed`, with a Zarr store (`path="....zarr"`, `_zarr_sweep`), the
processes share out the chunks: each computes whole chunks on its own devices and
writes them into the store (tested with two processes on one host). With NetCDF
output or none, every process runs the same chunks (process 0's view of the
finished ones is broadcast), each supplies and computes its own devices' shards
of each chunk, and process 0 alone writes. Either way `path` must be on a file
system all processes see.
"""

import functools
import os
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike, Contact, Start
from ..dynamics._base import AbstractDynamics
from ..dynamics._exact_dynamics import Exact
from ..dynamics._runs import horizon_bound
from ..model import _two_mass as model
from ..model._params import DEFAULTS, Params
from ..run._batch import check_hop_dynamics, dynamics_arg
from ..run._measure import check_measure_args
from . import _sharding as sharding
from ._dataset import dataset_fields, MEASURE_FIELDS as MEASURE_FIELDS, sweep_attrs, to_dataset  # re-exported
from ._grid import check_valid, Grid, RATIO
from ._store import ChunkOrder, ChunkStore, read_finished


if TYPE_CHECKING:
    from ..model._bodies import Mechanism
    from ..model._chain import Chain
from ._zarr_store import is_zarr


STATS: Counter = Counter()
"""Host-side counters: `"chunks_computed"` (chunks sent to the devices),
`"chunks_loaded"` (chunks read back from a partial store, or found done in a Zarr store) and `"pilots"` (pilot
runs for `order="cost"`). Used by the tests."""

ORDERS: tuple[str, ...] = ("auto", "natural", "cost")
"""Values of `sweep(order=...)`: see [`resolve_order`][]."""

AUTO_MIN_CONFIGS = 4096
"""Smallest sweep that `order="auto"` sorts by cost. The pilot costs one compilation
(3 s on this 2-core CPU) plus ~0.3 ms per configuration on one core. Measured
(benchmarks/NOTES.md, 2 devices, dt = 0.02): a 64 x 64 omega x a map, lane efficiency
0.37 -> 0.93 and 21 -> 11 s, pilot run included; the 512-point Fig. 8 line, already
well grouped in natural order, 0.73 -> 0.785 and no time saved."""


def _float_dtype(dtype: Any) -> np.dtype:
    dt = np.dtype(jnp.result_type(float) if dtype is None else dtype)
    if not np.issubdtype(dt, np.floating):
        raise ValueError(f"dtype must be a floating dtype, got {dt}.")
    if dt == np.float64 and not jax.config.read("jax_enable_x64"):
        raise ValueError(
            "dtype=float64 requested but JAX runs in 32-bit mode; enable it with "
            'jax.config.update("jax_enable_x64", True) at start-up (or the CLI flag --x64).'
        )
    return dt


def _max_steps(grid: Grid, dynamics: AbstractDynamics, horizon: float) -> int:
    """The step cap of the sweep's longest run, from its largest t_start, recorded with the results (`Exact`
    caps each configuration by its own span, or by its `max_steps`)."""
    # t_start depends on k and mhat only (eqs. 11-12): bound it over their combinations.
    k = grid.values.get("k", np.asarray([grid.fixed.get("k", DEFAULTS["k"])]))
    mh = grid.values.get("mhat", np.asarray([grid.fixed.get("mhat", DEFAULTS["mhat"])]))
    if grid.mode == "grid":
        k, mh = (x.ravel() for x in np.meshgrid(k, mh, indexing="ij"))
    return dynamics.step_cap(horizon_bound(Params(k=k, mhat=mh, check=False), horizon))


def resolve_order(
    order: str, dynamics: AbstractDynamics, horizon: float, window: float, n_configs: int, loops_per_device: int
) -> ChunkOrder:
    """The order a sweep's chunks are cut in: `"natural"` (grid order) or `"cost"`.

    `"auto"` picks `"cost"` where sorting can pay for its pilot run: dynamics whose
    iterations follow from a step (`AbstractDynamics.nominal_step`; the exact engine,
    whose cost the pilot models), durations that can differ (`horizon >
    window`: the run ends at $\\tau_z$ somewhere in between), several loops in
    sequence on each device (chunks, or sub-batches of `_sharding.MICRO_BATCH`:
    with a single loop per device the slowest configuration sets the time in any
    order), and at least [`AUTO_MIN_CONFIGS`][] configurations.

    **Raises:** `ValueError` for an unknown `order`.
    """
    if order not in ORDERS:
        raise ValueError(f"order must be one of {', '.join(map(repr, ORDERS))}, got {order!r}.")
    if order == "natural" or order == "cost":
        return order
    stepped = dynamics.nominal_step() is not None
    pays = stepped and horizon > window and loops_per_device > 1 and n_configs >= AUTO_MIN_CONFIGS
    return "cost" if pays else "natural"


def _loops_per_device(n_chunks: int, shard: int, micro_batch: int | None) -> int:
    """Integration loops each device runs one after another: chunks x sub-batches of its shard."""
    return n_chunks * (-(-shard // micro_batch) if micro_batch else 1)


def _cost_permutation(
    grid: Grid,
    z: float,
    horizon: float,
    window: float,
    dynamics: AbstractDynamics,
    contact: str,
    start: str,
    dtype: np.dtype,
) -> np.ndarray:
    """The flat configuration numbers by increasing expected cost (`_schedule.cost_order`, a pilot run)."""
    from ._schedule import cost_order

    STATS["pilots"] += 1
    # The pilot runs the exact engine; for adaptive dynamics only the durations it predicts matter.
    step = dynamics.nominal_step()
    dt = Exact().dt if step is None else step
    return cost_order(
        grid.config_values(np.arange(grid.size)),
        z=z,
        horizon=horizon,
        window=window,
        dt=dt,
        contact=contact,
        start=start,
        dtype=dtype,
    )


def _in_grid_order(run: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Results listed in the order they were run (`perm[j]` is the j-th configuration run) -> grid order."""
    out = np.empty_like(run)
    out[perm] = run
    return out


def sweep(
    axes: Mapping[str, ArrayLike | Sequence[float]],
    *,
    fixed: Mapping[str, float | int] | None = None,
    mode: Literal["grid", "list"] = "grid",
    z: float = 5.0,
    horizon: float = 2000.0,
    window: float = 25.0,
    dynamics: AbstractDynamics | None = None,
    contact: Contact = "strict",
    start: Start = "paper",
    dtype: Any = None,
    chunk_size: int = 4096,
    path: str | os.PathLike | None = None,
    overwrite: bool = False,
    progress: bool = True,
    on_invalid: Literal["raise", "flag"] = "raise",
    order: Literal["auto", "natural", "cost"] = "auto",
    mechanism: "Callable[..., Chain | Mechanism] | None" = None,
    t_start: float | None = None,
):
    """Evaluate [`measure`][] over a grid (or list) of parameters, in chunks, on all devices.

    The configurations are flattened (C order; sorted by expected cost with
    `order="cost"`) and cut into chunks of `chunk_size`, padded so every chunk has
    the same shape (each device's share a whole number of SIMD vectors, so a
    configuration's result does not depend on its place in the chunk): one
    compilation serves the whole sweep and memory is bounded by the chunk size. Each chunk is
    split over all devices JAX sees (a 1-D mesh; `shard_map`, so each device's
    integration loop ends on its own), and the same code runs on several GPUs
    or hosts. Progress (configurations/s) is reported from the host once per chunk.

    With `path`, each finished chunk is written at once to `path + ".parts/"`
    (one `.npz` per chunk and a `manifest.json` with the full specification), and
    the final dataset to `path` as NetCDF. A rerun with the same specification
    resumes from the finished chunks, or reads a finished sweep back without
    computing; a different specification at the same path is an error unless
    `overwrite=True`.

    A `path` ending in `.zarr` is a Zarr (v3) store instead (`_zarr_store`): every
    array is created whole at the start and each chunk, a block of the grid, is
    written into its region as it is done, so memory stays bounded by the chunk
    whatever the size of the map. Several processes can fill one store at once:
    under `jax.distributed` (or simply started on the same store) each process
    computes whole chunks on its own devices, taking them in turn through a lock
    per chunk, and returns when the store is complete (`_zarr_sweep`). The result is
    the store opened lazily (`xarray.open_zarr`); chunks are cut in grid order.

    **Arguments:**

    - `axes`: parameter name -> 1-D values (names of `PARAM_NAMES`, or
      `"omega_over_wn1"` for $\\omega/\\omega_{n1}$, eq. 11). Scalars count as fixed.
    - `fixed`: scalar values of other parameters; the rest take `DEFAULTS`.
    - `mode`: `"grid"` (outer product, one dimension per axis, in the order given)
      or `"list"` (axes of equal length zipped along one dimension `config`).
    - `z`, `horizon`, `window`, `dynamics`, `contact`, `start`, `dtype`: as in [`measure`][]
      (`dtype` defaults to JAX's default float).
    - `chunk_size`: configurations per chunk (rounded up to a multiple of the device count).
    - `path`: NetCDF file (resumable through its parts directory) or Zarr store
      (`.zarr`) for the result; `None` keeps it in memory.
    - `overwrite`: discard whatever is stored at `path` (finished or partial) and recompute.
    - `progress`: show a tqdm progress bar.
    - `on_invalid`: `"raise"` (default) rejects invalid configurations before any
      computation; `"flag"` runs them as `Status.INVALID` (e.g. a `mu_s` x `mu_k` map).
    - `order`: `"natural"` cuts the chunks in grid order; `"cost"` first sorts the
      configurations by expected cost (a pilot run of each, `_schedule.cost_order`),
      so that a chunk's loops do not wait for one slow configuration; `"auto"`
      (default) chooses `"cost"` where sorting pays for its pilot run (`_sweep.resolve_order`:
      large exact sweeps whose runs end at $\\tau_z$). The results are identical; a
      resumed sweep keeps the order it was started in. Recorded in the attribute `order`.
      A Zarr store is always cut in grid order (`"cost"` is refused there).
    - `mechanism`: a map over chains of N masses (or mechanisms, SPEC §9) instead of the paper's model: a
      function from the swept values (keyword arguments named as the axes, plus
      `fixed`, each a 1-D array with one entry per configuration) to a batched
      [`Chain`][] or [`Mechanism`][locomotion_jax.Mechanism] of that batch shape (build it with `check=False` and let
      `on_invalid` decide). The axes' names are then free. The map runs as the paper's
      model's does (chunks split over the devices, `order`, NetCDF resumable through its parts,
      Zarr from several processes), each chunk on the dynamics' N-body engine
      (`AbstractDynamics.measure_chunk`); the cost order's pilot runs the built mechanisms. The
      specification records a digest of the mechanisms built at the first and the last
      configurations, so a rerun with another builder is refused.
    - `t_start`: an explicit measurement start for every configuration (chains only;
      default `Chain.t_start`).

    **Returns:** an `xarray.Dataset` (read lazily from a Zarr store): one dimension and coordinate per swept axis, one
    variable per [`Measurement`][] field (plus `omega` when `omega_over_wn1` is swept; under `contact="hop"`
    the hopping fields `flight_fraction1`, `flight_fraction2`, `highest_hop1`, `highest_hop2`,
    `landings_per_period` and `zeno`, `_dataset.HOP_FIELDS`),
    and attributes recording the fixed parameters, dynamics, dtype, contact, start,
    z, horizon, window, order, step cap, package version and the specification (`sweep_spec`, JSON).

    **Raises:** `ValueError`, before any computation, for an unknown parameter, an
    empty or non-1-D axis, an invalid configuration (naming the parameter, its valid
    range and the grid index), bad settings, or an output path that cannot be written
    or holds a different sweep. `TypeError` for a `dynamics` that is not an [`AbstractDynamics`][].

    !!! Example

        ```python
        ds = sweep({"omega": np.linspace(1, 25, 256), "a": np.linspace(0.01, 0.1, 256)},
                   z=5.0, path="maps/ssl.nc")
        (ds.regime == Regime.SSL).plot()
        ```
    """
    dynamics = dynamics_arg(dynamics)
    if mechanism is not None:
        return _sweep_mechanism(mechanism, axes, fixed, mode, z, horizon, window, t_start, dynamics, contact, start,
                                dtype, chunk_size, path, overwrite, progress, on_invalid, order)  # fmt: skip
    if t_start is not None:
        raise ValueError("t_start is for chain maps (mechanism=...); the paper's model starts at Params.t_start.")
    model.check_contact(contact, hop=True)
    check_hop_dynamics(contact, dynamics)  # "hop" runs on the exact engine only
    model.initial_gap(Params(), start)  # validates `start`
    check_measure_args(z, horizon, window)
    if on_invalid not in ("raise", "flag"):
        raise ValueError(f"on_invalid must be 'raise' or 'flag', got {on_invalid!r}.")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}.")
    dt = _float_dtype(dtype)
    grid = Grid(axes, fixed, mode)
    if on_invalid == "raise":
        check_valid(grid)
    desc = dynamics.spec()
    spec = {
        "spec_version": 1,
        **grid.spec(),
        "z": float(z),
        "horizon": float(horizon),
        "window": float(window),
        "dynamics": desc,
        "contact": contact,
        "start": start,
        "dtype": dt.name,
        "on_invalid": on_invalid,
    }

    if path is not None and is_zarr(path):
        if order not in ORDERS:
            resolve_order(order, dynamics, horizon, window, grid.size, 1)  # raises
        if order == "cost":
            raise ValueError(
                "order='cost' is for NetCDF output or path=None: a Zarr store's chunks are blocks of the grid, "
                "computed in grid order. Use order='natural' or 'auto'."
            )
        from ._zarr_sweep import sweep_to_zarr

        return sweep_to_zarr(
            grid,
            spec,
            Path(path).expanduser(),
            int(chunk_size),
            z=z,
            horizon=horizon,
            window=window,
            dynamics=dynamics,
            contact=contact,
            start=start,
            dtype=dt,
            max_steps=_max_steps(grid, dynamics, horizon),
            overwrite=overwrite,
            progress=progress,
        )

    mesh = sharding.batch_mesh()
    ndev = sharding.device_count(mesh)
    chunk = -(-min(int(chunk_size), grid.size) // ndev) * ndev
    loops = _loops_per_device(
        -(-grid.size // chunk), sharding.padded_size(chunk, ndev, dt) // ndev, sharding.MICRO_BATCH
    )
    order = resolve_order(order, dynamics, horizon, window, grid.size, loops)
    permutation = None
    if order == "cost":  # called only when needed: not for a finished or resumed sweep
        permutation = functools.partial(_cost_permutation, grid, z, horizon, window, dynamics, contact, start, dt)
    finished, store, chunk, order, perm = plan_chunks(path, spec, chunk, grid.size, overwrite, order, permutation)
    if finished is not None:
        return finished
    padded = sharding.padded_size(chunk, ndev, dt)
    max_steps = _max_steps(grid, dynamics, horizon)

    def dispatch(i: int) -> dict[str, jax.Array]:
        flat = np.arange(i * chunk, i * chunk + padded)
        vals = grid.config_values(perm[np.minimum(flat, grid.size - 1)])
        pad = flat >= min((i + 1) * chunk, grid.size)
        # NaN padding is invalid: flagged, skipped by the integrator, and dropped.
        vals = {n: np.where(pad, np.nan, v) for n, v in vals.items()}
        return sharding.dispatch_chunk(vals, dt, z, horizon, window, dynamics, contact, start, mesh)

    results = run_chunks(grid.size, chunk, perm, store, dispatch, progress)
    flat_res = {k: results[k] for k in dataset_fields(contact)}
    if RATIO in grid.values or RATIO in grid.fixed:
        flat_res["omega"] = grid.config_values(np.arange(grid.size))["omega"]
    ds = to_dataset(grid, flat_res, sweep_attrs(grid, spec, dynamics, max_steps, ndev, order))
    if store is not None:
        store.finalize(ds)
    return ds


def plan_chunks(path: str | os.PathLike | None, spec: dict[str, Any], chunk: int, size: int, overwrite: bool,
                order: ChunkOrder, permutation: Callable[[], np.ndarray] | None) -> tuple:  # fmt: skip
    """`(finished, store, chunk, order, perm)` of a sweep into NetCDF (`path`) or memory (`None`):
    the finished dataset at `path` if it holds this sweep (`spec`), else the store of its parts
    (`_store.ChunkStore`, `None` in memory), the chunk size and order it runs with (a resumed sweep
    keeps those it was started with) and the permutation of the configurations it runs in
    (`permutation()`, called only for a new sweep; `None`: grid order). Any mechanism's map plans
    its chunks this way."""
    store = None
    if path is not None:
        path = Path(path).expanduser()
        finished = read_finished(path, spec, overwrite)
        if finished is not None:
            return finished, None, chunk, order, None
        store = ChunkStore(
            path,
            spec,
            chunk,
            size,
            overwrite,
            write=jax.process_index() == 0,
            order=order,
            permutation=permutation,
        )
        # A resumed sweep keeps its chunking and its order.
        chunk, order, perm = store.chunk_size, store.order, store.permutation
    else:
        perm = None if permutation is None else permutation()
    # perm[j] is the j-th configuration run; all processes must cut the same chunks.
    perm = np.arange(size) if perm is None else sharding.from_process0(perm)
    return None, store, chunk, order, perm


def run_chunks(size: int, chunk: int, perm: np.ndarray, store: ChunkStore | None,
               dispatch: Callable[[int], dict[str, jax.Array]], progress: bool) -> dict[str, np.ndarray]:  # fmt: skip
    """Every chunk of a sweep of `size` configurations cut `chunk` at a time in the order `perm`
    (`perm[j]` is the j-th configuration run), computed by `dispatch(i)` (chunk `i`'s device outputs,
    asynchronously; read by `_sharding.fetch`) unless `store` holds it, each saved to `store` the
    moment it is done. Any mechanism's map runs this loop (NetCDF or in memory; a Zarr store has its
    own, `_zarr_sweep.fill_store`).

    **Returns:** each output as one host array over the configurations, in grid order.
    """
    from tqdm.auto import tqdm

    n_chunks = -(-size // chunk)
    done = sharding.agree(store.completed() if store is not None else set(), n_chunks)
    results: dict[int, dict[str, np.ndarray]] = {}
    todo = [i for i in range(n_chunks) if i not in done]
    bar = tqdm(
        total=size,
        initial=sum(min(chunk, size - i * chunk) for i in done),
        unit="config",
        unit_scale=True,
        desc="sweep",
        disable=not progress or jax.process_index() != 0,
        smoothing=0.1,
    )

    def finish(i: int, out: dict) -> None:
        n = min(chunk, size - i * chunk)
        results[i] = sharding.fetch(out, n)
        if store is not None:
            store.save(i, results[i])  # written the moment it exists: an interruption loses nothing
        bar.update(n)
        bar.set_postfix_str("")

    if todo:  # the bar shows from the first second; the first chunk's count comes after its compilation
        bar.set_postfix_str("compiling (first call only)...")
    try:
        pending = None
        for i in todo:
            out = dispatch(i)
            STATS["chunks_computed"] += 1
            # Dispatch is asynchronous: the devices work on chunk i while the
            # host saves chunk i - 1.
            if pending is not None:
                finish(*pending)
            pending = (i, out)
        if pending is not None:
            finish(*pending)
    finally:
        bar.close()

    for i in sorted(done):  # `done` is empty without a store
        assert store is not None
        results[i] = store.load(i)
        STATS["chunks_loaded"] += 1
    return {k: _in_grid_order(np.concatenate([results[i][k] for i in range(n_chunks)]), perm) for k in results[0]}


def _sweep_mechanism(mechanism: "Callable[..., Chain | Mechanism]", axes, fixed, mode, z, horizon, window, t_start,
                     dynamics, contact, start, dtype, chunk_size, path, overwrite, progress, on_invalid,
                     order):  # fmt: skip
    """`sweep` over chains built by `mechanism` (see `maps._builder_sweep`)."""
    from ._builder_sweep import sweep_chain

    if not callable(mechanism):
        raise TypeError(
            f"mechanism must be a function of the swept values returning a Chain or a Mechanism, got {mechanism!r}."
        )
    if order not in ORDERS:
        raise ValueError(f"order must be one of {', '.join(map(repr, ORDERS))}, got {order!r}.")
    if on_invalid not in ("raise", "flag"):
        raise ValueError(f"on_invalid must be 'raise' or 'flag', got {on_invalid!r}.")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}.")
    check_measure_args(z, horizon, window)
    return sweep_chain(
        mechanism, axes, fixed=fixed, mode=mode, z=z, horizon=horizon, window=window, t_start=t_start,
        dynamics=dynamics, contact=contact, start=start, dtype=dtype,
        chunk_size=int(chunk_size), path=path, progress=progress, on_invalid=on_invalid, overwrite=overwrite,
        order=order,
    )  # fmt: skip
