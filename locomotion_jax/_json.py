"""JSON encoding of results: every non-finite number (NaN, +inf, -inf) becomes `null`.

JSON has no NaN or infinity. A `null` means "no finite value": not computable
(NaN), or never happened (`tau_z`, `e_z` when `z` is not reached, `t_liftoff`
without lift-off: inf); the record's flags (`reached`, `liftoff`, `status`) say which.
"""

import json
import math
from typing import Any

import numpy as np


def jsonable(x: Any) -> Any:
    """`x` with numpy scalars and arrays as Python values, non-finite floats as `None`, keys as strings."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def dumps(x: Any, **kwargs: Any) -> str:
    """`json.dumps` of [`jsonable`][]`(x)`; strict JSON (never `NaN` or `Infinity`)."""
    return json.dumps(jsonable(x), allow_nan=False, **kwargs)
