"""Result containers with named fields (compare diffrax `Solution`)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array


SMOOTH_MARGIN = 0.05
"""The smallest `transversality` and `near_miss` (radians of drive phase; `_exact` module
docstring, "Margins") at which a result counts as `smooth`. A relative change of a
parameter moves the switches by a drive phase of its order (they are locked to the drive
and to each other), so this is about the relative change that the switching structure is
known to survive (tests/test_margins.py)."""

SMOOTH_MARGIN_Z = 1e-4
"""The smallest `Measurement.margin_z` (relative to `tau_z`) at which `tau_z` and `e_z`
count as `smooth`. A relative change of a parameter moves $t_z$ by about $\\tau_z$ times
it, across the switches, which are locked to the drive: where a switch meets $t_z$ the
derivative stays continuous (the velocities are) but the curvature jumps, so a
derivative with a small `margin_z` describes `tau_z` over that relative range only, and
finite differences with larger steps disagree with it (tests/test_margins.py: at
omega = 2, `margin_z` 4e-5, a switch meets $t_5$ at a relative change of 5e-5, and the
reference's differences with steps 1e-4 and 1e-5 differ by 0.8 %). `tau_5` after a
long transient typically has `margin_z` between 1e-4 and 3e-3: a switch every few
tenths of a time unit, against `tau_5` of a few hundred."""


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
    - `valid`: False for save times after the run stopped (lift-off, collision or step
      cap); those entries repeat the last state reached, never NaN.
    - `status`: `Status` code; `liftoff`: a normal force reached zero
      (strict: the run stopped there; paper reading: flagged, continued);
      `t_liftoff`: first lift-off time (`inf` if none).
    - `transversality`, `near_miss`: the smallest margins to a change of switching
      structure from $t = 0$ to each save time, in radians of drive phase, at located
      switches and at near misses (as in [`Measurement`][]; `inf`: none).
      `switch_gap`: the drive phase between each save time and the nearest located
      switch. The positions and energies at a save time have derivatives through a switch
      at that time (the velocities are continuous), the velocities do not.
    - `start`, `contact`: the initial condition and contact reading used.
    - `y`, `vy` (`contact="hop"` only, else `None`; SPEC §10): each mass's height and vertical
      velocity, `batch_shape + (n_save, 2)`; `n_land`: the landings of both masses per configuration;
      `zeno`: whether the Zeno rule made a rebound plastic. Under `"hop"`, `e` includes gravity
      $m_i y_i$ and the vertical kinetic energy, `e_d` the impacts' losses, `N1`, `N2` are the
      ground's reaction $m_i - V_i$ (on a mass in flight: $-m_i \\dot w_i$), `mode` counts a mass in
      flight as slipping and `f_ex` has no friction from it.
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
    transversality: Array
    near_miss: Array
    switch_gap: Array
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)
    y: Array | None = None
    vy: Array | None = None
    n_land: Array | None = None
    zeno: Array | None = None

    @property
    def smooth(self) -> Array:
        """Per save time: whether the saved state is a smooth function of the parameters
        there (`transversality` and `near_miss` at least `SMOOTH_MARGIN`, and for the
        velocities' sake `switch_gap` too; `valid`, and no lift-off)."""
        return _smooth_rows(self)

    @property
    def x(self) -> Array:
        """Positions with a trailing mass axis, `(..., n_save, 2)` (as a chain's)."""
        return _stack(self.x1, self.x2)

    @property
    def v(self) -> Array:
        """Velocities with a trailing mass axis, `(..., n_save, 2)`."""
        return _stack(self.v1, self.v2)

    def to_numpy(self) -> dict[str, np.ndarray]:
        """The array fields (the hopping ones only under `contact="hop"`) as numpy arrays."""
        fields = (
            k for k in self.__dataclass_fields__ if k not in ("start", "contact") and getattr(self, k) is not None
        )
        return {k: np.asarray(getattr(self, k)) for k in fields}


def _stack(a: Array, b: Array) -> Array:
    return jnp.stack([a, b], -1)


def _smooth_rows(r) -> Array:
    margin = jnp.minimum(jnp.minimum(r.transversality, r.near_miss), r.switch_gap)
    return (margin >= SMOOTH_MARGIN) & r.valid & ~r.liftoff[..., None]


def _smooth(r) -> Array:
    phases = jnp.minimum(r.transversality, r.near_miss) >= SMOOTH_MARGIN
    return phases & (r.margin_z >= SMOOTH_MARGIN_Z) & (r.status == 0) & ~r.liftoff


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
    - `transversality`, `near_miss`: how close the measured interval (from
      $t_\\text{start}$ to the end of the run) came to a change of switching structure,
      as drive phases in radians (`_exact` module docstring, "Margins"): the smallest
      margin at a located switch or stick-or-reverse decision, and at a near miss of an
      event function (a stuck mass almost breaking away, a slipping one almost
      stopping, a normal force almost reaching zero, $|X - X_0|$ turning back short of
      `z`); `inf` where there was none (the smoothed model: always).
    - `margin_z`: the time from $t_z$ to the nearest switch, or to the turning point of
      $|X - X_0|$, relative to `tau_z`: about the relative change of a parameter at which
      `tau_z` and `e_z` change their switching structure (0 where `z` was not reached).
      Where the margins are small, a derivative may hold over a small range only or jump:
      see `smooth`. The nearest switch is the last located one before $t_z$ (exact) or the next
      one as estimated at $t_z$ from each event function approaching zero (its Taylor quadratic,
      one Newton step: `_numerics.predict`). Under `contact="hop"` the switches include landings
      and lift-offs: a body in flight at $t_z$ contributes its landing (its height's quadratic, so
      a rising body's landing is not estimated) and no friction event, a grounded one its lift-off
      ($N_i$) and its stick or slip events (tests/test_hop_margin.py).

    Under `contact="hop"` only (else `None`; SPEC §10), over the regime window like the stick
    fractions: `flight_fraction`, shape `batch_shape + (2,)`, the fraction of it each mass is in
    flight; `landings_per_period`, the landings of both masses per actuation period $2\\pi/\\omega$;
    `highest_hop`, shape `batch_shape + (2,)`, each mass's greatest height (0 for a mass that never
    flies); `zeno`, whether the Zeno rule made a rebound plastic during the run. Under `"hop"` a
    run goes on through lift-off (`liftoff` and `t_liftoff` record the first), `e_d` includes the
    landings' losses and `delta_e` gravity's potential $m_i y_i$ and the vertical kinetic energy.

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
    transversality: Array
    near_miss: Array
    margin_z: Array
    z: float = eqx.field(static=True)
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)
    flight_fraction: Array | None = None
    landings_per_period: Array | None = None
    highest_hop: Array | None = None
    zeno: Array | None = None

    @property
    def smooth(self) -> Array:
        """Whether the results are smooth functions of the parameters here, so that their
        derivatives are derivatives: `transversality` and `near_miss` at least
        `SMOOTH_MARGIN`, `margin_z` at least `SMOOTH_MARGIN_Z`, `status` OK and no lift-off
        (False where the margins are NaN)."""
        return _smooth(self)

    @property
    def stick_fraction(self) -> Array:
        """Stick fractions with a trailing mass axis, `(..., 2)` (as a chain's)."""
        return _stack(self.stick_fraction1, self.stick_fraction2)

    def to_numpy(self) -> dict[str, np.ndarray]:
        """The array fields (the hopping ones only under `contact="hop"`) as numpy arrays."""
        skip = ("z", "start", "contact")
        fields = (k for k in self.__dataclass_fields__ if k not in skip and getattr(self, k) is not None)
        return {k: np.asarray(getattr(self, k)) for k in fields}


class ChainTrajectory(eqx.Module):
    """States of a chain of N masses saved at the requested times (compare [`Trajectory`][]).

    Per-time fields have shape `batch_shape + (n_save,)`, per-mass ones a trailing
    mass axis `(..., n_save, N)`, per-spring ones a trailing spring axis `(..., n_save, N-1)`.

    - `t`; `x`, `v`: positions and velocities; `stuck`: whether each mass is stuck.
    - `X`: centre of mass $\\sum m_i x_i / \\sum m_i$; `e_d`, `w`, `e`: dissipated energy and
      actuator work since $t = 0$, total energy (SPEC §8).
    - `N`: signed normal forces; `l0`: rest lengths; `tension`: spring tensions.
    - `valid`, `status`, `liftoff`, `t_liftoff`, `n_switch`, `transversality`, `near_miss`,
      `switch_gap`, `smooth`, `start`, `contact`: as in [`Trajectory`][].
    - `y`, `vy` (`contact="hop"` only, else `None`): each body's height and vertical velocity,
      `(..., n_save, N)`; `n_land`: the number of landings per configuration; `zeno`: whether the
      Zeno rule made a rebound plastic (a bouncing sequence that would not end). Under `"hop"`,
      `e` includes gravity $m_i y_i$ and the vertical kinetic energy, and `e_d` the impacts' losses.
    """

    t: Array
    x: Array
    v: Array
    stuck: Array
    X: Array
    e_d: Array
    w: Array
    e: Array
    N: Array
    l0: Array
    tension: Array
    valid: Array
    status: Array
    liftoff: Array
    t_liftoff: Array
    n_switch: Array
    transversality: Array
    near_miss: Array
    switch_gap: Array
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)
    y: Array | None = None
    vy: Array | None = None
    n_land: Array | None = None
    zeno: Array | None = None

    @property
    def smooth(self) -> Array:
        """As [`Trajectory.smooth`][locomotion_jax.Trajectory.smooth]."""
        return _smooth_rows(self)

    def to_numpy(self) -> dict[str, np.ndarray]:
        skip = ("start", "contact")
        fields = self.__dataclass_fields__
        return {k: np.asarray(getattr(self, k)) for k in fields if k not in skip and getattr(self, k) is not None}


class ChainMeasurement(eqx.Module):
    """The steady-state measurements of a chain (compare [`Measurement`][], whose fields these are),
    with `stick_fraction` of shape `batch_shape + (N,)`: the fraction of the window each mass is stuck.

    Under `contact="hop"` only (else `None`), over the same window: `flight_fraction`, shape
    `batch_shape + (N,)`, the fraction of it each body is in flight; `landings_per_period`, the
    landings of all bodies per actuation period $2\\pi/\\omega$; `highest_hop`, shape
    `batch_shape + (N,)`, each body's greatest height $y_i$ (0 for a body that never flies); `zeno`,
    whether the Zeno rule made a rebound plastic during the run (a bouncing sequence that would
    not end; the run goes on with the body on the ground)."""

    tau_z: Array
    e_z: Array
    reached: Array
    regime: Array
    mean_speed: Array
    cost_of_transport: Array
    stick_fraction: Array
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
    transversality: Array
    near_miss: Array
    margin_z: Array
    z: float = eqx.field(static=True)
    start: str = eqx.field(static=True)
    contact: str = eqx.field(static=True)
    flight_fraction: Array | None = None
    landings_per_period: Array | None = None
    highest_hop: Array | None = None
    zeno: Array | None = None

    @property
    def smooth(self) -> Array:
        """As [`Measurement.smooth`][locomotion_jax.Measurement.smooth]."""
        return _smooth(self)

    def to_numpy(self) -> dict[str, np.ndarray]:
        """The array fields (the hopping ones only under `contact="hop"`) as numpy arrays."""
        skip = ("z", "start", "contact")
        fields = (k for k in self.__dataclass_fields__ if k not in skip and getattr(self, k) is not None)
        return {k: np.asarray(getattr(self, k)) for k in fields}
