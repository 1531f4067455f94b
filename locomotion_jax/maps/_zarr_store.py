"""A sweep's Zarr (v3) store: written chunk by chunk, by one process or several at once.

Layout of `path = "maps/fig6.zarr"`, a Zarr v3 group with consolidated metadata:

- one array per `Measurement` field, with the sweep's dimensions (`dimension_names`,
  read by `xarray.open_zarr`), created whole before any computation, filled with
  NaN (floats), `-2` (`status`, `regime`, `n_steps`, `n_switch`: not computed) or
  `False`; and one coordinate array per swept axis;
- group attributes: the dataset's attributes (as in the NetCDF output), among them
  `sweep_spec`, the sweep's full specification, and `sweep_block`, the shape of a chunk;
- `.locomotion_jax/done/chunk_000012`: an empty file created once chunk 12's data
  is written (a resumed sweep skips it);
- `.locomotion_jax/claims/chunk_000012.lock`: the lock a process holds while it
  computes chunk 12 (`fcntl.flock`).

A sweep chunk is one Zarr chunk: a block of the grid (whole trailing dimensions,
as many leading rows as fit in `chunk_size`), so a chunk is one region of every
array, each region is one file per array, and processes writing different chunks
never touch the same file. Zarr writes a file under a temporary name and renames
it, so a reader never sees half a chunk; a chunk is marked done only after all of
its arrays are written, so one interrupted mid-write is computed again.

Why `flock` for the claims: the kernel releases the lock of a process that dies,
however it dies, so a chunk whose process was killed is free at once, for a
resumed sweep or for a process of the same sweep still running; a lock file that
outlives its process blocks nothing. (On network file systems, `flock` needs the
file system's lock support, as on NFSv4 and Lustre mounted with `flock`. Without
`fcntl`, on Windows, claims always succeed: run one process per store there.)
"""

import json
import os
import shutil
import socket
import time
import uuid
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._store import _mismatch, canonical


try:
    import fcntl
except ImportError:  # Windows
    fcntl = None


FORMAT = 1
"""Version of this layout, stored in the attribute `locomotion_jax_store`."""

META = ".locomotion_jax"
"""Directory of the store holding the completion marks and the claims."""

NOT_COMPUTED = -2
"""Fill value of the integer arrays (`status`, `regime`, `n_steps`, `n_switch`) where no chunk was written
(no status or regime code: `Regime.UNDETERMINED` is -1)."""


def is_zarr(path: str | os.PathLike) -> bool:
    """Whether a sweep's `path` names a Zarr store (its name ends in `.zarr`)."""
    return Path(path).suffix == ".zarr"


def block_shape(shape: Sequence[int], chunk_size: int) -> tuple[int, ...]:
    """The largest block of the grid `shape` of at most `chunk_size` configurations (at
    least one) that is whole along the trailing dimensions: its configurations are a
    contiguous range of the grid in C order, like a chunk of a NetCDF sweep."""
    block, room = [], max(1, int(chunk_size))
    for n in reversed(shape):
        take = min(n, room)
        block.append(take)
        room = room // n if take == n else 1
    return tuple(reversed(block))


class Blocks:
    """The chunks of a grid cut in blocks of shape `block` (C order of the blocks)."""

    def __init__(self, shape: Sequence[int], block: Sequence[int]):
        if len(block) != len(shape) or any(b < 1 for b in block):
            raise ValueError(f"Block {tuple(block)} does not fit a grid of shape {tuple(shape)}.")
        self.shape, self.block = tuple(int(n) for n in shape), tuple(int(b) for b in block)
        self.counts = tuple(-(-n // b) for n, b in zip(self.shape, self.block))
        self.n_chunks = int(np.prod(self.counts))
        self.max_size = int(np.prod(self.block))

    def region(self, index: int) -> tuple[slice, ...]:
        corner = np.unravel_index(index, self.counts)
        return tuple(slice(c * b, min((c + 1) * b, n)) for c, b, n in zip(corner, self.block, self.shape))

    def configs(self, index: int) -> np.ndarray:
        """Flat (C order) numbers of the chunk's configurations, in C order within the block."""
        ranges = [np.arange(r.start, r.stop) for r in self.region(index)]
        return np.ravel_multi_index(np.ix_(*ranges), self.shape).ravel()


class Claim:
    """A chunk's lock, held until [`release`][]; the kernel releases it if the process dies.

    `previous`: the holder line an earlier claim left (`"host pid N since ..."`), or `None`. A
    chunk that is claimed again is not done, so its earlier holder stopped before finishing it:
    this process takes it over."""

    def __init__(self, fd: int | None, previous: str | None = None):
        self._fd = fd
        self.previous = previous

    def release(self) -> None:
        if self._fd is not None and fcntl is not None:  # a claim holds a descriptor only where fcntl exists
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


def variable_fill(dtype: np.dtype) -> Any:
    """The fill value of an array of `dtype`: where no chunk has been written."""
    dtype = np.dtype(dtype)
    if dtype == np.bool_:
        return False
    return np.nan if np.issubdtype(dtype, np.floating) else NOT_COMPUTED


class ZarrStore:
    """An open sweep store (see the module docstring).

    Use [`create`][] (one process creates; the others, or a resumed sweep, find it)
    or [`open`][]. **Attributes:** `path`, `blocks` (the chunking it was created with).
    """

    def __init__(self, path: Path, group: Any):
        self.path = path
        self.group = group
        attrs = dict(group.attrs)
        self.blocks = Blocks(attrs["sweep_shape"], attrs["sweep_block"])
        self.spec = json.loads(attrs["sweep_spec"])
        self.meta = path / META
        self._arrays: dict[str, Any] = {}  # opened once: a lookup reads metadata (half the cost of a write)

    # -- creation and opening ----------------------------------------------------------

    @staticmethod
    def open(path: Path, spec: Mapping[str, Any]) -> "ZarrStore":
        """Open the sweep store at `path` and check that it holds the sweep `spec`.

        **Raises:** `ValueError` if `path` is not a sweep store of this layout or holds
        a sweep with another specification (naming the entries that differ).
        """
        import zarr

        try:
            group = zarr.open_group(path, mode="r+", zarr_format=3, use_consolidated=True)
            attrs = dict(group.attrs)
            version, stored = attrs["locomotion_jax_store"], json.loads(str(attrs["sweep_spec"]))
        except Exception as err:  # not a sweep store: never write into it
            raise ValueError(
                f"Output path {path} exists and is not a locomotion_jax sweep store ({type(err).__name__}); "
                "pass overwrite=True (CLI: --overwrite) to replace it, or choose another path."
            ) from None
        if version != FORMAT:
            raise ValueError(f"{path} is a sweep store of layout {version}; this version reads layout {FORMAT}.")
        if canonical(stored) != canonical(spec):
            raise _mismatch(path, stored, spec)
        return ZarrStore(path, group)

    @staticmethod
    def create(
        path: Path,
        spec: Mapping[str, Any],
        dims: Sequence[str],
        shape: Sequence[int],
        block: Sequence[int],
        variables: Mapping[str, tuple[Any, ...]],
        coords: Mapping[str, tuple[str, np.ndarray]],
        attrs: Mapping[str, Any],
        overwrite: bool = False,
    ) -> "ZarrStore":
        """Create the store (unless one exists) and open it.

        The new store is built under a temporary name and renamed into place, so a
        process that opens `path` sees either nothing or a complete, empty store, and
        of several processes creating the same store at once one wins and the others
        open its store. An existing store is opened and checked as by [`open`][].

        **Arguments:**

        - `dims`, `shape`, `block`: the dimensions, the grid's shape and a chunk's block.
        - `variables`: name -> (dtype, attributes) of each array of measurements, or (dtype,
          attributes, trailing) for one with trailing dimensions after the grid's, `trailing` a
          tuple of `(dimension, length)` (a chain's `stick_fraction`: `(("mass", N),)`).
        - `coords`: name -> (dimension, values) of each coordinate.
        - `attrs`: the group's attributes (`sweep_spec` is added).
        - `overwrite`: delete whatever is at `path` first.

        **Raises:** `ValueError` if `path` cannot be written, or holds something else
        (see [`open`][]) and `overwrite` is False.
        """
        try:
            if overwrite and path.exists():
                shutil.rmtree(path) if path.is_dir() else path.unlink()
            if not path.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f"{path.name}.tmp-{uuid.uuid4().hex[:12]}")
                try:
                    _build(tmp, spec, dims, shape, block, variables, coords, attrs)
                    try:
                        os.rename(tmp, path)  # atomic; fails if another process was first
                    except OSError:
                        if not path.is_dir():
                            raise
                finally:
                    shutil.rmtree(tmp, ignore_errors=True)
        except OSError as err:
            raise ValueError(f"Cannot write the sweep output at {path}: {err.strerror or err}.") from None
        return ZarrStore.open(path, spec)

    # -- chunks ------------------------------------------------------------------------

    def _mark(self, index: int) -> Path:
        return self.meta / "done" / f"chunk_{index:06d}"

    def done(self) -> set[int]:
        """Indices of the chunks written completely."""
        folder = self.meta / "done"
        return {int(p.name.split("_")[1]) for p in folder.iterdir()} if folder.is_dir() else set()

    def is_done(self, index: int) -> bool:
        return self._mark(index).exists()

    def claim(self, index: int) -> Claim | None:
        """Lock chunk `index` for this process, or `None` if a live process holds it."""
        if fcntl is None:
            return Claim(None)
        file = self.meta / "claims" / f"chunk_{index:06d}.lock"
        fd = os.open(file, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held by another process
            os.close(fd)
            return None
        # Who holds it, for a person looking at a stalled sweep (the lock is the flock, not this text).
        previous = os.read(fd, 4096).decode(errors="replace").strip() or None
        os.lseek(fd, 0, os.SEEK_SET)
        os.ftruncate(fd, 0)
        os.write(fd, f"{socket.gethostname()} pid {os.getpid()} since {time.strftime('%Y-%m-%dT%H:%M:%S')}\n".encode())
        return Claim(fd, previous)

    def write(self, index: int, results: Mapping[str, np.ndarray]) -> None:
        """Write chunk `index`'s results (flat, in the block's C order, then any trailing dimensions) to
        its region, then mark it done."""
        region = self.blocks.region(index)
        shape = tuple(r.stop - r.start for r in region)
        for name, values in results.items():
            if name not in self._arrays:
                self._arrays[name] = self.group[name]
            values = np.asarray(values)
            self._arrays[name][region] = values.reshape(shape + values.shape[1:])
        self._mark(index).touch()

    def dataset(self):
        """The store as an `xarray.Dataset`, read lazily (`xarray.open_zarr`)."""
        import xarray as xr

        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
            return xr.open_zarr(self.path, consolidated=True, chunks=None, zarr_format=3)


def _build(tmp: Path, spec, dims, shape, block, variables, coords, attrs) -> None:
    import zarr

    group_attrs = {
        **{k: _json_attr(v) for k, v in attrs.items()},
        "sweep_spec": canonical(spec),
        "sweep_shape": [int(n) for n in shape],
        "sweep_block": [int(b) for b in block],
        "locomotion_jax_store": FORMAT,
    }
    group = zarr.open_group(tmp, mode="w-", zarr_format=3, attributes=group_attrs)
    index_coords = [n for n, (dim, _) in coords.items() if n == dim]
    other_coords = " ".join(n for n in coords if n not in index_coords)
    for name, (dim, values) in coords.items():
        values = np.asarray(values)
        group.create_array(name, data=values, chunks=values.shape, dimension_names=(dim,))
    for name, (dtype, var_attrs, *rest) in variables.items():
        trailing = tuple(rest[0]) if rest else ()
        var_attrs = dict(var_attrs) | ({"coordinates": other_coords} if other_coords else {})
        group.create_array(
            name,
            shape=tuple(shape) + tuple(n for _, n in trailing),
            dtype=np.dtype(dtype),
            chunks=tuple(block) + tuple(n for _, n in trailing),
            fill_value=variable_fill(dtype),
            dimension_names=tuple(dims) + tuple(d for d, _ in trailing),
            attributes=var_attrs,
        )
    with warnings.catch_warnings():  # consolidated metadata is not (yet) in the v3 specification
        warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
        zarr.consolidate_metadata(tmp, zarr_format=3)
    for sub in ("done", "claims"):
        (tmp / META / sub).mkdir(parents=True)


def _json_attr(value: Any) -> Any:
    """An attribute value JSON can hold (numpy scalars as Python numbers)."""
    return value.item() if isinstance(value, np.generic) else value
