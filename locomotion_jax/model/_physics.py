"""The physics interface: what the engines ask of a mechanism on a line, one configuration at a time.

A mechanism ([`Chain`][locomotion_jax.Chain]; the paper's model is its two-body case)
hands the engines an [`AbstractPhysics`][]: its bodies' masses, damping and friction
laws, the actuation at a drive phase, and the loads on the bodies as functions of the
positions, with the first and second time derivatives of those loads along a motion.
The engines own everything else: the stick/slip decisions and the events (SPEC §2), the
integration, the dense output and the margins. So a new mechanism is one subclass, and
each engine is written once (jax-md passes its energy function into `nve` the same way;
diffrax's solvers see only an `AbstractTerm`).

Per-body and per-load values are tuples with one scalar per body (under `vmap`, one
vector over the configurations each), as the engines carry them.
"""

import abc
from typing import Any, NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array
from ._friction import AbstractFriction


ZENO_SPEED = 1e-3
"""The default Zeno speed of the hopping reading (SPEC §10): a rebound slower than this is plastic, so
that a sequence of ever shorter bounces ends after finitely many landings."""


Scalars = tuple[Array, ...]
"""One scalar per body (or per spring): under `vmap`, one vector over the configurations each."""


class Loads(NamedTuple):
    """The loads on the bodies at one instant: horizontal $F_i$ and signed normal $N_i$ (the
    ground's reaction; eq. 5 for the paper's model), and `aux`, what the mechanism keeps of its
    own for the rates and the energy there (a chain: its springs' geometry and tensions)."""

    F: Scalars
    N: Scalars
    aux: Any


class LoadRates(NamedTuple):
    """The first time derivatives $\\dot F_i$, $\\dot N_i$ along a motion, and the mechanism's own
    (`aux`) for the second derivatives and the actuator's power rate."""

    dF: Scalars
    dN: Scalars
    aux: Any


class AbstractPhysics(eqx.Module):
    """The forces of one configuration of a mechanism, as the exact and smoothed engines use them.

    Bodies $i = 0, \\dots, N-1$ move on a line with positions $x_i$ and velocities $v_i$:

    $$m_i \\dot v_i = F_i(t, x) - c_i v_i - \\text{friction}_i, \\qquad \\text{friction}_i \\text{ from } n_i(N_i)$$

    (eq. 9 generalised). The loads depend on time only through the actuation, which is
    periodic with base frequency `omega`: the engines carry the phase
    $(\\cos\\omega t, \\sin\\omega t)$ and ask for the actuation there ([`drive`][]). The
    loads' time derivatives along a motion ([`load_rates`][], [`load_second`][]) feed the
    engines' quintic dense output and event prediction; they are written out by the chain
    rule, which costs a fraction of a forward-mode derivative.

    **Fields** every physics has:

    - `m`, `im`, `c`: masses, inverse masses and damping per body;
    - `friction`: the [`AbstractFriction`][locomotion_jax.AbstractFriction] of each body, with
      that body's coefficients; `mu_f`, `mu_b`: its static limits forward and backward
      (`mu_b[i]` is `None` for an isotropic law: the stick margin is then $\\mu n_i - |F_i|$);
    - `omega`: the actuation's base frequency; `one`: the value 1.0 at run time (see [`keep`][]).
    """

    m: eqx.AbstractVar[Scalars]
    im: eqx.AbstractVar[Scalars]
    c: eqx.AbstractVar[Scalars]
    friction: eqx.AbstractVar[tuple[AbstractFriction, ...]]
    mu_f: eqx.AbstractVar[Scalars]
    mu_b: eqx.AbstractVar[tuple[Array | None, ...]]
    omega: eqx.AbstractVar[Array]
    one: eqx.AbstractVar[Array]

    @property
    def n_bodies(self) -> int:
        return len(self.m)

    @property
    def lane_width(self) -> int:
        """Elements per configuration in the engine's kernels (`dynamics._runs.default_lanes`): 1 for
        one entry per body (this default); the array layout's entry holds all its bodies."""
        return 1

    def bodies(self, x: Array) -> Scalars:
        """An array whose last axis runs over the bodies (or the springs) as the engines carry it:
        one entry per body (this default), or one entry holding them all (the array layout,
        `model._chain_array`, whose reductions over bodies the engine does within the entry)."""
        return tuple(x[..., i] for i in range(x.shape[-1]))

    def stacked(self, xs: Scalars) -> Array:
        """The inverse of [`bodies`][]: the entries as one array with the bodies on its last axis."""
        return jnp.stack(xs, -1)

    @property
    def anchored(self) -> bool:
        """Whether the loads depend on the bodies' absolute positions (a spring to a wall), not on
        their gaps alone: a steady gait's section state then holds the positions. This default:
        no."""
        return False

    def contact_values(self, q: tuple[Any, ...], fill: Any) -> tuple[Any, ...]:
        """The entries of `q`, a quantity per entry of [`bodies`][] over the normal loads (a load, its
        least over a step, a count of landings), of the bodies whose $N_i$ are the ground's reactions:
        this default, every body's. A body without ground contact has a placeholder $N_i$ for its
        friction law ([`Mechanism`][locomotion_jax.Mechanism]): one entry per body leaves its entry out,
        an entry that holds several bodies (the array layout) puts `fill` in its place, the identity
        of the reduction that follows (0 for a sum, `inf` for a least). The figures over the normal
        loads (a steady gait's `min_normal`, the optimisers' normal-force margin, the landings'
        count) read these (`model._physics.contact_loads`)."""
        return q

    def keep(self, x: Array) -> Array:
        """Materialise `x` once per iteration: XLA on the CPU recomputes a cheap value inside
        every kernel that consumes it, but never duplicates a division, so dividing by the
        run-time 1.0 pins `x` to one buffer (benchmarks/NOTES.md). Exact: the value is unchanged."""
        if x.dtype == jnp.bool_:
            return (x.astype(self.one.dtype) / self.one) > 0.5
        return x / self.one

    @abc.abstractmethod
    def drive(self, c1: Array, s1: Array) -> Any:
        """The actuation at phase $(\\cos\\omega t, \\sin\\omega t) = $ `(c1, s1)` with its first two
        time derivatives: a pytree that [`loads`][] and the rates read (entries may be `None`)."""

    @abc.abstractmethod
    def loads(self, drive: Any, x: Scalars, keep: Any = None) -> Loads:
        """The loads at positions `x` under the actuation `drive`. `keep`, if given, is
        [`keep`][] applied to the intermediates that several later stages share."""

    @abc.abstractmethod
    def load_rates(self, drive: Any, loads: Loads, xd: Scalars, keep: Any = None) -> LoadRates:
        """$\\dot F_i$, $\\dot N_i$ along the velocities `xd` (zero for a stuck body)."""

    @abc.abstractmethod
    def load_second(
        self, drive: Any, loads: Loads, rates: LoadRates, xd: Scalars, a: Scalars
    ) -> tuple[Scalars, Scalars]:
        """$\\ddot F_i$, $\\ddot N_i$ along the velocities `xd` and accelerations `a`."""

    @abc.abstractmethod
    def power(self, drive: Any, loads: Loads, v: Scalars) -> Array:
        """The power the actuators put in (eq. 16 generalised): $\\dot w$."""

    @abc.abstractmethod
    def power_rate(self, drive: Any, loads: Loads, rates: LoadRates, v: Scalars, a: Scalars) -> Array:
        """The time derivative of [`power`][] along the motion."""

    @abc.abstractmethod
    def energy(self, loads: Loads, v: Scalars) -> Array:
        """The mechanical energy $e$, kinetic plus stored (eq. 10 generalised)."""

    @abc.abstractmethod
    def centre_of_mass(self, x: Scalars) -> Array:
        """$X = \\sum_i m_i x_i / \\sum_i m_i$ (eq. 3 generalised): the position a measurement follows."""

    @abc.abstractmethod
    def initial_positions(self, start: str) -> Array:
        """Positions at $t = 0$, shape `(N,)`, for a named start (`"paper"`, eq. 14, or `"relaxed"`)."""

    def initial_velocities(self, start: str) -> Array | None:
        """Velocities at $t = 0$, shape `(N,)`, or `None` (at rest: the default). A
        [`Mechanism`][locomotion_jax.Mechanism] returns its own `v0` (SPEC §9)."""
        return None

    def velocity_forces(self, v: Scalars) -> Scalars | None:
        """Per body, the forces linear in the velocities besides ground damping (relative dampers:
        $+c(v_b - v_a)$ on `a`, $-c(v_b - v_a)$ on `b`), added to $F_i$; `None` (the default):
        none. Linear, so the engine takes their rates as this map of the accelerations and jerks."""
        return None

    def velocity_power(self, v: Scalars, u: Scalars) -> Array | None:
        """The bilinear form $\\sum c\\,(v_b - v_a)(u_b - u_a)$ of those forces: at `u = v` the power they
        dissipate (into $e_d$); `None` (the default): none."""
        return None

    def hop(self) -> tuple[Array, Array, Scalars, Array]:
        """What the hopping reading `contact="hop"` (SPEC §10) needs: the initial heights and
        vertical velocities (shape `(N,)` each), the restitution per body and the Zeno speed.
        A physics that implements it takes the bodies' heights as keyword arguments of its loads,
        `loads(..., y=)`, `load_rates(..., yd=)` and `load_second(..., yd=, ya=)`, which the engines
        pass under `"hop"` only (`model._physics.loads_at` and its siblings), so a physics without hopping
        keeps the signatures above. A mechanism whose loads do not depend on the heights raises
        `NotImplementedError`."""
        raise NotImplementedError(
            f"contact='hop' is not supported by {type(self).__name__} yet (its loads do not depend on the "
            "bodies' heights); use a Mechanism, or contact='strict' or 'paper'."
        )

    def fall(self, N: Scalars) -> Scalars:
        """Under `contact="hop"`, the vertical acceleration of each body in flight: $\\dot w_i = -N_i/m_i$
        ($m_i \\dot w_i = -m_i + V_i$ with the load $N_i = m_i - V_i$, SPEC §10). Linear in `N`: the
        engine takes the jerk in flight as `fall` of the loads' rates."""
        return tuple(-q * im for q, im in zip(N, self.im))

    def ride(self, q: Scalars) -> Scalars:
        """Under `contact="hop"`, per body, the entry of the per-body quantity `q` (a normal load, a
        height, a vertical velocity) of the body it flies with: its own by default. A body lifts off
        where this load falls through zero (its lift-off event function; a body whose load is
        negative starts in flight or flies on after a plastic landing), and a steady gait's section
        state gives it this height and vertical velocity. A selection of entries, so also the rates
        of the loads from the loads' rates."""
        return q

    def landing_masses(self) -> Scalars:
        """Under `contact="hop"`, per body, the mass whose fall a landing of it stops: its normal impulse
        is $P_n$ = this mass times the jump of $w_i$ (SPEC §10), which bounds the tangential impulse
        $\\mu_k P_n$. A body's own mass $m_i$ by default."""
        return self.m

    def gaps(self, x: Scalars) -> Scalars:
        """The gaps between bodies that must stay positive: the engine stops a run with
        `Status.COLLISION` where one is $\\le 0$ after a step, and refuses an initial state where
        one is. None by default (bodies on a line may pass each other, as a capsule's internal
        mass passes its rest point); a chain's are its neighbours' $x_{j+1} - x_j$."""
        return ()

    def kinks(self, x: Scalars, y: Scalars | None = None) -> tuple[tuple[Array, Array], ...]:
        """Pairs $(u, h)$ of a coordinate $u$ whose passage through zero turns a force over within
        $|u| \\lesssim |h|$ (a tilted spring's extension and vertical offset: its direction
        $(u, h)/\\sqrt{u^2 + h^2}$), at positions `x` (and heights `y` under `contact="hop"`). A
        step whose $u$ changes sign while moving more than $|h|/2$ (fewer than 4 steps over the
        turn's width $2|h|$) does not resolve the turn: the engine stops the run there with
        `Status.UNRESOLVED`. None by default."""
        return ()


class AbstractArrayPhysics(AbstractPhysics):
    """A physics in the array layout: one entry holding every body (shape `(N,)` per configuration)
    in each per-body tuple, whose reductions over bodies the engines do within the entry (a chain's,
    `model._chain_array`; a mechanism's, `model._mechanism_array`)."""

    @property
    def n_bodies(self) -> int:
        return self.m[0].shape[-1]

    @property
    def lane_width(self) -> int:
        return self.n_bodies

    def bodies(self, x: Array) -> Scalars:
        return (x,)

    def stacked(self, xs: Scalars) -> Array:
        return jnp.concatenate(xs, -1)


def contact_loads(P: AbstractPhysics, N: tuple[Any, ...], fill: Any) -> tuple[Any, ...]:
    """The entries of the normal loads `N` (or of a quantity over them) that are ground reactions, with
    `fill` for a body out of contact within an entry ([`AbstractPhysics.contact_values`][]); empty
    where no entry holds a body that touches the ground."""
    return P.contact_values(N, fill)


def least_contact_load(P: AbstractPhysics, N: Scalars, like: Array) -> Array:
    """$\\min_i N_i$ over the bodies on the ground ([`contact_loads`][]); `inf` (of `like`'s dtype) where
    no body touches the ground."""
    inf = jnp.asarray(jnp.inf, like.dtype)
    loads = contact_loads(P, N, inf)
    return jnp.min(jnp.stack(loads)) if loads else inf


# -- the engines' calls: the heights only under contact="hop" -------------------------------------


def loads_at(P: AbstractPhysics, drive: Any, x: Scalars, keep: Any = None, y: Scalars | None = None) -> Loads:
    """`P.loads`, with the heights `y` passed only where there are some (`contact="hop"`)."""
    return P.loads(drive, x, keep) if y is None else P.loads(drive, x, keep, y=y)  # type: ignore[call-arg]


def load_rates_at(
    P: AbstractPhysics, drive: Any, loads: Loads, xd: Scalars, keep: Any = None, yd: Scalars | None = None
) -> LoadRates:
    """`P.load_rates`, with the vertical velocities `yd` passed only under `contact="hop"`."""
    if yd is None:
        return P.load_rates(drive, loads, xd, keep)
    return P.load_rates(drive, loads, xd, keep, yd=yd)  # type: ignore[call-arg]


def load_second_at(
    P: AbstractPhysics, drive: Any, loads: Loads, rates: LoadRates, xd: Scalars, a: Scalars,
    yd: Scalars | None = None, ya: Scalars | None = None,
) -> tuple[Scalars, Scalars]:  # fmt: skip
    """`P.load_second`, with the vertical velocities and accelerations passed only under `contact="hop"`."""
    if yd is None and ya is None:
        return P.load_second(drive, loads, rates, xd, a)
    return P.load_second(drive, loads, rates, xd, a, yd=yd, ya=ya)  # type: ignore[call-arg]
