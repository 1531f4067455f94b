"""[`Mechanism`][locomotion_jax.Mechanism]: bodies on a line and the elements between them (SPEC §9).

Capsule (vibration-driven) robots, a mass on a spring to a wall, blocks pushed by external
forces: each is a set of bodies, some touching the ground (a friction law) and some
carried by another body or free, and of elements ([`Spring`][locomotion_jax.Spring],
[`TiltedSpring`][locomotion_jax.TiltedSpring], [`Force`][locomotion_jax.Force],
[`ExternalForce`][locomotion_jax.ExternalForce]) between
any of them or a `lj.WALL`. The front ends run it on the N-body
exact engine as they run a [`Chain`][locomotion_jax.Chain].
"""

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ValuesLike
from ._chain_array import LAYOUTS
from ._checks import broadcast_shape, is_concrete, real_array
from ._elements import AbstractElement, Damper, signal_checks, signal_nodes, Spring, TiltedSpring, WALL
from ._friction import AbstractFriction, Coulomb
from ._mechanism import AbstractMechanism
from ._mechanism_array import array_physics, ArrayMechanismPhysics
from ._mechanism_physics import ground_body, mechanism_physics, MechanismPhysics
from ._physics import ZENO_SPEED
from ._waveform import AbstractWaveform, Fourier, Spline


MEASURE_PERIODS = 20
"""A mechanism's default measurement start: this many periods of its actuation ($t = 0$ unactuated)."""


def _per_body(name: str, x: Any, n: int) -> Array:
    """A per-body field: a scalar, or an array whose last axis has length `n`."""
    arr = real_array(name, x)
    if arr.ndim == 0:
        return jnp.broadcast_to(arr, (n,))
    if arr.shape[-1] != n:
        raise ValueError(
            f"Invalid parameter {name!r}: its last axis must have length {n} (one value per body), got shape "
            f"{arr.shape}."
        )
    return arr


def _split_law(law: AbstractFriction, i: int, n: int) -> AbstractFriction:
    """Body `i`'s law from one law for every body (scalar coefficients, or a last axis of length `n`)."""

    def at(x: Array) -> Array:
        if jnp.ndim(x) == 0:
            return x
        if x.shape[-1] not in (1, n):
            raise ValueError(
                f"friction: a law given for every body needs scalar coefficients or a last axis of length {n} "
                f"(one per body), got shape {x.shape}."
            )
        return x[..., i if x.shape[-1] > 1 else 0]

    return jax.tree_util.tree_map(at, law)


def _x0(end: "int | str") -> str:
    return "0" if end == WALL else f"x0[{end}]"


def _named(end: "int | str") -> str:
    return "the wall" if end == WALL else f"body {end}"


def _body(i: Any, n: int) -> bool:
    return i == WALL or (isinstance(i, int) and 0 <= i < n)


class Mechanism(AbstractMechanism):
    """Bodies on a line with friction, carried bodies, springs, internal and external forces (SPEC §9).

    Body $i$ (mass $m_i$, position $x_i$, velocity $v_i$, ground damping $c_i$) obeys
    $m_i\\dot v_i = F_i - c_i v_i - \\text{friction}_i$, with $F_i$ the sum of every element's
    force on it. A body with a friction law touches the ground with the normal load
    $N_i = m_i + $ the weights it carries $-$ the tilted springs' vertical forces on it and on the
    bodies it carries, and sticks and slips as in SPEC §8 (under the strict reading a run stops
    where a load reaches 0; under `contact="hop"` the body flies). A body with
    none (`friction[i] = None`) feels no friction: `carried_by[i] = j` puts its weight on
    body $j$ (or on the body that finally carries $j$), as an internal mass loads its
    capsule; `carried_by[i] = None` leaves it free on the line.

    Elements ([`Spring`][locomotion_jax.Spring], [`TiltedSpring`][locomotion_jax.TiltedSpring],
    [`Damper`][locomotion_jax.Damper], [`Force`][locomotion_jax.Force],
    [`ExternalForce`][locomotion_jax.ExternalForce]) join any two bodies or a body and
    `lj.WALL` (a fixed point at $x = 0$). Their waveforms share one base
    frequency $\\omega$ (the engine follows one phase). Energy: $e = \\sum m_i v_i^2/2 +
    \\sum f^2/(2k)$ over springs (a tilted spring's $T^2/(2k)$; under `contact="hop"` gravity's
    $\\sum m_i y_i$ too), and $w = e_d + \\Delta e$ with $w$ the work of the forces and
    the actuated rest lengths (SPEC §9).

    Per-body fields have a last axis of length N (a scalar is broadcast); leading axes of
    any field are batch axes, broadcast against each other.

    **Arguments:**

    - `masses`: $m_i > 0$, shape `(..., N)`.
    - `friction`: one [`AbstractFriction`][locomotion_jax.AbstractFriction] for every body not
      carried (scalar or per-body coefficients), or a list with a law or `None` per body.
      Default: `Coulomb(0.7, 0.5)` for every body not carried.
    - `carried_by`: per body, the index of the body that carries it, or `None`.
    - `links`: the elements.
    - `c`: ground damping per body, $c_i \\ge 0$ (default 0).
    - `x0`, `v0`: the initial positions (default 0) and velocities (default 0) per body; a
      body in contact at rest starts stuck where its static limits hold.
    - `y0`, `w0`: the initial heights $y_i \\ge 0$ (default 0) and vertical velocities (default 0)
      per body, for the hopping reading `contact="hop"` (SPEC §10; ignored by `"strict"` and
      `"paper"`). A body without a friction law has no vertical motion of its own: its `y0` and
      `w0` are 0. A carried body rides in the body that finally carries it: it flies, falls and
      lands with it (its height and vertical velocity are that body's), and that body's landing
      stops the fall of both (its normal impulse, which bounds the tangential one, is theirs:
      $P_n = (m_i + \\text{the carried masses})(w^+ - w^-)$). A free body stays on the line.
    - `restitution`: Newton's coefficient $e_i \\in [0, 1]$ per body at a landing, $w^+ = -e_i w^-$
      (default 0, plastic); a carried body's is its carrier's.
    - `zeno_speed`: a rebound slower than this, $e_i |w^-| <$ `zeno_speed`, is plastic ($w^+ = 0$),
      so that a sequence of ever shorter bounces ends after finitely many landings (default
      `1e-3`, in the units of SPEC §8: $\\sqrt{g\\,\\bar l}$; $\\ge 0$).
    - `check`: validate concrete values (default); with `check=False` an invalid
      configuration is flagged `Status.INVALID` in its own result instead.
    - `layout`: how the engines (exact and smoothed) lay the bodies out, as a
      [`Chain`][locomotion_jax.Chain]'s: `"unrolled"` (one scalar per body, every mechanism), `"array"`
      (one array over the bodies and one over the elements of each kind, `model._mechanism_array`:
      compile time independent of N; every waveform, carried and free bodies and laws of several
      classes included), or `"auto"` (the default: the array layout from `ARRAY_FROM` (16) bodies
      on, on a CPU).

    **Raises:** `ValueError` naming the element and the body for bad structure (a body carried
    by itself or in a loop, a carried body with a friction law, a link to a missing body, an
    initial state of the wrong length, waveforms of different base frequencies) and, with
    `check`, for values out of range (`k <= 0`, $m_i \\le 0$, ...).

    !!! Example

        ```python
        osc = Mechanism(masses=[1.0], friction=Coulomb(1.0, 1.0),
                        links=[Spring(0, WALL, k=1.0, rest=0.0)], x0=[12.0], v0=[6.0])
        capsule = Mechanism(masses=[1.0, 0.5], friction=[Coulomb(0.5, 0.4), None], carried_by=[None, 0],
                            links=[Spring(0, 1, k=10.0), Force(0, 1, Sinusoid(a=0.6, omega=3.0, lbar=0.0))])
        ```
    """

    kind: ClassVar[str] = "mechanism"

    m: Array
    c: Array
    x0: Array
    v0: Array
    y0: Array
    w0: Array
    restitution: Array
    zeno_speed: Array
    friction: tuple[AbstractFriction | None, ...]
    links: tuple[AbstractElement, ...]
    carried_by: tuple[int | None, ...] = eqx.field(static=True)
    # How the engines lay the bodies out (`_chain_array.engine_physics`).
    layout: str = eqx.field(static=True, default="auto")

    def __init__(
        self,
        masses: ValuesLike,
        friction: "AbstractFriction | Sequence[AbstractFriction | None] | None" = None,
        carried_by: "Sequence[int | None] | None" = None,
        links: Sequence[AbstractElement] = (),
        c: ValuesLike = 0.0,
        x0: ValuesLike | None = None,
        v0: ValuesLike = 0.0,
        *,
        y0: ValuesLike = 0.0,
        w0: ValuesLike = 0.0,
        restitution: ValuesLike = 0.0,
        zeno_speed: ValuesLike = ZENO_SPEED,
        check: bool = True,
        layout: str = "auto",
    ):
        m = real_array("masses", masses)
        if m.ndim == 0 or m.shape[-1] < 1:
            raise ValueError(f"Invalid parameter 'masses': one value per body (last axis), got shape {m.shape}.")
        n = m.shape[-1]
        self.m = m
        self.c = _per_body("c", c, n)
        self.x0 = _per_body("x0", 0.0 if x0 is None else x0, n)
        self.v0 = _per_body("v0", v0, n)
        self.y0 = _per_body("y0", y0, n)
        self.w0 = _per_body("w0", w0, n)
        self.restitution = _per_body("restitution", restitution, n)
        self.zeno_speed = real_array("zeno_speed", zeno_speed)
        carried = [None] * n if carried_by is None else list(carried_by)
        if len(carried) != n:
            raise ValueError(f"carried_by: one entry per body ({n}), got {len(carried)}.")
        for i, j in enumerate(carried):
            if j is None:
                continue
            if isinstance(j, bool) or not isinstance(j, int) or not 0 <= j < n:
                raise ValueError(f"carried_by: body {i} is carried by {j!r}, which is not a body (0 to {n - 1}).")
            if j == i:
                raise ValueError(f"carried_by: body {i} is carried by itself.")
        for i in range(n):
            ground_body(tuple(carried), i)  # refuses a loop, naming its bodies
        self.carried_by = tuple(carried)
        self.friction = self._laws(friction, n)
        for i, j in enumerate(carried):
            if j is not None and self.friction[i] is not None:
                raise ValueError(
                    f"friction: body {i} is carried by body {j} (no ground contact) but has a friction law; "
                    f"give None for it."
                )
            if j is not None and self.friction[ground_body(self.carried_by, i)] is None:
                g = ground_body(self.carried_by, i)
                raise ValueError(
                    f"carried_by: body {i} is carried by body {g}, which does not touch the ground (no friction law)."
                )
        links = tuple(links)
        for k, el in enumerate(links):
            if not isinstance(el, AbstractElement):
                kinds = "a Spring, TiltedSpring, Damper, Force or ExternalForce"
                raise TypeError(f"links[{k}] must be {kinds}, got {type(el).__name__}.")
            ends = el.bodies()
            for e in ends:
                if not _body(e, n):
                    raise ValueError(
                        f"links[{k}] {el.describe()}: body {e} does not exist (the mechanism has bodies 0 to {n - 1})."
                    )
            if len(ends) == 2 and ends[0] == ends[1]:
                raise ValueError(f"links[{k}] {el.describe()}: joins body {ends[0]} to itself.")
        self.links = links
        self._check_frequencies()
        if layout not in LAYOUTS:
            raise ValueError(f"Invalid parameter 'layout': expected one of {LAYOUTS}, got {layout!r}.")
        self.layout = layout
        _ = self.batch_shape  # fields whose batch axes do not broadcast are refused here, named
        if check and is_concrete(self):
            self.validate()

    @staticmethod
    def _laws(friction: Any, n: int) -> tuple[AbstractFriction | None, ...]:
        if friction is None or isinstance(friction, AbstractFriction):
            law = Coulomb() if friction is None else friction
            return tuple(_split_law(law, i, n) for i in range(n))
        laws = tuple(friction)
        if len(laws) != n:
            raise ValueError(f"friction: one law or None per body ({n}), got {len(laws)}.")
        for i, law in enumerate(laws):
            if law is not None and not isinstance(law, AbstractFriction):
                raise TypeError(f"friction[{i}] (body {i}) must be an AbstractFriction or None, got {law!r}.")
        return laws

    def _check_frequencies(self) -> None:
        """All waveforms share one base frequency (the engine follows one phase $\\omega t$)."""
        waves = [(k, el, w) for k, el in enumerate(self.links) for w in el.signals() if isinstance(w, AbstractWaveform)]
        if not waves or not all(is_concrete(w.omega) for _, _, w in waves):
            return
        k0, el0, w0 = waves[0]
        for k, el, w in waves[1:]:
            try:
                mine, first = np.broadcast_arrays(np.asarray(w.omega), np.asarray(w0.omega))
                same = np.array_equal(mine, first, equal_nan=True)  # a NaN is refused by name later
            except ValueError:
                same = False
            if not same:
                raise ValueError(
                    f"links[{k}] {el.describe()}: its waveform's omega={np.asarray(w.omega).tolist()!r} differs from "
                    f"the mechanism's base frequency omega={np.asarray(w0.omega).tolist()!r} (links[{k0}] "
                    f"{el0.describe()}); all waveforms of one mechanism share it (use harmonics of it in a Fourier)."
                )

    # -- structure and batching -------------------------------------------------------

    def _nodes(self) -> list[tuple[str, Array, int]]:
        """Every array field: `(name for messages, array, number of trailing non-batch axes)`."""
        out = [
            ("masses", self.m, 1),
            ("c", self.c, 1),
            ("x0", self.x0, 1),
            ("v0", self.v0, 1),
            ("y0", self.y0, 1),
            ("w0", self.w0, 1),
            ("restitution", self.restitution, 1),
            ("zeno_speed", self.zeno_speed, 0),
        ]
        for i, law in enumerate(self.friction):
            if law is not None:
                out += [(f"{name} (body {i})", x, 0) for name, x in law.fields().items()]
        for k, el in enumerate(self.links):
            out += [(f"{name} of links[{k}]", x, 0) for name, x in el.values().items()]
            for s in el.signals():
                out += [(f"waveform of links[{k}]", x, tail) for x, tail in signal_nodes(s)]
        return out

    @property
    def n_masses(self) -> int:
        """The number of bodies $N$ (the name the chain path uses)."""
        return self.m.shape[-1]

    @property
    def n_bodies(self) -> int:
        return self.m.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        shapes = {}
        for j, (name, x, tail) in enumerate(self._nodes()):
            shape = jnp.shape(x)
            key = name if name not in shapes else f"{name} (array {j})"  # a waveform has several arrays
            shapes[key] = shape[: len(shape) - tail]
        return broadcast_shape(shapes)

    @property
    def dtype(self) -> Any:
        return jnp.result_type(*jax.tree_util.tree_leaves(self))

    def drawing(self) -> Any:
        """What [`animate`][locomotion_jax.run._animation.animate] draws of the mechanism: its bodies (in ground
        contact, carried or free) and springs (`run._mechanism_animation.Drawing`)."""
        from ..run._mechanism_animation import mechanism_drawing

        return mechanism_drawing(self)

    def broadcast(self) -> "Mechanism":
        """Every field broadcast to `batch_shape` (and its own trailing axes) with one dtype."""
        b, dt = self.batch_shape, self.dtype
        tails = {id(x): tail for _, x, tail in self._nodes()}
        leaves, tree = jax.tree_util.tree_flatten(self)
        full = lambda x, tail: jnp.broadcast_to(jnp.asarray(x, dt), b + jnp.shape(x)[jnp.ndim(x) - tail :])
        return jax.tree_util.tree_unflatten(tree, [full(x, tails.get(id(x), 0)) for x in leaves])

    def __getitem__(self, index: Any) -> "Mechanism":
        """Index the batch axes of the broadcast mechanism."""
        idx = index if isinstance(index, tuple) else (index,)
        if len(idx) > len(self.batch_shape):
            raise IndexError(f"too many indices for a mechanism batch of shape {self.batch_shape}.")
        return jax.tree_util.tree_map(lambda x: x[idx], self.broadcast())

    @classmethod
    def stack(cls, items: "list[Mechanism]") -> "Mechanism":
        """Stack mechanisms of the same structure (bodies, laws, elements) along a new leading batch axis."""
        if len(items) == 0:
            raise ValueError("Mechanism.stack needs at least one Mechanism.")
        items = [q.broadcast() for q in items]
        structures = {jax.tree_util.tree_structure(q) for q in items}
        shapes = {tuple(x.shape for x in jax.tree_util.tree_leaves(q)) for q in items}
        if len(structures) > 1 or len(shapes) > 1:
            raise ValueError("Mechanism.stack: the mechanisms differ in structure (bodies, laws, elements) or shape.")
        return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *items)

    # -- derived quantities -------------------------------------------------------------

    def waveforms(self) -> list[AbstractWaveform]:
        """The elements' waveforms, in the order of `links`."""
        return [s for el in self.links for s in el.signals() if isinstance(s, AbstractWaveform)]

    def describe(self) -> str:
        carried = sum(j is not None for j in self.carried_by)
        return f"mechanism of {self.n_bodies} bodies ({carried} carried), {len(self.links)} links"

    def attributes(self) -> dict[str, str]:
        """The kind, each body's friction law (`none` for a carried body) and each link's `describe()`."""
        laws = ", ".join("none" if law is None else type(law).__name__ for law in self.friction)
        return {"kind": self.kind, "friction": laws, "links": ", ".join(el.describe() for el in self.links)}

    # -- the actuated signals (what the optimisers design) ----------------------------------

    def actuated(self) -> list[int]:
        """The indices in `links` of the elements driven by a waveform (a spring's rest length, an
        internal or an external force): the mechanism's actuated signals, in this order."""
        return [j for j, el in enumerate(self.links) if any(isinstance(s, AbstractWaveform) for s in el.signals())]

    @property
    def n_signals(self) -> int:
        """The number of actuated signals (`actuated`)."""
        return len(self.actuated())

    def with_fourier(self, cos: Array, sin: Array, omega: Array) -> "Mechanism":
        """A copy with each actuated element's waveform replaced by the Fourier series of
        coefficients `cos[..., j, :]`, `sin[..., j, :]` (absolute units) and base frequency `omega`,
        its mean (the old waveform's `lbar`) kept. Leading axes of the coefficients are batch axes."""
        return self._driven(lambda j, lbar: Fourier(cos[..., j, :], sin[..., j, :], omega, lbar))

    def with_spline(self, control: Array, omega: Array) -> "Mechanism":
        """A copy with each actuated element's waveform replaced by the periodic cubic B-spline of
        control values `control[..., j, :]` (absolute units, about the old waveform's `lbar`) and base
        frequency `omega`. Leading axes of the control values are batch axes."""
        return self._driven(lambda j, lbar: Spline(control[..., j, :], omega, lbar))

    def _driven(self, signal: Any) -> "Mechanism":
        """A copy whose `j`-th actuated element takes `signal(j, lbar)` in place of its waveform."""
        links = list(self.links)
        for j, i in enumerate(self.actuated()):
            el = links[i]
            name = "rest" if isinstance(el, (Spring, TiltedSpring)) else "waveform"
            links[i] = eqx.tree_at(lambda e: getattr(e, name), el, signal(j, getattr(el, name).lbar))
        return eqx.tree_at(lambda m: m.links, self, tuple(links))

    def physics(self) -> MechanismPhysics:
        """The mechanism's [`AbstractPhysics`][locomotion_jax.AbstractPhysics]: what the engine integrates it with."""
        return mechanism_physics(self)

    def array_physics(self) -> ArrayMechanismPhysics:
        """The mechanism's physics in the array layout (`model._mechanism_array`)."""
        return array_physics(self)

    @property
    def omega(self) -> Array:
        """The base frequency of the actuation (0 without any waveform), batch shape."""
        waves = self.waveforms()
        w = waves[0].omega if waves else jnp.zeros((), self.dtype)
        return jnp.broadcast_to(jnp.asarray(w, self.dtype), self.batch_shape)

    @property
    def total_mass(self) -> Array:
        return self.m.sum(-1)

    @property
    def t_start(self) -> Array:
        """Default start of a measurement: `MEASURE_PERIODS` periods of the actuation (0 without one)."""
        w = self.omega
        return jnp.where(w > 0, MEASURE_PERIODS * 2 * math.pi / jnp.where(w > 0, w, 1), 0.0)

    def time_scales(self, waveform: Any = None) -> list[Any]:
        """The resolution guards' scales (`AbstractMechanism.time_scales`; the elements carry
        their waveforms) of a flat batch:

        - the forcing: the highest harmonic of every actuated element and external force;
        - $2\\pi/\\omega_\\max$ of the free linearised bodies: every spring, wall springs
          included, in the stiffness matrix, over the diagonal mass matrix;
        - the damping time $\\min_i m_i/c_i$, each body's $c_i$ with its dampers' (a bound of the
          fastest decay of $M^{-1} C$ by its rows);
        - a friction law's own time (`AbstractFriction.time_scale`), over the normal load of
          the body: $(m_i/N_i)\\,v_s/\\mu_s$ with $N_i$ the weights it carries."""
        from . import _scales as sc

        n, size = self.n_bodies, self.batch_shape[0]
        scales = []
        waves = self.waveforms()
        if waves:
            fastest = max(waves, key=sc.harmonics)
            scales.append(sc.forcing(fastest, sc.flat(fastest.omega, size)))
        K = jnp.zeros((size, n, n), self.dtype)
        k_max = jnp.zeros((size,), self.dtype)
        for el in self.links:
            k = el.values().get("k")  # a spring's stiffness (other elements have none)
            if k is None:
                continue
            k = sc.flat(k, size)
            k_max = jnp.maximum(k_max, k)
            ends = [e for e in el.bodies() if e != WALL]
            for a in ends:
                K = K.at[:, a, a].add(k)
            if len(ends) == 2:
                K = K.at[:, ends[0], ends[1]].add(-k).at[:, ends[1], ends[0]].add(-k)
        natural = 2 * math.pi / sc.free_frequency(self.m, K)
        scales.append(sc.TimeScale("k", "natural period 2*pi/w_max of the free bodies and springs", natural,
                                   sc.STEPS_PER_PERIOD, "period",
                                   {"k (largest)": k_max, "masses (smallest)": self.m.min(-1)}))  # fmt: skip
        # Dampers bound the fastest decay of M^-1 C by its rows (Gershgorin): a wall damper adds
        # its c to its body's, one between two bodies 2c to each (its diagonal and off-diagonal).
        c = jnp.broadcast_to(self.c, (size, n))
        for el in self.links:
            if isinstance(el, Damper):
                for e in el.bodies():
                    if e != WALL:
                        c = c.at[:, e].add((2 if WALL not in el.bodies() else 1) * sc.flat(el.c, size))
        scales.append(sc.TimeScale("c", "damping time min_i m_i/c_i (dampers included)", jnp.min(self.m / c, -1),
                                   sc.STEPS_PER_TIME, "damping time", {"c (largest)": c.max(-1)}))  # fmt: skip
        for i, law in enumerate(self.friction):
            scale = None if law is None else law.time_scale()
            if scale is None:
                continue
            load = sum(self.m[:, j] for j in range(n) if ground_body(self.carried_by, j) == i)
            t = sc.flat(scale[0], size) * self.m[:, i] / load
            scales.append(sc.TimeScale("v_s", f"friction time (m_i/N_i) v_s/mu_s of body {i}", t, sc.STEPS_PER_TIME,
                                       "friction time", {"v_s": sc.flat(scale[1], size)}))  # fmt: skip
        return scales

    def start_scale(self) -> Any:
        from ._scales import start_span

        what = f"Mechanism.t_start ({MEASURE_PERIODS} periods of the actuation)"
        return start_span(self.t_start, what, {"omega": self.omega})

    # -- validation -----------------------------------------------------------------------

    def _checks(self) -> list[tuple[str, str, Array, str, Any]]:
        """`(owner, parameter, valid mask, valid range, values)`, finite values first."""
        out: list[tuple[str, str, Array, str, Any]] = []
        per_body = [("masses", self.m), ("c", self.c), ("x0", self.x0), ("v0", self.v0), ("y0", self.y0),
                    ("w0", self.w0), ("restitution", self.restitution)]  # fmt: skip
        for name, x in per_body:
            for i in range(self.n_bodies):
                out.append((f"body {i}", name, jnp.isfinite(x[..., i]), "finite", x[..., i]))
        out.append(("the mechanism", "zeno_speed", jnp.isfinite(self.zeno_speed), "finite", self.zeno_speed))
        out.append(("the mechanism", "zeno_speed", self.zeno_speed >= 0, "zeno_speed >= 0", self.zeno_speed))
        for i in range(self.n_bodies):
            out.append((f"body {i}", "masses", self.m[..., i] > 0, "m_i > 0", self.m[..., i]))
            out.append((f"body {i}", "c", self.c[..., i] >= 0, "c_i >= 0", self.c[..., i]))
            y, w, e = self.y0[..., i], self.w0[..., i], self.restitution[..., i]
            out.append((f"body {i}", "y0", y >= 0, "y0_i >= 0 (a height above the ground)", y))
            out.append((f"body {i}", "restitution", (e >= 0) & (e <= 1), "0 <= e_i <= 1", e))
            if self.friction[i] is None:  # carried or free (SPEC 9): no vertical motion
                out.append((f"body {i}", "y0", y == 0, "0 (a body without a friction law has no vertical motion)", y))
                out.append((f"body {i}", "w0", w == 0, "0 (a body without a friction law has no vertical motion)", w))
        for i, law in enumerate(self.friction):
            if law is None:
                continue
            owner = f"{type(law).__name__} of body {i}"
            fields = law.fields()
            out += [(owner, name, jnp.isfinite(x), "finite", x) for name, x in fields.items()]
            ranges = law.valid_ranges()
            out += [(owner, name, ok, ranges.get(name, "valid"), fields[name]) for name, ok in law.validity().items()]
        waves = self.waveforms()
        for k, el in enumerate(self.links):
            owner = f"links[{k}] {el.describe()}"
            for name, x in el.values().items():
                out.append((owner, name, jnp.isfinite(x), "finite", x))
            if isinstance(el, (Spring, TiltedSpring)):
                out.append((owner, "k", el.k > 0, "k > 0", el.k))
            if isinstance(el, TiltedSpring):
                # A horizontal one's ends must not meet (its `gaps`): a start with `b` at or behind
                # `a` would stop at its first step.
                at = lambda e: jnp.zeros_like(self.x0[..., 0]) if e == WALL else self.x0[..., int(e)]
                name, u = f"{_x0(el.b)} - {_x0(el.a)}", at(el.b) - at(el.a)
                valid = (f"> 0 where d = 0 (a horizontal tilted spring keeps {_named(el.b)} ahead of "
                         f"{_named(el.a)}; one with d != 0 lets its ends pass)")  # fmt: skip
                out.append((owner, name, (el.d != 0) | (u > 0), valid, u))
            if isinstance(el, Damper):
                out.append((owner, "c", el.c >= 0, "c >= 0", el.c))
            for s in el.signals():
                for name, ok, valid in signal_checks(s):
                    out.append((owner, name, ok, valid, getattr(s, name, s)))
                if isinstance(s, AbstractWaveform) and s is not waves[0]:
                    same = s.omega == waves[0].omega
                    out.append((owner, "omega", same, "the mechanism's base frequency (the first waveform's omega)",
                                s.omega))  # fmt: skip
        return out

    def is_valid(self) -> Array:
        """Traceable mask (batch shape) of configurations inside the valid ranges."""
        ok = jnp.ones(self.batch_shape, bool)
        for *_, mask, _, _ in self._checks():
            ok = ok & jnp.broadcast_to(mask, self.batch_shape)
        return ok

    def validate(self) -> "Mechanism":
        """Raise `ValueError` at the first invalid value, naming the element or body, the parameter,
        the batch index and the valid range."""
        shape = self.batch_shape
        for owner, name, mask, valid, value in self._checks():
            bad = ~np.broadcast_to(np.asarray(mask), shape)
            if bad.any():
                where = tuple(int(i) for i in np.argwhere(bad)[0]) if shape else ()
                at = f" at batch index {where}" if shape else ""
                v = np.broadcast_to(np.asarray(value), shape)[where] if np.ndim(value) <= len(shape) else value
                got = np.asarray(v).tolist()
                raise ValueError(f"Invalid parameter {name!r} of {owner}{at}: got {name}={got!r}; the valid range is "
                                 f"{valid}.")  # fmt: skip
        return self
