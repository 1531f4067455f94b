"""The configurations of a sweep of the paper's model: swept axes, fixed values, validity.

Host-side only (numpy): a map of millions of configurations is described by its axes,
and the values of any block of them are computed when that block is run.
"""

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..model._params import _validity, DEFAULTS, PARAM_NAMES, Params, VALID_RANGES
from ._store import digest


RATIO = "omega_over_wn1"
"""Convenience axis: $\\omega / \\omega_{n1}$ (eq. 11); `omega` is then derived per configuration."""


class Grid:
    """Host-side description of the configurations: swept axes plus fixed values."""

    def __init__(self, axes: Mapping[str, Any], fixed: Mapping[str, Any] | None, mode: str):
        if mode not in ("grid", "list"):
            raise ValueError(f"mode must be 'grid' (outer product) or 'list' (zipped axes), got {mode!r}.")
        known = PARAM_NAMES + (RATIO,)
        fixed = dict(fixed or {})
        if not isinstance(axes, Mapping) or not axes:
            raise ValueError("axes must be a non-empty mapping of parameter name -> 1-D array of values.")
        for name in list(axes) + list(fixed):
            if name not in known:
                raise ValueError(f"Unknown parameter {name!r}; valid names are {list(known)}.")
        self.values: dict[str, np.ndarray] = {}
        for name, v in axes.items():
            arr = np.asarray(v, dtype=np.float64)
            if arr.ndim == 0:  # a scalar among the axes is a fixed value, as in Params.grid
                fixed.setdefault(name, float(arr))
                continue
            if arr.ndim != 1:
                raise ValueError(f"Axis {name!r} must be 1-D, got shape {arr.shape}.")
            if arr.size == 0:
                raise ValueError(f"Axis {name!r} is empty: a sweep needs at least one value per axis.")
            if name in fixed:
                raise ValueError(f"Parameter {name!r} is given both as an axis and as a fixed value.")
            self.values[name] = arr
        if not self.values:
            raise ValueError("axes holds no 1-D axis: nothing to sweep (put scalars in fixed=).")
        self.fixed = {}
        for name, v in fixed.items():
            arr = np.asarray(v, dtype=np.float64)
            if arr.ndim != 0:
                raise ValueError(f"Fixed parameter {name!r} must be a scalar, got shape {arr.shape}.")
            self.fixed[name] = float(arr)
        given = set(self.values) | set(self.fixed)
        if "omega" in given and RATIO in given:
            raise ValueError("Give either 'omega' or 'omega_over_wn1', not both.")
        for name in PARAM_NAMES:  # everything not given takes the paper's default
            if name not in given and not (name == "omega" and RATIO in given):
                self.fixed[name] = DEFAULTS[name]
        self.names = tuple(self.values)
        self.mode = mode
        lengths = [v.size for v in self.values.values()]
        if mode == "list" and len(set(lengths)) > 1:
            detail = ", ".join(f"{n}: {v.size}" for n, v in self.values.items())
            raise ValueError(f"mode='list' needs axes of equal length, got {detail}.")
        self.shape = tuple(lengths) if mode == "grid" else (lengths[0],)
        self.size = math.prod(self.shape)

    def index(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """Index into each axis of the flat configuration numbers `flat` (C order)."""
        if self.mode == "list":
            return {n: flat for n in self.names}
        return dict(zip(self.names, np.unravel_index(flat, self.shape)))

    def config_values(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """Float64 values of all of `PARAM_NAMES` for the flat configuration numbers `flat`."""
        idx = self.index(flat)
        raw = {n: np.full(flat.shape, v) for n, v in self.fixed.items()}
        raw.update({n: self.values[n][idx[n]] for n in self.names})
        if RATIO in raw:
            ratio = raw.pop(RATIO)
            with np.errstate(all="ignore"):  # invalid mhat/k give NaN here and are flagged anyway
                raw["omega"] = ratio * np.sqrt(raw["k"] / (2 * raw["mhat"] * (1 - raw["mhat"])))
        return raw

    def spec(self) -> dict[str, Any]:
        # Axes are identified by a digest of their float64 values (plus a readable
        # summary): the coordinates themselves are in the dataset, and a list sweep of
        # a million configurations should not become a 20 MB attribute.
        axes = {
            n: {"n": int(v.size), "first": float(v[0]), "last": float(v[-1]), "sha256": digest(v, "<f8")}
            for n, v in self.values.items()
        }
        return {"mode": self.mode, "axes": axes, "fixed": dict(sorted(self.fixed.items()))}


def check_valid(grid: Grid, block: int = 1 << 18) -> int:
    """Raise `ValueError` for the first invalid configuration; host-only (numpy) and blockwise."""
    n_bad, first = 0, None
    for lo in range(0, grid.size, block):
        flat = np.arange(lo, min(lo + block, grid.size))
        vals = grid.config_values(flat)
        with np.errstate(all="ignore"):
            masks = _validity(vals, np)
        ok = np.ones(flat.shape, bool)
        for name in PARAM_NAMES:
            ok &= np.broadcast_to(masks[name], flat.shape)
        n_bad += int((~ok).sum())
        if first is None and not ok.all():
            first = int(flat[np.argmin(ok)])
    if first is None:
        return 0
    one = grid.config_values(np.asarray([first]))
    where = {n: int(i[0]) for n, i in grid.index(np.asarray([first])).items()}
    at = ", ".join(f"{n}[{i}]={float(grid.values[n][i])!r}" for n, i in where.items())
    try:
        values: dict[str, Any] = {n: float(v[0]) for n, v in one.items()}
        Params(**values)
        reason = f"omega derived from {RATIO} is invalid ({VALID_RANGES['omega']})"
    except ValueError as err:
        reason = str(err)
    raise ValueError(
        f"{n_bad} of {grid.size} configurations of the sweep are invalid; the first, at {at}: {reason} "
        "Narrow the range, or pass on_invalid='flag' (CLI: --on-invalid flag) to record them as Status.INVALID."
    )
