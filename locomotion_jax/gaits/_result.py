"""The one result class of a steady-gait solve, [`Gait`][], for every mechanism, and the paper's names
it shares with [`Branch`][] (`PaperNames`)."""

from typing import Any

import equinox as eqx

from .._custom_types import Array
from .._results import _paper_name, _two_bodies, BODIES


def _section_name(name: str, index: int, doc: str) -> property:
    """A paper's name for one entry of the section state (`u` is `state[..., 0]`) of a `Gait` or a
    `Branch`, refused where there are not two bodies or the section state is not the gap and the velocities."""

    def get(result: Any) -> Array:  # a Gait or a Branch
        _two_bodies(result, name)
        if result.state.shape[-1] not in (3, 7):  # (u, v1, v2), heights appended under "hop"
            raise ValueError(
                f"`{name}` names the gap state (u, v1, v2) of two bodies; this section state holds "
                f"{result.state.shape[-1]} numbers (a mechanism anchored to the wall: positions then velocities)."
            )
        return result.state[..., index]

    return property(get, doc=doc)


class PaperNames(eqx.Module):
    """The paper's names of the two-mass model on a result with a section `state` and a per-body
    `stick_fraction` ([`Gait`][], [`Branch`][]): `u`, `v1`, `v2` (the state's columns) and
    `stick_fraction1`, `stick_fraction2`, refused with a `ValueError` for other than two bodies."""

    state: eqx.AbstractVar[Array]
    stick_fraction: eqx.AbstractVar[Array]

    @property
    def n_bodies(self) -> int:
        """The number of bodies $N$ (the length of the trailing body axis)."""
        return self.stick_fraction.shape[-1]

    u = _section_name("u", 0, "The paper's gap $u = x_2 - x_1$ at the section: `state[..., 0]` (two bodies only).")
    v1 = _section_name("v1", 1, "The paper's $v_1$ at the section: `state[..., 1]` (two bodies only).")
    v2 = _section_name("v2", 2, "The paper's $v_2$ at the section: `state[..., 2]` (two bodies only).")
    stick_fraction1 = _paper_name(
        "stick_fraction1", "stick_fraction", 0, "Fraction of the period mass 1 is stuck (two bodies only)."
    )
    stick_fraction2 = _paper_name(
        "stick_fraction2", "stick_fraction", 1, "Fraction of the period mass 2 is stuck (two bodies only)."
    )


class Gait(PaperNames):
    """Steady gaits (periodic orbits) per configuration, of any mechanism ([`steady_gait`][]).

    Per-configuration fields have shape `batch`; per-body ones a trailing body axis `batch + (N,)`.

    - `status` ([`GaitStatus`][]) and `converged` (`status == CONVERGED`).
    - `k`: the gait's period in actuation periods (0 when none converged); `period`: $kT$.
    - `mean_speed`: $\\Delta X / (kT)$ over one gait period (eq. 4), exact for the orbit.
    - `e_d`, `work`: dissipated energy (eq. 15) and actuator work (eq. 16) per gait period (equal
      on the orbit: the energy (eq. 10) is periodic).
    - `cost_of_transport`: $e_d / |\\Delta X|$, energy per unit distance (as `Measurement`'s
      $e_z/z$; `inf` for a gait that does not move: one that dissipates nothing, or an anchored
      mechanism's, whose `mean_speed` is 0 since its positions are periodic).
    - `stick_fraction`: fraction of the gait period each mass is stuck, `batch + (N,)`;
      `regime`: [`Regime`][] SSL if any mass is stuck longer than `STICK_TOL`, else SL.
    - `n_switch`: switches per gait period; `n_land`: landings per gait period (0 but under
      `contact="hop"`; a carried body's are its carrier's, counted once).
    - `state`: the orbit's state at the section $\\omega t \\equiv 0$: gaps then velocities
      $(u_1, \\dots, u_{N-1}, v_1, \\dots, v_N)$, `batch + (2N - 1,)` (the paper's $(u, v_1, v_2)$);
      under `contact="hop"` the heights and vertical velocities $(y_1, \\dots, y_N, w_1, \\dots, w_N)$
      appended, `batch + (4N - 1,)`; a mechanism anchored to the wall: positions then velocities
      $(x_1, \\dots, x_N, v_1, \\dots, v_N)$, `batch + (2N,)`.
    - `monodromy`: $M = \\partial\\Phi_k/\\partial y$ in the order of `state`; `multipliers`: its
      eigenvalues (complex, by decreasing modulus); `stable`: all moduli below 1. A mechanism
      anchored to the wall with a body stuck all period has a family of orbits (that body holds
      anywhere within its stick range): a multiplier 1, not `stable`, and the orbit found is the
      member that Newton's method (least-norm steps there) reaches from the transient's end.
    - `residual`: $\\|\\Phi_k(y) - y\\|_\\infty$ at the last iterate (NaN where nothing was solved:
      invalid parameters, a lift-off in the transient); `n_iter`: Newton iterations.
    - `liftoff`: a normal force reached zero on the orbit or the transient (paper reading: flagged,
      the orbit is still computed).
    - `slip_margin`: the smallest negated stick margin $\\max(F_i - \\mu_{s,\\mathrm{fwd}} n_i,
      -F_i - \\mu_{s,\\mathrm{bwd}} n_i)$ (eq. 7) at the instants where a slipping mass's velocity
      reaches zero on the orbit: $> 0$, every such mass reverses (SL); $< 0$, one sticks (SSL);
      `inf` if no velocity reaches zero, `-inf` if a mass is stuck all period. It is continuous
      where a stick interval shrinks to nothing, so that its zero is the SSL/SL boundary.
    - `min_normal`: the smallest signed normal force $\\min_t \\min_i N_i$ (eq. 5) on the orbit over
      the bodies on the ground (its zero is the onset of lift-off; a body without ground contact
      has no normal load: `inf` where no body touches the ground).
    - `contact`: the contact reading solved; `names`: `"paper"` for the paper's model (the CLI
      then reports the paper's names), else `"bodies"`.

    The paper's names of the two-mass model are properties: `u`, `v1`, `v2` (the section state) and
    `stick_fraction1`, `stick_fraction2`; they raise a `ValueError` on a gait of other than two bodies.
    """

    status: Array
    converged: Array
    k: Array
    period: Array
    mean_speed: Array
    e_d: Array
    work: Array
    cost_of_transport: Array
    stick_fraction: Array
    regime: Array
    n_switch: Array
    n_land: Array
    state: Array
    monodromy: Array
    multipliers: Array
    stable: Array
    residual: Array
    n_iter: Array
    liftoff: Array
    slip_margin: Array
    min_normal: Array
    contact: str = eqx.field(static=True)
    names: str = eqx.field(static=True, default=BODIES)
