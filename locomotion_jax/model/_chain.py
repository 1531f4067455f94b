"""A chain of N masses joined by N-1 actuated springs (SPEC §8); N = 2 is the paper's model."""

import math
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.core  # (jax.core.Tracer) for type checkers
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ValuesLike
from ._actuator import AbstractActuator, RestLength
from ._chain_array import array_physics, ArrayChainPhysics, LAYOUTS
from ._chain_physics import chain_physics, ChainPhysics
from ._checks import broadcast_shape, real_array, related
from ._elements import signal_fields
from ._friction import AbstractFriction, Coulomb
from ._mechanism import AbstractMechanism
from ._params import normal_positive, Params
from ._springwaves import check_waveforms, spring_signals, SpringFourier, to_spring_fourier, TravellingWave
from ._waveform import AbstractWaveform, Spline


def _per(name: str, x: ValuesLike, n: int, what: str) -> Array:
    """A per-mass or per-spring field: a scalar, or an array whose last axis has length `n` (or 1)."""
    x = real_array(name, x)
    if x.ndim == 0:
        return x[None]
    if x.shape[-1] not in (1, n):
        raise ValueError(
            f"Invalid parameter {name!r}: its last axis must have length {n} (one value per {what}) or be a "
            f"scalar; got shape {x.shape}."
        )
    return x


class Chain(AbstractMechanism):
    """A chain of masses $m_0, \\dots, m_{N-1}$ on a line, $x_0 < \\dots < x_{N-1}$, joined by springs (SPEC §8).

    Spring $j$ joins masses $j$ and $j+1$: stiffness $k_j$, vertical offset $d_j$, mean
    rest length $\\bar\\ell_j$, and an actuation signal $s_j(t)$ (the `waveforms`) that the
    `actuator` turns into a rest length $\\ell_{0,j}(t) = \\bar\\ell_j + s_j(t)$ ([`RestLength`][],
    the paper's) or an internal force $f_j(t) = s_j(t)$ ([`InternalForce`][]). With
    $u_j = x_{j+1} - x_j$, $\\ell_j = \\sqrt{u_j^2 + d_j^2}$ (eq. 2), $T_j = k_j(\\ell_j - \\ell_{0,j})$,
    $f_{x,j} = T_j u_j/\\ell_j$ and $f_{y,j} = T_j d_j/\\ell_j$:

    $$F_i = f_{x,i} - f_{x,i-1} + f_i - f_{i-1}, \\qquad N_i = m_i - f_{y,i} + f_{y,i-1}$$

    (missing springs count zero; eqs. 5 and 8 for $N = 2$). Each mass has damping $c_i$
    and the `friction` law.

    Per-mass fields have a last axis of length N and per-spring fields of length N-1
    (a scalar is broadcast); leading axes are batch axes, broadcast against each other.

    **Arguments:**

    - `masses`: $m_i > 0$, shape `(..., N)`, $N \\ge 2$.
    - `k`, `d`, `lbar`: per spring ($k_j > 0$, $|d_j| < \\bar\\ell_j$, $\\bar\\ell_j > 0$); `lbar=None`
      takes the mean rest lengths of Sinusoid/Fourier waveforms, else 3.
    - `c`: damping per mass, $c_i \\ge 0$.
    - `waveforms`: a [`TravellingWave`][], a [`SpringFourier`][], one waveform for every spring
      (`Sinusoid`, `Fourier`, `Spline`, any [`AbstractWaveform`][locomotion_jax.AbstractWaveform]), or a
      list of them (one per spring, a common base frequency). Default: no actuation.
    - `friction`: an [`AbstractFriction`][] with per-mass coefficients; default `Coulomb(0.7, 0.5)`.
    - `actuator`: [`RestLength`][] (default), [`InternalForce`][] or an actuator of your own; one for the
      whole batch, its fields numbers (constants of the compiled program).
    - `layout`: how the engines (exact and smoothed) lay the masses out: `"unrolled"` (one scalar per mass:
      fastest for a few masses, but compile time and cost per mass grow with N), `"array"` (one
      array over the masses: compile time independent of N; every waveform and every contact
      reading), or `"auto"` (default): the array layout from `ARRAY_FROM` (16) masses on for
      `measure` and `simulate` on a CPU (`ARRAY_FROM_ACCELERATOR`, 4, on a GPU), and from
      `GAIT_ARRAY_FROM` (3) on for steady gaits, continuation and the optimiser
      (docs/performance.md, "Long chains").
    - `check`: validate concrete values (default); invalid values raise `ValueError` naming the
      parameter, the mass or spring index and the valid range. With `check=False` an invalid
      configuration is flagged `Status.INVALID` in its own result instead.

    !!! Example

        ```python
        worm = Chain(masses=[1.0, 1.0, 1.0], k=50.0, d=0.5, lbar=3.0, c=0.01,
                     waveforms=TravellingWave(a=0.05, omega=2.0, phi=2 * jnp.pi / 3),
                     friction=AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7))
        paper = Chain.from_params(Params(omega=2.0))   # the paper's two-mass model
        ```
    """

    kind: ClassVar[str] = "chain"

    m: Array
    c: Array
    k: Array
    d: Array
    lbar: Array
    waves: SpringFourier
    friction: AbstractFriction
    actuator: AbstractActuator = eqx.field(static=True)
    # Each spring's waveform where one is neither a Sinusoid nor a Fourier (a Spline): it drives
    # the spring itself and `waves` keeps only the base frequency; `None`: `waves` holds the actuation.
    signals: tuple[AbstractWaveform, ...] | None = None
    # How the engines lay the masses out (`_chain_array.engine_physics`).
    layout: str = eqx.field(static=True, default="auto")

    def __init__(
        self,
        masses: ValuesLike,
        k: ValuesLike = 50.0,
        d: ValuesLike = 0.5,
        lbar: ValuesLike | None = None,
        c: ValuesLike = 0.01,
        waveforms: Any = None,
        friction: AbstractFriction | None = None,
        actuator: AbstractActuator | None = None,
        *,
        check: bool = True,
        layout: str = "auto",
    ):
        m = real_array("masses", masses)
        if m.ndim == 0 or m.shape[-1] < 2:
            raise ValueError(
                f"Invalid parameter 'masses': a chain needs N >= 2 masses (last axis); got shape {m.shape}."
            )
        n = m.shape[-1]
        self.m = m
        self.c = _per("c", c, n, "mass")
        self.k = _per("k", k, n - 1, "spring")
        self.d = _per("d", d, n - 1, "spring")
        if waveforms is None:
            waveforms = TravellingWave(0.0, 0.0)
        if check:
            check_waveforms(waveforms)  # named by the waveform's own fields (phi is lost in the normal form)
        self.waves, wave_lbar = to_spring_fourier(waveforms, n - 1)
        self.signals = spring_signals(waveforms, n - 1)
        if lbar is None:
            lbar = 3.0 if wave_lbar is None else wave_lbar
        elif wave_lbar is not None and _concrete(wave_lbar) and _concrete(lbar):
            if not np.allclose(np.asarray(wave_lbar), np.asarray(lbar)):
                raise ValueError(
                    f"Invalid parameter 'lbar': got lbar={lbar!r}, but the waveforms' mean rest lengths are "
                    f"{np.asarray(wave_lbar).tolist()}; give one of them (lbar=None takes the waveforms')."
                )
        self.lbar = _per("lbar", lbar, n - 1, "spring")
        friction = Coulomb() if friction is None else friction
        if not isinstance(friction, AbstractFriction):
            raise TypeError(f"friction must be an AbstractFriction, got {type(friction).__name__}.")
        for name, value in friction.fields().items():
            _per(name, value, n, "mass")
        self.friction = friction
        actuator = RestLength() if actuator is None else actuator
        if not isinstance(actuator, AbstractActuator):
            raise TypeError(f"actuator must be an AbstractActuator, got {type(actuator).__name__}.")
        for path, value in jax.tree_util.tree_flatten_with_path(actuator)[0]:
            if np.ndim(value):  # the actuator is static: one for the whole batch
                name = type(actuator).__name__ + jax.tree_util.keystr(path)
                raise ValueError(f"Invalid parameter 'actuator': its fields are numbers, one actuator for the whole "
                                 f"batch; got {name} of shape {np.shape(value)}.")  # fmt: skip
        self.actuator = actuator
        if layout not in LAYOUTS:
            raise ValueError(f"Invalid parameter 'layout': expected one of {LAYOUTS}, got {layout!r}.")
        self.layout = layout
        _ = self.batch_shape  # fields whose batch axes do not broadcast are refused here, named
        if check and all(_concrete(x) for x in jax.tree_util.tree_leaves(self)):
            self.validate()

    @classmethod
    def from_params(cls, params: Params, waveform: Any = None) -> "Chain":
        """The two-mass chain of the paper's model: $m_1 = 2\\hat m$, $m_2 = 2(1 - \\hat m)$, eq. (13)."""
        p = params.broadcast()
        from ._waveform import Sinusoid

        wave = Sinusoid(p.a, p.omega, p.lbar) if waveform is None else waveform
        return cls(
            masses=jnp.stack([p.m1, p.m2], -1), k=p.k[..., None], d=p.d[..., None], lbar=p.lbar[..., None],
            c=p.c[..., None], waveforms=wave, friction=Coulomb(p.mu_s[..., None], p.mu_k[..., None]), check=False,
        )  # fmt: skip

    @classmethod
    def stack(cls, items: "list[Chain]") -> "Chain":
        """Stack chains of the same N, friction law, actuator and layout along a new leading batch axis."""
        if len(items) == 0:
            raise ValueError("Chain.stack needs at least one Chain.")
        items = [c.broadcast() for c in items]
        H = max(c.waves.harmonics for c in items)
        pad = lambda w: jnp.pad(w, [(0, 0)] * (w.ndim - 1) + [(0, H - w.shape[-1])])
        items = [eqx.tree_at(lambda c: (c.waves.cos, c.waves.sin), c, (pad(c.waves.cos), pad(c.waves.sin)))
                 for c in items]  # fmt: skip
        structures = {jax.tree_util.tree_structure(c) for c in items}
        shapes = {tuple(x.shape for x in jax.tree_util.tree_leaves(c)) for c in items}
        if len(structures) > 1 or len(shapes) > 1:
            raise ValueError("Chain.stack: the chains differ in N, friction law, actuator, layout or batch shape.")
        return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *items)

    # -- shapes ------------------------------------------------------------------

    @property
    def n_masses(self) -> int:
        return self.m.shape[-1]

    @property
    def omega(self) -> Array:
        """The waveforms' base frequency (batch shape)."""
        return self.waves.omega

    @property
    def batch_shape(self) -> tuple[int, ...]:
        fields = {"masses": self.m, "c": self.c, "k": self.k, "d": self.d, "lbar": self.lbar, **self.friction.fields()}
        shapes = {n: x.shape[:-1] for n, x in fields.items()}
        shapes |= {"waveforms (cos)": self.waves.cos.shape[:-2], "waveforms (sin)": self.waves.sin.shape[:-2],
                   "omega": self.waves.omega.shape}  # fmt: skip
        for j, w in enumerate(self.signals or ()):
            shapes |= {f"waveforms[{j}] ({n})": x.shape[: x.ndim - tail] for n, x, tail in signal_fields(w)}
        return broadcast_shape(shapes)

    @property
    def dtype(self) -> Any:
        return jnp.result_type(*jax.tree_util.tree_leaves(self))

    def broadcast(self) -> "Chain":
        """Every field broadcast to `batch_shape` (and its mass or spring axis) with one dtype."""
        b, dt, n = self.batch_shape, self.dtype, self.n_masses
        full = lambda x, tail: jnp.broadcast_to(jnp.asarray(x, dt), b + tail)
        fr = jax.tree_util.tree_map(lambda x: full(x if jnp.ndim(x) else x[None], (n,)), self.friction)
        H = self.waves.harmonics
        waves = SpringFourier(full(self.waves.cos, (n - 1, H)), full(self.waves.sin, (n - 1, H)),
                              full(self.waves.omega, ()))  # fmt: skip
        out = eqx.tree_at(
            lambda c: (c.m, c.c, c.k, c.d, c.lbar, c.waves, c.friction), self,
            (full(self.m, (n,)), full(self.c, (n,)), full(self.k, (n - 1,)), full(self.d, (n - 1,)),
             full(self.lbar, (n - 1,)), waves, fr),
        )  # fmt: skip
        if self.signals is None:
            return out

        def signal(w: AbstractWaveform) -> AbstractWaveform:
            fields = signal_fields(w)
            arrays = [full(x, x.shape[x.ndim - tail :]) for _, x, tail in fields]
            return eqx.tree_at(lambda v: [getattr(v, name) for name, _, _ in fields], w, arrays)

        return eqx.tree_at(lambda c: c.signals, out, tuple(map(signal, self.signals)))

    def with_waves(self, waves: SpringFourier) -> "Chain":
        """A copy actuated by the Fourier coefficients `waves` (any `signals` dropped)."""
        out = eqx.tree_at(lambda c: c.waves, self, waves)
        return out if self.signals is None else eqx.tree_at(lambda c: c.signals, out, None)

    @property
    def n_signals(self) -> int:
        """The number of actuated signals: one per spring, its rest length about `lbar`."""
        return self.n_masses - 1

    def with_fourier(self, cos: Array, sin: Array, omega: Array) -> "Chain":
        """A copy whose spring `j` is driven by the Fourier series of coefficients `cos[..., j, :]`,
        `sin[..., j, :]` (absolute units, about its `lbar`) and base frequency `omega`."""
        return self.with_waves(SpringFourier(cos, sin, omega))

    def with_spline(self, control: Array, omega: Array) -> "Chain":
        """A copy whose spring `j` is driven by the periodic cubic B-spline of control values
        `control[..., j, :]` (absolute units, about its `lbar`) and base frequency `omega`. Leading
        axes of the control values are batch axes."""
        S = self.n_signals
        lbar = jnp.broadcast_to(jnp.asarray(self.lbar, control.dtype), (S,))
        signals = tuple(Spline(control[..., j, :], omega, lbar[j]) for j in range(S))
        zeros = jnp.zeros(jnp.shape(omega) + (S, 1), control.dtype)
        out = self.with_waves(SpringFourier(zeros, zeros, omega))  # the normal form keeps omega only
        return eqx.tree_at(lambda c: c.signals, out, signals, is_leaf=lambda x: x is None)

    def __getitem__(self, index: Any) -> "Chain":
        """Index the batch axes of the broadcast chain."""
        nb = len(self.batch_shape)
        idx = index if isinstance(index, tuple) else (index,)
        if len(idx) > nb:
            raise IndexError(f"too many indices for a chain batch of shape {self.batch_shape}.")
        return jax.tree_util.tree_map(lambda x: x[idx], self.broadcast())

    # -- derived quantities --------------------------------------------------------

    def physics(self) -> ChainPhysics:
        """The chain's [`AbstractPhysics`][locomotion_jax.AbstractPhysics]: what the engines integrate it with."""
        P = chain_physics(self)
        if self.signals is None:
            return P
        return eqx.tree_at(lambda P: P.waveforms, P, self.signals, is_leaf=lambda x: x is None)

    def array_physics(self) -> "ArrayChainPhysics":
        """The chain's physics in the array layout (`model._chain_array`)."""
        return array_physics(self)

    @property
    def total_mass(self) -> Array:
        return self.m.sum(-1)

    def natural_frequencies(self) -> Array:
        """Natural frequencies of the linearised chain with mass $i$ held, for each $i$: shape `(..., N, N-1)`.

        Springs of stiffness $k_j$ between neighbours (the geometry factor ignored, as in
        eqs. 11-12). For $N = 2$: $(\\omega_{n2}, \\omega_{n3})$, i.e. $\\sqrt{k/m_1}$ and $\\sqrt{k/m_2}$.
        """
        c = self.broadcast()
        n = self.n_masses
        K = jnp.zeros(c.k.shape[:-1] + (n, n), c.k.dtype)
        j = jnp.arange(n - 1)
        K = K.at[..., j, j].add(c.k).at[..., j + 1, j + 1].add(c.k)
        K = K.at[..., j, j + 1].add(-c.k).at[..., j + 1, j].add(-c.k)
        s = 1 / jnp.sqrt(c.m)
        Kn = K * s[..., :, None] * s[..., None, :]
        # Row `held` of `keep`: every mass but that one. One batched eigensolver call for all of them:
        # on a CPU, concurrent calls of the batched eigensolver inside one program can deadlock
        # XLA's thread pool (each waits for workers that the other holds).
        keep = np.array([[i for i in range(n) if i != held] for held in range(n)])
        return jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(Kn[..., keep[:, :, None], keep[:, None, :]]), 0))

    @property
    def omega_min(self) -> Array:
        """The lowest natural frequency with one mass held, over which mass (SPEC §5 for $N = 2$)."""
        return self.natural_frequencies().min((-2, -1))

    @property
    def t_start(self) -> Array:
        """Default start of the measurement: 80 periods of [`omega_min`][] (Sect. 3 for $N = 2$)."""
        return 80 * 2 * math.pi / self.omega_min

    def time_scales(self, waveform: Any = None) -> list[Any]:
        """The resolution guards' scales (`AbstractMechanism.time_scales`; a chain carries its
        waveforms): the forcing's highest harmonic (of its fastest waveform, `_scales.harmonics`),
        $2\\pi/\\omega_\\max$ of the free linearised chain (by eigenvalue interlacing no lower than
        any of `natural_frequencies`), the damping time $\\min_i m_i/c_i$ and, under a `Stribeck`
        law, $v_s/\\mu_s$: the time over which friction alone (normal force $m_i g$, $g = 1$)
        changes a speed by $v_s$."""
        from . import _scales as sc

        n = self.n_masses
        j = jnp.arange(n - 1)
        K = jnp.zeros(self.k.shape[:-1] + (n, n), self.k.dtype)
        K = K.at[..., j, j].add(self.k).at[..., j + 1, j + 1].add(self.k)
        K = K.at[..., j, j + 1].add(-self.k).at[..., j + 1, j].add(-self.k)
        natural = 2 * math.pi / sc.free_frequency(self.m, K)
        # The springs' own waveforms where they have them (`signals`), else their Fourier coefficients.
        fastest = self.waves if self.signals is None else max(self.signals, key=sc.harmonics)
        scales = [
            sc.forcing(fastest, jnp.broadcast_to(fastest.omega, self.batch_shape)),
            sc.TimeScale("k", "natural period 2*pi/w_max of the free chain", natural, sc.STEPS_PER_PERIOD, "period",
                         {"k (largest)": self.k.max(-1), "masses (smallest)": self.m.min(-1)}),
            sc.TimeScale("c", "damping time min_i m_i/c_i", jnp.min(self.m / self.c, -1), sc.STEPS_PER_TIME,
                         "damping time", {"c (largest)": self.c.max(-1)}),
        ]  # fmt: skip
        law = self.friction.time_scale()
        if law is not None:
            t, v_s = (jnp.min(jnp.broadcast_to(x, self.m.shape), -1) for x in law)
            scales.append(sc.TimeScale("v_s", "Stribeck time v_s/mu_s", t, sc.STEPS_PER_TIME, "Stribeck time",
                                       {"v_s (smallest)": v_s}))  # fmt: skip
        return scales

    def start_scale(self) -> Any:
        from ._scales import start_span

        what = "Chain.t_start (80 periods of the lowest natural frequency with one mass held)"
        return start_span(self.t_start, what, {"k (smallest)": self.k.min(-1), "masses (largest)": self.m.max(-1)})

    # -- validation ------------------------------------------------------------------

    def _checks(self) -> list[tuple[str, Array, str, str]]:
        """`(name, valid mask (..., axis), valid range, index kind)` of every constraint."""
        c = self.broadcast()
        fr = c.friction
        stroke = c.stroke()
        # Finite values first: a NaN is reported as the parameter that holds it, not as a relation it breaks.
        checks = [(name, jnp.isfinite(value), "finite", "mass")
                  for name, value in [("masses", c.m), ("c", c.c), *fr.fields().items()]]  # fmt: skip
        checks += [(name, jnp.isfinite(value), "finite", "spring") for name, value in [("k", c.k), ("d", c.d),
                                                                                        ("lbar", c.lbar)]]  # fmt: skip
        checks.append(("waveforms", jnp.isfinite(c.waves.cos).all(-1) & jnp.isfinite(c.waves.sin).all(-1), "finite",
                       "spring"))  # fmt: skip
        if c.signals is not None:
            checks.append(("waveforms", jnp.stack([w.is_valid() for w in c.signals], -1), "valid", "spring"))
        omega_ok = jnp.isfinite(c.waves.omega) & (c.waves.omega >= 0)
        checks += [
            ("omega", jnp.broadcast_to(omega_ok[..., None], c.k.shape), "omega >= 0 and finite", "spring"),
            ("masses", normal_positive(c.m), "m_i > 0, a normal float", "mass"),
            ("c", c.c >= 0, "c_i >= 0", "mass"),
            ("k", normal_positive(c.k), "k_j > 0, a normal float", "spring"),
            ("lbar", normal_positive(c.lbar, jnp, 2), "lbar_j > 0 with lbar_j**2 a normal float", "spring"),
            ("d", jnp.abs(c.d) < c.lbar, "|d_j| < lbar_j", "spring"),
        ]
        if isinstance(self.actuator, RestLength):
            checks.append(("waveforms", stroke < c.lbar, "stroke (sum of amplitudes) < lbar_j", "spring"))
        ranges = fr.valid_ranges()
        for name, ok in fr.validity().items():
            checks.append((name, ok, ranges.get(name, "valid"), "mass"))
        return checks

    def stroke(self) -> Array:
        """The largest excursion of each spring's signal, shape `(..., N - 1)` (broadcast chain)."""
        if self.signals is None:
            return self.waves.stroke()
        strokes = [w.stroke() for w in self.signals]
        shape = jnp.broadcast_shapes(*(jnp.shape(q) for q in strokes))
        return jnp.stack([jnp.broadcast_to(q, shape) for q in strokes], -1)

    def is_valid(self) -> Array:
        """Traceable mask (batch shape) of configurations inside the valid ranges."""
        ok = jnp.ones(self.batch_shape, bool)
        for _, mask, _, _ in self._checks():
            ok = ok & jnp.broadcast_to(mask, self.batch_shape + mask.shape[-1:]).all(-1)
        return ok

    def validate(self) -> "Chain":
        """Raise `ValueError` at the first invalid value: parameter, mass or spring index, batch index, range."""
        shape = self.batch_shape
        c = self.broadcast()
        values = {"masses": c.m, "c": c.c, "k": c.k, "d": c.d, "lbar": c.lbar, "waveforms": c.stroke(),
                  "omega": jnp.broadcast_to(c.waves.omega[..., None], c.k.shape), **c.friction.fields()}  # fmt: skip
        for name, mask, valid, kind in self._checks():
            bad = ~np.broadcast_to(np.asarray(mask), shape + mask.shape[-1:])
            if bad.any():
                where = tuple(int(i) for i in np.argwhere(bad)[0])
                at = f" at batch index {where[:-1]}" if shape else ""
                shown = [(n, float(np.asarray(values[n])[where])) for n in (name, *related(name, valid, values))]
                got_s = ": got " + ", ".join(f"{'stroke' if n == 'waveforms' else n}={v!r}" for n, v in shown)
                raise ValueError(
                    f"Invalid parameter {name!r} of {kind} {where[-1]}{at}{got_s}; the valid range is {valid}."
                )
        return self

    def check_section(self, y: Any) -> None:
        """The gaps $u_j$, the first `N - 1` entries of a section state, must be positive (SPEC §8: the
        masses stay in order)."""
        if np.any(np.asarray(y)[: self.n_masses - 1] <= 0):
            raise ValueError(
                f"start: the gaps u_j must be > 0 (the masses in order along the chain), got {y[: self.n_masses - 1]}."
            )

    def describe(self) -> str:
        return f"chain of {self.n_masses} masses, {type(self.friction).__name__} friction, " + (
            f"{type(self.actuator).__name__} actuator"
        )

    def attributes(self) -> dict[str, str]:
        """The kind, the friction law's and the actuator's class names."""
        return {"kind": self.kind, "friction": type(self.friction).__name__, "actuator": type(self.actuator).__name__}

    def drawing(self) -> Any:
        """What [`animate`][locomotion_jax.run._animation.animate] draws of the chain: every mass on the ground, a
        spring between each pair of neighbours (`run._mechanism_animation.Drawing`)."""
        from ..run._mechanism_animation import Drawing

        n = self.n_masses
        return Drawing(contact=[True] * n, carried=[False] * n, springs=[(j, j + 1) for j in range(n - 1)])

    def optimum(self, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start):
        """As `AbstractMechanism.optimum`: travelling waves, then per-spring harmonics (`optimisation._chain`)."""
        from ..optimisation._optimise import chain_optimum

        return chain_optimum(self, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start)


def _concrete(x: Any) -> bool:
    return not isinstance(x, jax.core.Tracer)
