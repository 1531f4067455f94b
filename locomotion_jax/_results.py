"""Result containers with named fields (compare diffrax `Solution`)."""

import equinox as eqx
import numpy as np

from ._custom_types import Array


class Trajectory(eqx.Module):
    """States saved at the requested times (one configuration or a batch).

    Array fields have shape `batch_shape + (n_save,)` (per-time fields) or
    `batch_shape` (per-configuration fields).

    - `t`: save times; `x1, v1, x2, v2`: positions and velocities.
    - `X`: centre of mass (eq. 4). `e_d`: dissipated energy since $t=0$ (eq. 15).
      `w`: actuator work since $t=0$ (eq. 16). `e`: total energy (eq. 10).
    - `mode`: contact mode (Sect. 2.2; `Mode`): 0 both stick, 1 both slip,
      2 $m_1$ slips, 3 $m_2$ slips.
    - `l0`: rest length; `N1, N2`: signed normal forces (eq. 5); `f_ex`: the
      horizontal friction plus damping force on the system (eq. 17).
    - `valid`: False for save times after the run stopped (lift-off or step
      cap); those entries repeat the last state reached, never NaN.
    - `status`: `Status` code; `liftoff`: a normal force reached zero
      (strict: the run stopped there; paper reading: flagged, continued);
      `t_liftoff`: first lift-off time (`inf` if none).
    - `start`, `contact`: the initial condition and contact reading used.
    """

    t: Array
    x1: Array
    v1: Array
    x2: Array
    v2: Array
    X: Array
    e_d: Array
    w: Array
    e: Array
    mode: Array
    l0: Array
    N1: Array
    N2: Array
    f_ex: Array
    valid: Array
    status: Array
    liftoff: Array
    t_liftoff: Array
    n_switch: Array
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)

    def to_numpy(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k)) for k in self.__dataclass_fields__ if k not in ("start", "contact")}


class Measurement(eqx.Module):
    """The paper's measurements (Sect. 3-5; SPEC §5), per configuration.

    The measurement starts at $t_\\text{start}$ = 80 periods of the lowest
    natural frequency and runs until $|X - X(t_\\text{start})| = z$ or the horizon.

    - `tau_z`: time to travel `z` after $t_\\text{start}$; **`inf` when not
      reached** (then `reached` is False).
    - `e_z`: dissipated energy (eq. 15) over the same interval; `inf` when not reached.
    - `reached`: whether $|X - X(t_\\text{start})|$ reached `z` within the horizon.
    - `regime`: `Regime` code: 1 SSL, 0 SL (the paper's window rule over
      `window` = 25), -1 undetermined (the run stopped before the window ended).
    - `mean_speed`: signed $\\Delta X / \\Delta t$ over the measured interval
      (to `tau_z`, or to the horizon/stop when not reached).
    - `cost_of_transport`: `e_z / z` (`inf` when not reached).
    - `stick_fraction1`, `stick_fraction2`: fraction of the window each mass is stuck.
    - `e_d`, `work`, `delta_e`: dissipated energy, actuator work and change of
      total energy over the measured interval; `balance` $= w - e_d - \\Delta e$
      (eq. 16; zero up to the integration error).
    - `liftoff`, `t_liftoff`: as in `Trajectory`. `status`: `Status` code.
    - `t_start`, `X_start`: the measurement's start time and centre of mass.
    - `n_steps`: integrator iterations used; `n_switch`: mode switches.

    Quantities that cannot be computed because the run stopped before
    $t_\\text{start}$ (lift-off, invalid input) are NaN, and `status` says why.
    """

    tau_z: Array
    e_z: Array
    reached: Array
    regime: Array
    mean_speed: Array
    cost_of_transport: Array
    stick_fraction1: Array
    stick_fraction2: Array
    e_d: Array
    work: Array
    delta_e: Array
    balance: Array
    liftoff: Array
    t_liftoff: Array
    status: Array
    t_start: Array
    X_start: Array
    n_steps: Array
    n_switch: Array
    z: float = eqx.field(static=True)
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)

    def to_numpy(self) -> dict[str, np.ndarray]:
        skip = ("z", "start", "contact")
        return {k: np.asarray(getattr(self, k)) for k in self.__dataclass_fields__ if k not in skip}
