"""Maps over chains of N masses and mechanisms: [`sweep`][locomotion_jax.sweep] with a `mechanism` builder.

A chain has no fixed list of parameter names (its fields are per mass and per spring,
its waveform and friction law are classes), so the sweep asks the user for a builder:
a function from the swept values (1-D arrays, one entry per configuration) to a
batched [`Chain`][] or [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9). The configurations are
cut into chunks of one shape, the last one padded with repeats of its last configuration, so one
compilation serves the map; each chunk is measured by `measure` (the dynamics' N-mass engine). The
map is kept in memory, written to NetCDF when done, or written into a Zarr store chunk by chunk
([`_to_zarr`][]: blocks of the grid, resumable, shared by processes as a map of the paper's model).
"""

import hashlib
import math
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._results import Measurement
from ..model._bodies import Mechanism
from ..model._chain import Chain
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
):
    """The chain sweep behind `sweep(axes, mechanism=build)`; arguments as there.

    Returns an `xarray.Dataset` with one dimension per axis (`"config"` for a list),
    one variable per [`Measurement`][] field (`stick_fraction` with a trailing
    `mass` dimension), the axes as coordinates and the settings as attributes; for a
    Zarr `path`, the store, filled chunk by chunk ([`_to_zarr`][]) and read lazily.
    """
    import xarray as xr
    from tqdm.auto import tqdm

    from ..run._measure import measure

    values, shape = _axes(axes, mode)
    fixed = dict(fixed or {})
    if path is not None:
        path = Path(path).expanduser()
        if not is_zarr(path) and path.suffix != ".nc":
            raise ValueError(
                f"path for a chain sweep must be a NetCDF file (.nc), written when the map is done, or a Zarr store "
                f"(.zarr), written chunk by chunk; got {str(path)!r}."
            )
        if not is_zarr(path):
            _check_writable(path)  # before the work, not when the map is done
    size = math.prod(shape)
    chunk = min(int(chunk_size), size)
    n_chunks = -(-size // chunk)

    def chunk_chain(i: int) -> "tuple[Chain | Mechanism, int]":
        flat = np.arange(i * chunk, (i + 1) * chunk)
        n = int(min(chunk, size - i * chunk))
        chain = _build(build, values, shape, mode, fixed, np.minimum(flat, size - 1))
        return chain, n

    if on_invalid == "raise":  # before any computation: every configuration is checked
        for i in range(n_chunks):
            chain, n = chunk_chain(i)
            bad = np.flatnonzero(~np.asarray(chain.is_valid())[:n])
            if bad.size:
                j = int(bad[0])
                where = np.unravel_index(i * chunk + j, shape) if mode == "grid" else (i * chunk + j,)
                at = ", ".join(f"{name}={float(values[name][k])!r}" for name, k in zip(values, where))
                try:
                    chain[j].validate()
                except ValueError as e:
                    index = tuple(map(int, where))
                    raise ValueError(f"Invalid configuration at grid index {index} ({at}): {e}") from None

    def run(chain: "Chain | Mechanism") -> Measurement:
        return measure(chain, float(z), horizon=float(horizon), window=float(window), t_start=t_start,
                       dynamics=dynamics, contact=contact, start=start, dtype=dtype)  # fmt: skip

    first = _build(build, values, shape, mode, fixed, np.zeros((1,), int))
    attrs = _attrs(first, values, mode, fixed, dtype, z, horizon, window, t_start, dynamics, contact, start, on_invalid)
    if path is not None and is_zarr(path):
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
        return _to_zarr(path, spec, attrs, values, shape, mode, chunk, overwrite, progress,
                        lambda flat: run(_build(build, values, shape, mode, fixed, flat)))  # fmt: skip

    parts: list[dict[str, np.ndarray]] = []
    bar = tqdm(total=size, unit="config", unit_scale=True, desc="sweep", disable=not progress)
    bar.set_postfix_str("compiling (first call only)...")  # shown from the first second
    try:
        for i in range(n_chunks):
            chain, n = chunk_chain(i)
            m = run(chain)
            parts.append({k: v[:n] for k, v in m.to_numpy().items()})
            bar.update(n)
            bar.set_postfix_str("")
    finally:
        bar.close()

    dims = tuple(values) if mode == "grid" else ("config",)
    coords = {n: (n if mode == "grid" else "config", v) for n, v in values.items()}
    data = {}
    for name in Measurement.__dataclass_fields__:
        if name in ("z", "start", "contact", "names") or name not in parts[0]:  # the hopping fields outside "hop"
            continue
        arr = np.concatenate([p[name] for p in parts])
        extra = arr.shape[1:]
        data[name] = (dims + ("mass",) * len(extra), arr.reshape(shape + extra))
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    if path is not None:
        try:
            ds.to_netcdf(path, engine="h5netcdf")
        except OSError as err:
            raise ValueError(f"Cannot write the sweep output at {path}: {err.strerror or err}.") from None
    return ds


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
             measure_at: Callable[[np.ndarray], Measurement]):  # fmt: skip
    """The map into a Zarr store (`_zarr_sweep.fill_store`: resumable, several processes at once):
    each chunk a block of the grid, its configurations (the flat grid indices `blocks.configs`,
    padded with repeats of the last to the block's size: one compiled program) measured by
    `measure_at(indices)`; the store's arrays and their dtypes are those of the first chunk's results."""
    from ._dataset import DESCRIPTIONS
    from ._zarr_store import block_shape, Blocks, ZarrStore
    from ._zarr_sweep import fill_store

    size = math.prod(shape)
    ran: dict[int, Measurement] = {}  # the first chunk, run to learn the arrays, is not run again

    def compute(blocks: Blocks, index: int) -> Measurement:
        if index in ran:
            return ran.pop(index)
        flat = blocks.configs(index)
        return measure_at(np.concatenate([flat, np.repeat(flat[-1:], blocks.max_size - flat.size)]))

    def collect(blocks: Blocks, index: int, m: Measurement, n: int) -> dict[str, np.ndarray]:
        return {k: v[:n] for k, v in m.to_numpy().items()}

    def create() -> ZarrStore:
        if path.exists() and not overwrite:
            return ZarrStore.open(path, spec)
        blocks = Blocks(shape, block_shape(shape, chunk))
        ran[0] = compute(blocks, 0)
        trailing = lambda v: (("mass", v.shape[1]),) if v.ndim > 1 else ()
        variables = {k: (v.dtype, {"description": DESCRIPTIONS.get(k, k)}, trailing(v))
                     for k, v in ran[0].to_numpy().items()}  # fmt: skip
        dims = tuple(values) if mode == "grid" else ("config",)
        coords = {n: (n if mode == "grid" else "config", v) for n, v in values.items()}
        return ZarrStore.create(path, spec, dims, shape, blocks.block, variables, coords, attrs, overwrite)

    return fill_store(path, spec, create, size, compute, collect, progress)


def _check_writable(path: Path) -> None:
    """Create `path`'s folder and a file in it, or raise `ValueError` naming the path and the reason."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", suffix=".probe"):
            pass
    except OSError as err:
        raise ValueError(f"Cannot write the sweep output at {path}: {err.strerror or err}.") from None
