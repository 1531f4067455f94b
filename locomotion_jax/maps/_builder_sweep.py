"""Maps over chains of N masses and mechanisms: [`sweep`][locomotion_jax.sweep] with a `mechanism` builder.

A chain has no fixed list of parameter names (its fields are per mass and per spring,
its waveform and friction law are classes), so the sweep asks the user for a builder:
a function from the swept values (1-D arrays, one entry per configuration) to a
batched [`Chain`][] or [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9). The map then runs as a
map of the paper's model does, on the same loops (`_sweep.run_chunks`, `_zarr_sweep.fill_store`):
chunks of one shape (the padding run as invalid configurations, which cost no steps), so one
compilation serves the map; each chunk split over every device JAX sees
(`_sharding.dispatch_mechanism_chunk`); optionally sorted by a pilot run's expected cost
(`_schedule.mechanism_cost_order`); kept in memory, written to NetCDF through a parts directory
(resumable), or into a Zarr store chunk by chunk ([`_to_zarr`][]: blocks of the grid, resumable,
shared by processes)."""

import hashlib
import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._results import MEASUREMENT_KEYS
from ..dynamics._exact_dynamics import Exact
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ._schedule import mechanism_cost_order
from ._zarr_store import is_zarr


def _axes(axes: Mapping[str, Any], mode: str) -> tuple[dict[str, np.ndarray], tuple[int, ...]]:
    if mode not in ("grid", "list"):
        raise ValueError(f"mode must be 'grid' (outer product) or 'list' (zipped axes), got {mode!r}.")
    if not isinstance(axes, Mapping) or not axes:
        raise ValueError("axes must be a non-empty mapping of name -> 1-D array of values.")
    values = {}
    for name, v in axes.items():
        arr = np.asarray(v, dtype=np.float64)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"Axis {name!r} must be a non-empty 1-D array, got shape {arr.shape}.")
        values[name] = arr
    lengths = [v.size for v in values.values()]
    if mode == "list" and len(set(lengths)) > 1:
        raise ValueError(f"mode='list' needs axes of equal length, got {dict(zip(values, lengths))}.")
    return values, (tuple(lengths) if mode == "grid" else (lengths[0],))


def _build(build: Callable[..., Any], values, shape, mode, fixed, flat: np.ndarray) -> "Chain | Mechanism":
    idx = np.unravel_index(flat, shape) if mode == "grid" else (flat,) * len(values)
    kwargs = {n: v[i] for (n, v), i in zip(values.items(), idx)}
    chain = build(**kwargs, **fixed)
    if not isinstance(chain, (Chain, Mechanism)):
        raise TypeError(f"mechanism must return a Chain or a Mechanism, got {type(chain).__name__}.")
    if chain.batch_shape != flat.shape:
        raise ValueError(
            f"mechanism must return a {type(chain).__name__} of batch shape {flat.shape} (one configuration per "
            f"value of the swept axes), got {chain.batch_shape}; build it from the arrays it is given."
        )
    return chain


def sweep_chain(
    build: "Callable[..., Chain | Mechanism]",
    axes: Mapping[str, Any],
    *,
    fixed: Mapping[str, Any] | None,
    mode: str,
    z: float,
    horizon: float,
    window: float,
    t_start: float | None,
    dynamics: Any,
    contact: str,
    start: str,
    dtype: Any,
    chunk_size: int,
    path: str | Path | None,
    progress: bool,
    on_invalid: str,
    overwrite: bool = False,
    order: str = "auto",
):
    """The chain sweep behind `sweep(axes, mechanism=build)`; arguments as there.

    Returns an `xarray.Dataset` with one dimension per axis (`"config"` for a list),
    one variable per [`Measurement`][] field (`stick_fraction` with a trailing
    `mass` dimension), the axes as coordinates and the settings as attributes; for a
    Zarr `path`, the store, filled chunk by chunk ([`_to_zarr`][]) and read lazily.
    """
    import xarray as xr

    from . import _sharding as sharding
    from ._sweep import _loops_per_device, plan_chunks, resolve_order, run_chunks, STATS

    values, shape = _axes(axes, mode)
    fixed = dict(fixed or {})
    if path is not None:
        path = Path(path).expanduser()
        if not is_zarr(path) and path.suffix != ".nc":
            raise ValueError(
                f"path for a chain sweep must be a NetCDF file (.nc), resumable through its parts directory, or a "
                f"Zarr store (.zarr), written chunk by chunk; got {str(path)!r}."
            )
    size = math.prod(shape)
    at = lambda flat: _build(build, values, shape, mode, fixed, flat)  # the mechanisms of flat grid indices

    if on_invalid == "raise":  # before any computation: every configuration is checked
        check = min(int(chunk_size), size)
        for lo in range(0, size, check):
            chain = at(np.minimum(np.arange(lo, lo + check), size - 1))
            bad = np.flatnonzero(~np.asarray(chain.is_valid())[: size - lo])
            if bad.size:
                j = int(bad[0])
                where = np.unravel_index(lo + j, shape) if mode == "grid" else (lo + j,)
                named = ", ".join(f"{name}={float(values[name][k])!r}" for name, k in zip(values, where))
                try:
                    chain[j].validate()
                except ValueError as e:
                    index = tuple(map(int, where))
                    raise ValueError(f"Invalid configuration at grid index {index} ({named}): {e}") from None

    first = at(np.zeros((1,), int))
    dt = np.dtype(first.astype(dtype).dtype if dtype is not None else first.dtype)
    attrs = _attrs(first, values, mode, fixed, dtype, z, horizon, window, t_start, dynamics, contact, start, on_invalid)
    spec = {
        "spec_version": 1,
        "sweep": "mechanism",
        "axes": {n: v.tolist() for n, v in values.items()},
        "mode": mode,
        "fixed": {k: _plain(v) for k, v in fixed.items()},
        "mechanism": _digest(build, values, shape, mode, fixed, first),
        **{k: attrs[k] for k in ("dtype", "contact", "start", "z", "horizon", "window", "on_invalid")},
        "t_start": None if t_start is None else float(t_start),
        "dynamics": dynamics.spec(),
    }
    settings = (dt, z, horizon, window, t_start, dynamics, contact, start)
    if path is not None and is_zarr(path):
        if order == "cost":
            raise ValueError(
                "order='cost' is for NetCDF output or path=None: a Zarr store's chunks are blocks of the grid, "
                "computed in grid order. Use order='natural' or 'auto'."
            )
        mesh = sharding.batch_mesh(local=True)  # each process computes whole chunks on its own devices
        ndev = sharding.device_count(mesh)

        def run_block(flat: np.ndarray) -> dict[str, Any]:
            n = sharding.padded_size(flat.size, ndev, dt)
            live = np.arange(n) < flat.size
            return sharding.dispatch_mechanism_chunk(at(flat[np.minimum(np.arange(n), flat.size - 1)]), live,
                                                     *settings, mesh)  # fmt: skip

        return _to_zarr(path, spec, attrs, values, shape, mode, chunk_size, overwrite, progress, run_block)

    mesh = sharding.batch_mesh()
    ndev = sharding.device_count(mesh)
    chunk = -(-min(int(chunk_size), size) // ndev) * ndev
    padded = sharding.padded_size(chunk, ndev, dt)
    loops = _loops_per_device(-(-size // chunk), padded // ndev, sharding.MICRO_BATCH)
    order = resolve_order(order, dynamics, horizon, window, size, loops)
    step = dynamics.nominal_step()

    def cost_order() -> np.ndarray:  # called only for a new sweep
        STATS["pilots"] += 1
        return mechanism_cost_order(at, size, chunk, t_start=t_start, z=z, horizon=horizon, window=window,
                                    dt=Exact().dt if step is None else step, contact=contact, start=start,
                                    dtype=dtype)  # fmt: skip

    permutation = cost_order if order == "cost" else None

    finished, store, chunk, order, perm = plan_chunks(path, spec, chunk, size, overwrite, order, permutation)
    if finished is not None:
        return finished

    def dispatch(i: int) -> dict[str, Any]:
        flat = np.arange(i * chunk, i * chunk + padded)
        live = flat < min((i + 1) * chunk, size)  # the rest: padding, run as invalid and dropped
        return sharding.dispatch_mechanism_chunk(at(perm[np.minimum(flat, size - 1)]), live, *settings, mesh)

    flat = _measured(run_chunks(size, chunk, perm, store, dispatch, progress))
    dims = tuple(values) if mode == "grid" else ("config",)
    coords = {n: (n if mode == "grid" else "config", v) for n, v in values.items()}
    data = {}
    for name, arr in flat.items():
        extra = arr.shape[1:]
        data[name] = (dims + ("mass",) * len(extra), arr.reshape(shape + extra))
    ds = xr.Dataset(data, coords=coords, attrs=attrs | {"order": order, "n_devices": ndev,
                                                         "sweep_spec": json.dumps(spec)})  # fmt: skip
    if store is not None:
        store.finalize(ds)
    return ds


def _measured(out: dict[str, Any]) -> dict[str, np.ndarray]:
    """A chunk's outputs (or a map's) as `Measurement.to_numpy` names and orders them."""
    return {k: np.asarray(out[k]) for k in MEASUREMENT_KEYS if k in out}


def _attrs(first: "Chain | Mechanism", values: dict[str, np.ndarray], mode: str, fixed: dict[str, Any], dtype: Any,
           z: float, horizon: float, window: float, t_start: float | None, dynamics: Any, contact: str, start: str,
           on_invalid: str) -> dict[str, Any]:  # fmt: skip
    """The dataset's attributes: the sweep's settings and the mechanism's kind and laws (`first`, the
    mechanism of the first configuration)."""
    import jax

    from .. import __version__
    from .._status import Regime, Status

    return {
        "title": "locomotion_jax chain sweep",
        "sweep_mode": mode,
        "swept": ",".join(values),
        "n_masses": first.n_masses,
        **first.attributes(),
        **{f"fixed_{k}": v for k, v in fixed.items() if np.ndim(v) == 0 and isinstance(v, (int, float))},
        "dtype": str(np.dtype(first.astype(dtype).dtype if dtype is not None else first.dtype)),
        "contact": contact,
        "start": start,
        "z": float(z),
        "horizon": float(horizon),
        "window": float(window),
        "t_start": "Chain.t_start (80 periods of the lowest nonzero natural frequency)" if t_start is None else t_start,
        **{f"dynamics_{k}" if k != "dynamics" else k: v for k, v in dynamics.describe().items()},
        "on_invalid": on_invalid,
        "version": __version__,
        "jax_version": jax.__version__,
        "status_codes": ", ".join(f"{int(s)}={s.name}" for s in Status),
        "regime_codes": ", ".join(f"{int(r)}={r.name}" for r in Regime),
    }


def _plain(value: Any) -> Any:
    """A fixed argument of the builder as the store's specification records it: numbers as lists,
    anything else by its type."""
    try:
        return np.asarray(value, np.float64).tolist()
    except (TypeError, ValueError):
        return type(value).__name__


def _digest(build: Callable[..., Any], values: dict[str, np.ndarray], shape: tuple[int, ...], mode: str,
            fixed: dict[str, Any], first: "Chain | Mechanism") -> dict[str, Any]:  # fmt: skip
    """What identifies the builder in a store's specification: the class, kind and laws of the
    mechanisms it builds at the first configuration (`first`) and the last, and the SHA-256 of their
    leaves (dtypes, shapes and values), so that a store is resumed only by a builder that gives the
    same mechanisms there."""
    import jax

    digest = hashlib.sha256()
    last = _build(build, values, shape, mode, fixed, np.array([math.prod(shape) - 1]))
    for m in (first, last):
        digest.update(type(m).__name__.encode())
        for leaf in jax.tree_util.tree_leaves(m):
            a = np.asarray(leaf)
            digest.update(f"{a.dtype}{a.shape}".encode() + a.tobytes())
    return {"class": type(first).__name__, **first.attributes(), "sha256": digest.hexdigest()}


def _to_zarr(path: Path, spec: dict[str, Any], attrs: dict[str, Any], values: dict[str, np.ndarray],
             shape: tuple[int, ...], mode: str, chunk: int, overwrite: bool, progress: bool,
             run_block: Callable[[np.ndarray], dict[str, Any]]):  # fmt: skip
    """The map into a Zarr store (`_zarr_sweep.fill_store`: resumable, several processes at once):
    each chunk a block of the grid, its configurations (the flat grid indices `blocks.configs`)
    started by `run_block(indices)` (`_sharding.dispatch_mechanism_chunk`'s outputs; every block
    padded to one size: one compiled program); the store's arrays and their dtypes are those of the
    first chunk's results."""
    from . import _sharding as sharding
    from ._dataset import DESCRIPTIONS
    from ._zarr_store import block_shape, Blocks, ZarrStore
    from ._zarr_sweep import fill_store

    size = math.prod(shape)
    ran: dict[int, dict[str, np.ndarray]] = {}  # the first chunk, run to learn the arrays, is not run again

    def compute(blocks: Blocks, index: int) -> Callable[[int], dict[str, np.ndarray]]:
        """Chunk `index` started; its results (`n` configurations) when called."""
        if index in ran:
            arrays = ran.pop(index)
            return lambda n: {k: v[:n] for k, v in arrays.items()}
        flat = blocks.configs(index)
        out = run_block(np.concatenate([flat, np.repeat(flat[-1:], blocks.max_size - flat.size)]))
        return lambda n: _measured(sharding.fetch(out, n))

    def collect(blocks: Blocks, index: int, results: Callable[[int], dict[str, np.ndarray]], n: int):
        return results(n)

    def create() -> ZarrStore:
        if path.exists() and not overwrite:
            return ZarrStore.open(path, spec)
        blocks = Blocks(shape, block_shape(shape, chunk))
        first = ran[0] = compute(blocks, 0)(blocks.max_size)
        trailing = lambda v: (("mass", v.shape[1]),) if v.ndim > 1 else ()
        variables = {k: (v.dtype, {"description": DESCRIPTIONS.get(k, k)}, trailing(v)) for k, v in first.items()}
        dims = tuple(values) if mode == "grid" else ("config",)
        coords = {n: (n if mode == "grid" else "config", v) for n, v in values.items()}
        return ZarrStore.create(path, spec, dims, shape, blocks.block, variables, coords, attrs, overwrite)

    return fill_store(path, spec, create, size, compute, collect, progress)
