"""Result containers with named fields (compare diffrax `Solution`)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array
from ._status import mode_code


SMOOTH_MARGIN = 0.05
"""The smallest `transversality` and `near_miss` (radians of drive phase; `_engine` module
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


PAPER = "paper"
"""`names` of a result of the paper's model ([`Params`][locomotion_jax.Params]): `to_numpy` names its
arrays as the paper does (`x1`, `v1`, `x2`, `v2`, `N1`, `N2`, `mode`, `l0`, `stick_fraction1`, ...)."""

BODIES = "bodies"
"""`names` of a result of any other mechanism: `to_numpy` names its arrays as the fields are."""

_TRAJECTORY_PAPER_KEYS = (
    "t", "x1", "v1", "x2", "v2", "X", "e_d", "w", "e", "mode", "l0", "N1", "N2", "f_ex", "valid", "status",
    "liftoff", "t_liftoff", "n_switch", "transversality", "near_miss", "switch_gap", "y", "vy", "n_land", "zeno",
)  # fmt: skip
_TRAJECTORY_BODIES_KEYS = (
    "t", "x", "v", "stuck", "X", "e_d", "w", "e", "N", "l0", "tension", "valid", "status", "liftoff",
    "t_liftoff", "n_switch", "transversality", "near_miss", "switch_gap", "y", "vy", "n_land", "zeno",
)  # fmt: skip
MEASUREMENT_KEYS: tuple[str, ...] = (
    "tau_z", "e_z", "reached", "regime", "mean_speed", "cost_of_transport", "stick_fraction", "e_d", "work",
    "delta_e", "balance", "liftoff", "t_liftoff", "status", "t_start", "X_start", "n_steps", "n_switch",
    "transversality", "near_miss", "margin_z", "flight_fraction", "landings_per_period", "highest_hop", "zeno",
)  # fmt: skip
"""The keys of `Measurement.to_numpy()` of any mechanism but the paper's model, in order (the hopping
ones only under `contact="hop"`): the array fields."""
MEASUREMENT_PAPER_KEYS: tuple[str, ...] = tuple(
    k for name in MEASUREMENT_KEYS for k in ((name + "1", name + "2") if name == "stick_fraction" else (name,))
)
"""The keys of `Measurement.to_numpy()` for the paper's model, in order (the hopping ones only under
`contact="hop"`): the fields, with `stick_fraction` as `stick_fraction1`, `stick_fraction2`."""


def _two_bodies(result, name: str) -> None:
    """Refuse a paper's name (`x1`, `N2`, `mode`, ...) on a result that has not two bodies."""
    n = result.n_bodies
    if n != 2:
        raise ValueError(
            f"`{name}` is the paper's name for the two-mass model; this result has {n} bodies "
            "(read the fields with a trailing body axis, as `x[..., 0]`, `stick_fraction[..., 1]`)."
        )


def _paper_name(name: str, field: str, index: int, doc: str) -> property:
    """A paper's name for one column of a per-body or per-spring field (`x1` is `x[..., 0]`),
    refused on a result that has not two bodies."""

    def get(result) -> Array:
        _two_bodies(result, name)
        return getattr(result, field)[..., index]

    return property(get, doc=doc)


def _arrays(result, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """`keys` read from `result` as numpy arrays, without those that are `None` (the hopping ones
    outside `contact="hop"`, a chain's `f_ex`, the paper's model's `tension`)."""
    values = ((k, getattr(result, k)) for k in keys)
    return {k: np.asarray(v) for k, v in values if v is not None}


class Trajectory(eqx.Module):
    """States of a mechanism saved at the requested times (one configuration or a batch):
    the paper's two-mass model, a chain of N masses or any other mechanism.

    Per-time fields have shape `batch_shape + (n_save,)`, per-body ones a trailing body axis
    `batch_shape + (n_save, N)`, per-spring ones a trailing spring axis `(..., n_save, N - 1)`;
    per-configuration fields have shape `batch_shape`.

    - `t`: save times; `x`, `v`: positions and velocities; `stuck`: whether each body is stuck.
    - `X`: centre of mass $\\sum m_i x_i / \\sum m_i$ (eq. 4). `e_d`: dissipated energy since
      $t=0$ (eq. 15). `w`: actuator work since $t=0$ (eq. 16). `e`: total energy (eq. 10).
    - `N`: signed normal forces (eq. 5); `rest_length`: each spring's rest length $\\ell_0$;
      `tension`: each spring's tension (`None` for the paper's model).
    - `f_ex`: the horizontal friction plus damping force on the system (eq. 17; the paper's
      model only, else `None`).
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
    - `start`, `contact`: the initial condition and contact reading used. `names`: how
      `to_numpy` names the arrays (`PAPER` for the paper's model).
    - `y`, `vy` (`contact="hop"` only, else `None`; SPEC §10): each body's height and vertical
      velocity, `(..., n_save, N)`; `n_land`: the landings of all bodies per configuration;
      `zeno`: whether the Zeno rule made a rebound plastic (a bouncing sequence that would not
      end). Under `"hop"`, `e` includes gravity $m_i y_i$ and the vertical kinetic energy, `e_d`
      the impacts' losses, `N` the ground's reaction $m_i - V_i$ (on a body in flight:
      $-m_i \\dot w_i$), a body in flight is not `stuck` and `f_ex` has no friction from it.

    The paper's names of the two-mass model (two bodies only; `ValueError` otherwise):
    `x1`, `v1`, `x2`, `v2`, `N1`, `N2`, `l0` (the one spring's rest length) and `mode`
    (the contact mode of Sect. 2.2, `Mode`: 0 both stick, 1 both slip, 2 $m_1$ slips,
    3 $m_2$ slips; a body in flight counts as slipping).
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
    rest_length: Array
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
    names: str = eqx.field(static=True, default=BODIES)
    tension: Array | None = None
    f_ex: Array | None = None
    y: Array | None = None
    vy: Array | None = None
    n_land: Array | None = None
    zeno: Array | None = None

    @property
    def n_bodies(self) -> int:
        """The number of bodies $N$ (the length of the trailing body axis)."""
        return self.x.shape[-1]

    @property
    def smooth(self) -> Array:
        """Per save time: whether the saved state is a smooth function of the parameters
        there (`transversality` and `near_miss` at least `SMOOTH_MARGIN`, and for the
        velocities' sake `switch_gap` too; `valid`, and no lift-off)."""
        return _smooth_rows(self)

    x1 = _paper_name("x1", "x", 0, "The paper's $x_1$: `x[..., 0]` (two bodies only).")
    v1 = _paper_name("v1", "v", 0, "The paper's $v_1$: `v[..., 0]` (two bodies only).")
    x2 = _paper_name("x2", "x", 1, "The paper's $x_2$: `x[..., 1]` (two bodies only).")
    v2 = _paper_name("v2", "v", 1, "The paper's $v_2$: `v[..., 1]` (two bodies only).")
    N1 = _paper_name("N1", "N", 0, "The paper's $N_1$: `N[..., 0]` (two bodies only).")
    N2 = _paper_name("N2", "N", 1, "The paper's $N_2$: `N[..., 1]` (two bodies only).")
    l0 = _paper_name("l0", "rest_length", 0, "The paper's $\\ell_0(t)$: `rest_length[..., 0]` (two bodies only).")

    @property
    def mode(self) -> Array:
        """The contact mode of Sect. 2.2 (`Mode`) from the two bodies' `stuck` flags (two bodies only)."""
        _two_bodies(self, "mode")
        return mode_code(self.stuck[..., 0], self.stuck[..., 1])

    def to_numpy(self) -> dict[str, np.ndarray]:
        """The array fields as numpy arrays (the hopping ones only under `contact="hop"`), named as
        the paper does for the paper's model (`x1`, `v1`, `x2`, `v2`, `mode`, `l0`, `N1`, `N2`,
        `f_ex`, ...), else as the fields (with the rest lengths as `l0`)."""
        if self.names == PAPER:
            return _arrays(self, _TRAJECTORY_PAPER_KEYS)
        out = _arrays(self, tuple("rest_length" if k == "l0" else k for k in _TRAJECTORY_BODIES_KEYS))
        return {("l0" if k == "rest_length" else k): v for k, v in out.items()}


def _smooth_rows(r) -> Array:
    margin = jnp.minimum(jnp.minimum(r.transversality, r.near_miss), r.switch_gap)
    return (margin >= SMOOTH_MARGIN) & r.valid & ~r.liftoff[..., None]


def _smooth(r) -> Array:
    phases = jnp.minimum(r.transversality, r.near_miss) >= SMOOTH_MARGIN
    return phases & (r.margin_z >= SMOOTH_MARGIN_Z) & (r.status == 0) & ~r.liftoff


class Measurement(eqx.Module):
    """The paper's measurements (Sects. 3-5; SPEC §5), per configuration, of any mechanism.

    The measurement starts at $t_\\text{start}$ = 80 periods of the lowest
    natural frequency and runs until $|X - X(t_\\text{start})| = z$ or the horizon.
    Per-configuration fields have shape `batch_shape`, per-body ones a trailing body axis
    `batch_shape + (N,)`.

    - `tau_z`: time to travel `z` after $t_\\text{start}$; **`inf` when not
      reached** (then `reached` is False).
    - `e_z`: dissipated energy (eq. 15) over the same interval; `inf` when not reached.
    - `reached`: whether $|X - X(t_\\text{start})|$ reached `z` within the horizon.
    - `regime`: `Regime` code: 1 SSL, 0 SL (the paper's window rule over
      `window` = 25), -1 undetermined (the run stopped before the window ended).
    - `mean_speed`: signed $\\Delta X / \\Delta t$ over the measured interval
      (to `tau_z`, or to the horizon/stop when not reached).
    - `cost_of_transport`: `e_z / z` (`inf` when not reached).
    - `stick_fraction`: per body, the fraction of the window it is stuck (the paper's
      `stick_fraction1`, `stick_fraction2` for two bodies).
    - `e_d`, `work`, `delta_e`: dissipated energy, actuator work and change of
      total energy over the measured interval; `balance` $= w - e_d - \\Delta e$
      (eq. 16; zero up to the integration error).
    - `liftoff`, `t_liftoff`: as in `Trajectory`. `status`: `Status` code.
    - `t_start`, `X_start`: the measurement's start time and centre of mass.
    - `n_steps`: integrator iterations used; `n_switch`: mode switches.
    - `transversality`, `near_miss`: how close the measured interval (from
      $t_\\text{start}$ to the end of the run) came to a change of switching structure,
      as drive phases in radians (`_engine` module docstring, "Margins"): the smallest
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
    - `z`, `start`, `contact`: as measured. `names`: how `to_numpy` names the arrays
      (`PAPER` for the paper's model).

    Under `contact="hop"` only (else `None`; SPEC §10), over the regime window like the stick
    fractions: `flight_fraction`, per body, the fraction of it each body is in flight;
    `landings_per_period`, the landings of all bodies per actuation period $2\\pi/\\omega$;
    `highest_hop`, per body, its greatest height (0 for a body that never flies); `zeno`, whether
    the Zeno rule made a rebound plastic during the run (a bouncing sequence that would not end;
    the run goes on with the body on the ground). Under `"hop"` a run goes on through lift-off
    (`liftoff` and `t_liftoff` record the first), `e_d` includes the landings' losses and
    `delta_e` gravity's potential $m_i y_i$ and the vertical kinetic energy.

    Quantities that cannot be computed because the run stopped before
    $t_\\text{start}$ (lift-off, invalid input) are NaN, and `status` says why.
    """

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
    names: str = eqx.field(static=True, default=BODIES)
    flight_fraction: Array | None = None
    landings_per_period: Array | None = None
    highest_hop: Array | None = None
    zeno: Array | None = None

    @property
    def n_bodies(self) -> int:
        """The number of bodies $N$ (the length of `stick_fraction`'s trailing axis)."""
        return self.stick_fraction.shape[-1]

    @property
    def smooth(self) -> Array:
        """Whether the results are smooth functions of the parameters here, so that their
        derivatives are derivatives: `transversality` and `near_miss` at least
        `SMOOTH_MARGIN`, `margin_z` at least `SMOOTH_MARGIN_Z`, `status` OK and no lift-off
        (False where the margins are NaN)."""
        return _smooth(self)

    stick_fraction1 = _paper_name(
        "stick_fraction1", "stick_fraction", 0, "Mass 1's stick fraction: `stick_fraction[..., 0]` (two bodies only)."
    )
    stick_fraction2 = _paper_name(
        "stick_fraction2", "stick_fraction", 1, "Mass 2's stick fraction: `stick_fraction[..., 1]` (two bodies only)."
    )

    def to_numpy(self) -> dict[str, np.ndarray]:
        """The array fields as numpy arrays (the hopping ones only under `contact="hop"`), with the
        stick fractions of the paper's model as `stick_fraction1`, `stick_fraction2`."""
        return _arrays(self, MEASUREMENT_PAPER_KEYS if self.names == PAPER else MEASUREMENT_KEYS)
