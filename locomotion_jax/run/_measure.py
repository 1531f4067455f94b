"""`measure`: the paper's steady-state measurements (Sects. 3-5), on any dynamics and mechanism.

The front end checks the arguments and prepares the batch; the dynamics measure it
(`AbstractDynamics.measure_two_mass` or `measure_chain`, as the mechanism chooses):
the exact engines accumulate the measurements on the fly, so memory does not grow
with the number of steps (`dynamics._chain_measure`, the paper's model through `dynamics._paper`).
"""

from typing import Any, overload

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike
from .._results import Measurement, PAPER
from ..dynamics._base import AbstractDynamics
from ..dynamics._forward import check_static
from ..model import _two_mass as model
from ..model._bodies import Mechanism
from ..model._chain import Chain
from ..model._params import Params
from ..model._waveform import AbstractWaveform
from ._batch import (
    check_contact_start,
    check_hop_dynamics,
    dynamics_arg,
    mechanism_arg,
    prepare,
    prepare_chain,
    prepare_chain_initial,
    prepare_initial,
    unflatten,
)
from ._resolution import flag, guard_chain, guard_two_mass


def _start_times(t_start: ArrayLike | None, shape: tuple[int, ...], dtype: Any) -> jax.Array | None:
    """Explicit measurement starts, broadcast to the batch and flattened (`None`: the paper's)."""
    if t_start is None:
        return None
    check_static("t_start", t_start)
    ts = np.broadcast_to(np.asarray(t_start, float), shape)
    if not np.all(np.isfinite(ts)) or np.any(ts < 0):
        raise ValueError(f"t_start must be finite and >= 0, got {t_start!r}.")
    return jnp.asarray(ts.reshape((-1,)), dtype)


def check_measure_args(z: float, horizon: float, window: float) -> None:
    for name, value in (("z", z), ("horizon", horizon), ("window", window)):
        check_static(name, value)
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}.")


@overload
def measure(
    params: Params,
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
) -> Measurement: ...


@overload
def measure(
    params: Chain | Mechanism,
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
) -> Measurement: ...


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
    model.check_contact(contact, hop=True)  # each path below refuses "hop" where it does not support it
    check_hop_dynamics(contact, dynamics)
    model.initial_gap(Params(), start)
    check_measure_args(z, horizon, window)
    # The mechanism picks its path (double dispatch); each path runs the dynamics' method for it.
    args = (dynamics, float(z), float(horizon), float(window), t_start, waveform, contact, start, initial, dtype)
    return mechanism_arg(params).dispatch(two_mass=lambda p: _two_mass(p, *args), chain=lambda c: _chain(c, *args))


def _two_mass(params: Params, dynamics: AbstractDynamics, z, horizon, window, t_start, waveform, contact, start,
              initial, dtype) -> Measurement:  # fmt: skip
    flat, wave, axes, shape = prepare(params, waveform, dtype)
    ts = _start_times(t_start, shape, flat.dtype)
    flat, unresolved = guard_two_mass(dynamics, flat, wave, shape, default_start=ts is None)
    y0 = prepare_initial(initial, shape, flat.dtype)
    out = flag(dynamics.measure_two_mass(flat, wave, axes, z, horizon, window, contact, start, ts, y0), unresolved)
    start = "initial" if initial is not None else start
    return Measurement(**unflatten(out, shape), z=z, start=start, contact=contact, names=PAPER)


def _chain(chain: Chain | Mechanism, dynamics: AbstractDynamics, z, horizon, window, t_start, waveform, contact,
           start, initial, dtype) -> Measurement:  # fmt: skip
    if waveform is not None:
        raise ValueError(
            f"waveform= applies to Params; a {type(chain).__name__} carries its own waveforms (springs or links)."
        )
    return measure_chain(chain, dynamics, z, horizon, window, t_start, contact, start, dtype, initial)


def measure_chain(chain: Chain | Mechanism, dynamics: AbstractDynamics, z: float, horizon: float, window: float,
                  t_start: Any, contact: str, start: str, dtype: Any,
                  initial: Any = None) -> Measurement:  # fmt: skip
    """`measure` for a [`Chain`][] or a [`Mechanism`][locomotion_jax.Mechanism] (arguments as there; also the
    chunks of a chain sweep)."""
    check_contact_start(contact, start, chain)
    check_hop_dynamics(contact, dynamics)  # measure_chain is also the chain sweeps' entry
    flat, valid, shape = prepare_chain(chain, dtype)
    ts = _start_times(t_start, shape, flat.dtype)  # checked on the host, as for the two-mass model
    valid, unresolved = guard_chain(dynamics, flat, valid, shape, default_start=ts is None)
    y0 = prepare_chain_initial(initial, shape, flat.n_masses, flat.dtype, flat)
    n = valid.shape[0]
    if ts is None:
        ts = jnp.full((n,), jnp.inf, flat.dtype)  # the chains' own, `Chain.t_start`
    out = flag(dynamics.measure_chain(flat, valid, ts, z, horizon, window, contact, start, y0), unresolved)
    start = "initial" if initial is not None else start
    return Measurement(**unflatten(out, shape), z=z, start=start, contact=contact)
