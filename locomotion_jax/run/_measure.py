"""`measure`: the paper's steady-state measurements (Sects. 3-5), on any dynamics and mechanism.

The front end checks the arguments, the mechanism flattens itself into a batch
(`AbstractMechanism.flat_batch`) and the dynamics measure it (`AbstractDynamics.measure`):
the exact engines accumulate the measurements on the fly, so memory does not grow
with the number of steps (`dynamics._measure`, the paper's model through `dynamics._paper`).
"""

from typing import Any

import numpy as np

from .._custom_types import ArrayLike
from .._results import Measurement
from ..dynamics._base import AbstractDynamics
from ..dynamics._forward import check_static
from ..model import _two_mass as model
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ._batch import check_hop_dynamics, dynamics_arg, mechanism_arg, unflatten
from ._resolution import flag


def check_measure_args(z: float, horizon: float, window: float) -> None:
    for name, value in (("z", z), ("horizon", horizon), ("window", window)):
        check_static(name, value)
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}.")


def measure(
    params: "Params | Chain | Mechanism",
    z: float = 5.0,
    *,
    horizon: float = 2000.0,
    window: float = 25.0,
    t_start: ArrayLike | None = None,
    dynamics: AbstractDynamics | None = None,
    waveform: AbstractWaveform | None = None,
    contact: str = "strict",
    start: str = "paper",
    initial: tuple | None = None,
    dtype: Any = None,
) -> Measurement:
    """Measure $\\tau_z$, $e_z$, the regime and more (Sects. 3-5; SPEC §5).

    One configuration or a batch: the batch runs under `vmap` in one compiled
    call, and each configuration stops on its own (lift-off, `z` reached after
    the regime window, or the horizon). One failing configuration is flagged in
    its own `status` and never affects the others.

    **Arguments:**

    - `params`: the mechanism: [`Params`][] (the paper's two-mass model) or a [`Chain`][]
      (any batch shape).
    - `z`: distance to travel (paper: 5).
    - `horizon`: time allowed after $t_\\text{start}$ (default 2000).
    - `window`: the regime window $\\Delta\\tau$ (paper: 25).
    - `t_start`: start of the measurement (scalar or batch-shaped); default 80 periods of the
      lowest natural frequency with one mass held (`Params.t_start`, `Chain.t_start`).
    - `dynamics`, `waveform`, `contact`, `start`, `initial`, `dtype`: as in [`simulate`][]
      (a chain carries its own waveforms).

    **Returns:** a [`Measurement`][] with batch shape `params.batch_shape`, for the paper's model as for a
    chain or any other mechanism (one class: per-body fields have a trailing body axis).

    **Raises:** `TypeError` for a `params` or `dynamics` of the wrong type; `ValueError` for
    invalid arguments (before any computation).

    !!! Example

        ```python
        m = measure(Params(omega=2.0), z=5.0)
        float(m.tau_z), float(m.e_z), Regime(int(m.regime))
        # Flight and landing (SPEC §10): Status.OK through lift-off, both masses in flight 90 % of the
        # window. At omega = 10 the hops grow until the masses cross (Status.COLLISION; docs/model.md).
        h = measure(Params(omega=9.0, a=0.1), contact="hop")
        h.flight_fraction, h.highest_hop, h.landings_per_period
        ```
    """
    dynamics = dynamics_arg(dynamics)
    model.check_contact(contact, hop=True)  # the mechanism refuses "hop" where it does not support it
    check_hop_dynamics(contact, dynamics)
    model.initial_gap(Params(), start)
    check_measure_args(z, horizon, window)
    # The mechanism flattens itself (what differs between mechanisms travels in the batch).
    batch, unresolved, shape = mechanism_arg(params).flat_batch(
        dynamics, waveform=waveform, dtype=dtype, t_start=t_start, initial=initial, measuring=True, contact=contact,
        start=start,
    )  # fmt: skip
    out = flag(dynamics.measure(batch, float(z), float(horizon), float(window), contact, start), unresolved)
    start = "initial" if initial is not None else start
    return Measurement(**unflatten(out, shape), z=float(z), start=start, contact=contact, names=batch.names)
