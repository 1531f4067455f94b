"""A warm start: JAX's persistent compilation cache in a per-user directory.

Every new process traces and compiles the engine again (about 10 s on a 2-core
CPU for `simulate`); with the cache, a compiled executable is written to disk the
first time and read back by later processes. Tracing still happens in every
process (JAX computes the cache key from the traced program), so a warm call
costs the imports, the tracing and the reads.

Nothing here runs on import: library code leaves JAX's global configuration
alone. A Python session calls [`enable_compilation_cache`][]; the command line
calls it at start-up unless given `--no-cache` (or `LOCOMOTION_JAX_CACHE=0`).
"""

import os
import sys
from pathlib import Path


ENV_DIR = "LOCOMOTION_JAX_CACHE_DIR"
"""Environment variable naming the cache directory (overrides the per-user default)."""

ENV_SWITCH = "LOCOMOTION_JAX_CACHE"
"""Environment variable read by the command line: `0`, `false`, `no` or `off` turn the cache off."""


WRITE_EVERY_ENTRY: dict[str, float | int] = {
    "jax_persistent_cache_min_compile_time_secs": 0.0,
    "jax_persistent_cache_min_entry_size_bytes": -1,
}
"""JAX settings with which every compilation is written to the cache ([`enable_compilation_cache`][]);
JAX also reads each from the environment variable of its name in upper case."""


def user_cache_root() -> Path:
    """The platform's per-user cache directory: `$XDG_CACHE_HOME` (default `~/.cache`)
    on Linux, `~/Library/Caches` on macOS, `%LOCALAPPDATA%` on Windows."""
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches"
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")


def cache_dir() -> Path:
    """The default cache directory.

    `$LOCOMOTION_JAX_CACHE_DIR` if set; otherwise `locomotion_jax/jax` under the
    per-user cache directory of the platform ([`user_cache_root`][]).
    """
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    return user_cache_root() / "locomotion_jax" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache for this process, in `path`.

    Sets `jax_compilation_cache_dir` and writes *every* compilation to the cache:
    `jax_persistent_cache_min_compile_time_secs = 0` (JAX's default, 1 s, would
    leave out the dozens of small computations a call also compiles, each of which
    is faster to read back than to compile again) and no minimum entry size. The
    cache key covers the program, the devices, the compiler options (the engine's
    `_compile.COMPILER_OPTIONS` included), `XLA_FLAGS` and the JAX version, so a
    stale entry is never used; the directory can be deleted at any time. It also
    covers the directory's path (JAX puts a GPU autotuning cache inside it and keys
    on that option), so a cache moved elsewhere is not read.

    This changes JAX's global configuration, for the whole process: call it once,
    at start-up (it also takes effect after computations have run). Do not point
    it at a directory others can write to: JAX trusts the cache's contents.

    **Arguments:**

    - `path`: the cache directory (created if missing); default `$LOCOMOTION_JAX_CACHE_DIR`
      if set, else `locomotion_jax/jax` in the platform's per-user cache directory
      (`~/.cache` on Linux: `_cache.cache_dir`).

    **Returns:** the directory in use.

    **Raises:** `ValueError` if the directory cannot be created.

    !!! Example

        ```python
        import locomotion_jax as lj

        lj.enable_compilation_cache()  # ~/.cache/locomotion_jax/jax
        lj.measure(lj.Params(omega=2.0))  # compiled once, read back by the next session
        ```
    """
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    directory = cache_dir() if path is None else Path(path).expanduser()
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"Cannot create the compilation cache directory {directory}: {err.strerror or err}.") from None
    jax.config.update("jax_compilation_cache_dir", str(directory))
    for name, value in WRITE_EVERY_ENTRY.items():
        jax.config.update(name, value)
    # JAX opens its cache once per process, at the first compilation: reset it so a
    # cache already opened (in another directory, or found missing) takes this one.
    compilation_cache.reset_cache()
    return directory
