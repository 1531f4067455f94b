"""On-disk store of a sweep: finished chunks as they complete, then one NetCDF file.

Layout for `path = "maps/fig6.nc"`:

- `maps/fig6.nc.parts/manifest.json`: the sweep's full specification (axes values,
  fixed parameters, dynamics, dtype, ...) and its chunking;
- `maps/fig6.nc.parts/chunk_000012.npz`: the measurements of chunk 12, unpadded;
- `maps/fig6.nc.parts/order.npy`: for a sweep not run in grid order (`order="cost"`),
  the permutation of the configurations its chunks were cut from (the manifest
  holds its digest), so a resumed sweep cuts the same chunks;
- `maps/fig6.nc`: the final `xarray.Dataset` (NetCDF4 through h5netcdf), written when
  every chunk is done; the parts directory is then removed. Its attribute
  `sweep_spec` holds the same specification, so a rerun can recognise it.

Why `.npz` per chunk for NetCDF output: each chunk is written to a temporary name
and renamed (`os.replace` is atomic on POSIX), so a crash or kill can never leave
a half-written chunk that looks complete, and a chunk of configurations in any
order (`order="cost"`) is stored as it was run. The NetCDF file is assembled in
memory at the end, which suits small maps; large ones, and several processes
writing at once, go to a Zarr store (`_zarr_store`).
"""

import hashlib
import json
import os
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeAlias

import numpy as np


MANIFEST = "manifest.json"
ORDER = "order.npy"

ChunkOrder: TypeAlias = Literal["natural", "cost"]
"""How a sweep's configurations are cut into chunks: grid order, or sorted by expected cost."""


def digest(values: np.ndarray, dtype: str) -> str:
    """Short SHA-256 of an array's values, cast to a fixed little-endian `dtype` (e.g. `"<f8"`)."""
    return hashlib.sha256(np.ascontiguousarray(values, dtype).tobytes()).hexdigest()[:16]


def canonical(spec: Mapping[str, Any]) -> str:
    """Deterministic JSON of a specification (Python floats round-trip exactly)."""
    return json.dumps(spec, sort_keys=True, separators=(",", ":"))


def spec_difference(stored: Mapping[str, Any], requested: Mapping[str, Any], prefix: str = "") -> str:
    """Human-readable list of the entries that differ, by their path (`mechanism.sha256`): entries
    that are mappings on both sides are compared entry by entry."""
    lines = []
    for key in sorted(set(stored) | set(requested)):
        a, b = stored.get(key, "<missing>"), requested.get(key, "<missing>")
        if canonical({"v": a}) == canonical({"v": b}):
            continue
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            lines.append(spec_difference(a, b, f"{prefix}{key}."))
            continue
        sa, sb = canonical({"v": a})[5:-1], canonical({"v": b})[5:-1]
        short = lambda s: s if len(s) <= 120 else s[:117] + "..."
        lines.append(f"  {prefix}{key}: stored {short(sa)}, requested {short(sb)}")
    return "\n".join(lines)


def _mismatch(what: Path, stored: Mapping[str, Any], requested: Mapping[str, Any]) -> ValueError:
    return ValueError(
        f"{what} holds a sweep with a different specification:\n{spec_difference(stored, requested)}\n"
        "Pass overwrite=True (CLI: --overwrite) to replace it, or choose another path."
    )


def _atomic_write(target: Path, write) -> None:
    tmp = target.with_name(target.name + f".tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_finished(path: Path, spec: Mapping[str, Any], overwrite: bool):
    """Return the finished dataset at `path` if it matches `spec`, else `None`.

    With `overwrite`, whatever is at `path` is deleted and `None` returned.

    **Raises:** `ValueError` if `path` holds something else and `overwrite` is False.
    """
    import xarray as xr

    if path.is_dir():
        raise ValueError(f"Output path {path} is a directory; give a file name such as {path / 'sweep.nc'}.")
    if not path.exists():
        return None
    if overwrite:  # start afresh, whatever is there
        path.unlink()
        return None
    try:
        ds = xr.load_dataset(path, engine="h5netcdf")
        stored = json.loads(ds.attrs["sweep_spec"])
    except Exception as err:  # not a sweep file: never clobber it silently
        raise ValueError(
            f"Output path {path} exists and is not a locomotion_jax sweep ({type(err).__name__}); "
            "pass overwrite=True (CLI: --overwrite) to replace it."
        ) from None
    if canonical(stored) == canonical(spec):
        return ds
    raise _mismatch(path, stored, spec)


class ChunkStore:
    """The parts directory of one sweep (see the module docstring).

    **Arguments:**

    - `path`: the final NetCDF file; chunks live in `path + ".parts"`.
    - `spec`: the sweep's specification (JSON-serialisable).
    - `chunk_size`: configurations per chunk for a new store; a resumed store
      keeps the chunk size it was started with (the result does not depend on it).
    - `n_configs`: total number of configurations.
    - `overwrite`: discard any stored chunks (recompute everything).
    - `write`: False on the non-zero processes of a multi-host run (only process 0 writes).
    - `order`, `permutation`: for a new store, the name of the order the chunks are
      cut in and a function returning its permutation of the configurations (`None`:
      grid order). It is called only for a new store: a resumed store keeps the order
      it was started with, read back from disk (the result does not depend on it).

    **Attributes:** `chunk_size`, `order` and `permutation` (`None` for grid order) in use.

    **Raises:** `ValueError` if the directory cannot be created or written, holds
    a sweep with a different specification and `overwrite` is False, or its stored
    permutation is missing or damaged.
    """

    def __init__(
        self,
        path: Path,
        spec: Mapping[str, Any],
        chunk_size: int,
        n_configs: int,
        overwrite: bool = False,
        write: bool = True,
        order: ChunkOrder = "natural",
        permutation: Callable[[], np.ndarray] | None = None,
    ):
        self.path = path
        self.parts = path.with_name(path.name + ".parts")
        self.write = write
        self.chunk_size: int
        self.order: ChunkOrder
        self.permutation: np.ndarray | None
        manifest = self.parts / MANIFEST
        try:  # fail now, not after hours of computing, if the NetCDF writer is missing
            import h5netcdf  # noqa: F401
            import h5py  # noqa: F401
        except ImportError as err:
            raise ValueError(f"Writing the sweep needs h5netcdf and h5py: {err}.") from None
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if overwrite and write and self.parts.exists():
                shutil.rmtree(self.parts)  # start afresh
            stored = json.loads(manifest.read_text()) if manifest.exists() else None
            if stored is not None and canonical(stored["spec"]) != canonical(spec):
                raise _mismatch(self.parts, stored["spec"], spec)
            if stored is None:
                self.chunk_size, self.order = int(chunk_size), order
                perm = None if permutation is None else np.asarray(permutation(), np.int64)
                self.permutation = perm
                record = {"spec": spec, "chunk_size": self.chunk_size, "n_configs": int(n_configs), "order": order}
                if perm is not None:
                    record["permutation_sha256"] = digest(perm, "<i8")
                if write:
                    self.parts.mkdir(parents=True, exist_ok=True)
                    if perm is not None:  # before the manifest, which marks the store as started
                        _atomic_write(self.parts / ORDER, lambda f: np.save(f, perm))
                    _atomic_write(manifest, lambda f: f.write(json.dumps(record, indent=1).encode()))
            else:
                self.chunk_size = int(stored["chunk_size"])
                self.order = stored.get("order", "natural")  # stores written before orders existed
                self.permutation = self._stored_permutation(stored)
        except OSError as err:
            raise ValueError(f"Cannot write the sweep output at {path}: {err.strerror or err}.") from None

    def _stored_permutation(self, stored: Mapping[str, Any]) -> np.ndarray | None:
        """The permutation a resumed store was started with, checked against the manifest's digest."""
        if "permutation_sha256" not in stored:
            return None
        file = self.parts / ORDER
        perm = np.load(file) if file.is_file() else np.zeros(0, np.int64)
        if perm.shape != (int(stored["n_configs"]),) or digest(perm, "<i8") != stored["permutation_sha256"]:
            raise ValueError(
                f"{file} is missing or damaged: the stored chunks cannot be placed. "
                "Pass overwrite=True (CLI: --overwrite) to recompute the sweep."
            )
        return perm

    def _file(self, index: int) -> Path:
        return self.parts / f"chunk_{index:06d}.npz"

    def completed(self) -> set[int]:
        """Indices of the chunks already on disk (complete by construction: atomic renames)."""
        if not self.parts.is_dir():
            return set()
        return {int(p.stem.split("_")[1]) for p in self.parts.glob("chunk_*.npz")}

    def save(self, index: int, arrays: Mapping[str, np.ndarray]) -> None:
        if self.write:
            # numpy's stubs match `**arrays` against `savez`'s `allow_pickle` keyword
            _atomic_write(self._file(index), lambda f: np.savez(f, **arrays))  # pyright: ignore[reportArgumentType]

    def load(self, index: int) -> dict[str, np.ndarray]:
        with np.load(self._file(index)) as data:
            return {k: data[k] for k in data.files}

    def finalize(self, ds, keep_parts: bool = False) -> None:
        """Write the dataset as NetCDF (atomically) and drop the parts directory."""
        if not self.write:
            return
        tmp = self.path.with_name(self.path.name + f".tmp{os.getpid()}")
        try:
            ds.to_netcdf(tmp, engine="h5netcdf")
            os.replace(tmp, self.path)  # readers never see a half-written file
        finally:
            if tmp.exists():
                tmp.unlink()
        if not keep_parts:
            shutil.rmtree(self.parts, ignore_errors=True)
