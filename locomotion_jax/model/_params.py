"""Model parameters as a pytree of floating arrays (paper Sect. 2.1, eq. 6)."""

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.core  # (jax.core.Tracer) for type checkers
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike
from ._checks import broadcast_shape, real_array
from ._mechanism import AbstractMechanism


PARAM_NAMES: tuple[str, ...] = ("k", "c", "d", "lbar", "a", "omega", "mu_s", "mu_k", "mhat")

DEFAULTS: dict[str, float] = {
    "k": 50.0,
    "c": 0.01,
    "d": 0.5,
    "lbar": 3.0,
    "a": 0.05,
    "omega": 2.0,
    "mu_s": 0.7,
    "mu_k": 0.5,
    "mhat": 0.5,
}
"""The paper's defaults (Sect. 3, Fig. 5 caption); `omega = 2 = 0.2 wn1` is Fig. 5a."""

# Human-readable valid ranges, used in error messages and by the CLI.
VALID_RANGES: dict[str, str] = {
    "k": "k > 0, a normal float (k >= 2.3e-308 in float64, 1.2e-38 in float32)",
    "c": "c >= 0",
    "d": "|d| < lbar",
    "lbar": "lbar > 0 with lbar**2 a normal float (1.5e-154 <= lbar <= 6.7e153 in float64, 1.1e-19 to 9.2e18 "
    "in float32)",
    "a": "0 <= a < lbar",
    "omega": "omega >= 0",
    "mu_s": "mu_s >= mu_k",
    "mu_k": "mu_k >= 0",
    "mhat": "0 < mhat < 1, a normal float",
}


def normal_positive(x: Any, xp=jnp, power: int = 1) -> Any:
    """`x > 0` with `x**power` a normal float, not subnormal and a quarter of the largest at most:
    XLA's CPU code flushes subnormal numbers to zero, so a subnormal stiffness or mass, or a
    length whose square underflows ($\\ell^2 = u^2 + d^2$, eq. 2), became 0 inside the engines, and
    one whose square overflows inf (a NaN with status OK, found by tests/test_fuzz.py)."""
    dtype = xp.asarray(x).dtype
    info = xp.finfo(dtype if xp.issubdtype(dtype, xp.floating) else float)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        xp_ = x**power
        return (x > 0) & (xp_ >= info.tiny) & (xp_ <= info.max / 4)


def _validity(p: Mapping[str, Any], xp=jnp) -> dict[str, Any]:
    """Per-parameter validity masks; works with numpy (host checks) or jnp (traced)."""
    fin = {name: xp.isfinite(p[name]) for name in PARAM_NAMES}
    ok = {
        "k": normal_positive(p["k"], xp),
        "c": p["c"] >= 0,
        "d": xp.abs(p["d"]) < p["lbar"],
        "lbar": normal_positive(p["lbar"], xp, 2),
        "a": (p["a"] >= 0) & (p["a"] < p["lbar"]),
        "omega": p["omega"] >= 0,
        "mu_s": p["mu_s"] >= p["mu_k"],
        "mu_k": p["mu_k"] >= 0,
        "mhat": normal_positive(p["mhat"], xp) & (p["mhat"] < 1),
    }
    return {name: fin[name] & ok[name] for name in PARAM_NAMES}


def _is_concrete(x: Any) -> bool:
    return not isinstance(x, jax.core.Tracer)


class Params(AbstractMechanism):
    """Dimensionless parameters of the two-mass model (eq. 6), as a pytree.

    Every field is a floating array; a field may carry leading batch axes, and all
    fields broadcast against each other, so one `Params` describes one
    configuration or a whole batch (see [`Params.grid`][]). Fields not given take
    the paper's defaults ([`DEFAULTS`][]).

    Masses are normalised so that $m_1 + m_2 = 2$ (eq. 6 with $M = (M_1+M_2)/2$):
    $m_1 = 2\\hat m$, $m_2 = 2(1 - \\hat m)$.

    **Arguments:**

    - `k`: spring stiffness, $k > 0$.
    - `c`: linear damping on each mass, $c \\ge 0$.
    - `d`: vertical offset of the spring, $|d| < \\bar\\ell$ (sign sets the direction).
    - `lbar`: mean rest length $\\bar\\ell > 0$ (eq. 13).
    - `a`: actuation amplitude, $0 \\le a < \\bar\\ell$ (eq. 13).
    - `omega`: actuation frequency, $\\omega \\ge 0$ (eq. 13).
    - `mu_s`, `mu_k`: static and kinetic friction, $\\mu_s \\ge \\mu_k \\ge 0$.
    - `mhat`: mass ratio $\\hat m = m_1 / (m_1 + m_2) \\in (0, 1)$.
    - `check`: validate concrete values (default). Complex or non-numeric values and
      fields whose shapes do not broadcast are refused whatever `check`. Invalid values raise
      `ValueError` naming the parameter, its valid range and, in a batch, the
      offending index. With `check=False` invalid configurations are instead
      flagged per configuration (`Status.INVALID`) by the simulators.

    **Raises:** `ValueError` for an unknown or invalid parameter.

    !!! Example

        ```python
        p = Params(omega=2.0)                      # Fig. 5a
        batch = Params.grid(omega=jnp.linspace(1, 25, 64), a=jnp.linspace(0.01, 0.1, 32))
        batch.batch_shape  # (64, 32)
        ```
    """

    kind: ClassVar[str] = "paper"

    k: Array
    c: Array
    d: Array
    lbar: Array
    a: Array
    omega: Array
    mu_s: Array
    mu_k: Array
    mhat: Array

    def __init__(
        self,
        k: ArrayLike = DEFAULTS["k"],
        c: ArrayLike = DEFAULTS["c"],
        d: ArrayLike = DEFAULTS["d"],
        lbar: ArrayLike = DEFAULTS["lbar"],
        a: ArrayLike = DEFAULTS["a"],
        omega: ArrayLike = DEFAULTS["omega"],
        mu_s: ArrayLike = DEFAULTS["mu_s"],
        mu_k: ArrayLike = DEFAULTS["mu_k"],
        mhat: ArrayLike = DEFAULTS["mhat"],
        *,
        check: bool = True,
    ):
        values = dict(k=k, c=c, d=d, lbar=lbar, a=a, omega=omega, mu_s=mu_s, mu_k=mu_k, mhat=mhat)
        for name, value in values.items():
            setattr(self, name, real_array(name, value))
        _ = self.batch_shape  # fields that do not broadcast are refused here, named, whatever `check`
        if check and all(_is_concrete(getattr(self, n)) for n in PARAM_NAMES):
            self.validate()

    # -- construction helpers -------------------------------------------------

    @classmethod
    def from_dict(cls, values: Mapping[str, ArrayLike], *, check: bool = True) -> "Params":
        """Build from a mapping; unknown names raise `ValueError` listing the valid ones."""
        unknown = sorted(set(values) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"Unknown parameter(s) {unknown}; valid names are {list(PARAM_NAMES)}.")
        return cls(**values, check=check)

    @classmethod
    def grid(cls, *, check: bool = True, **axes: ArrayLike | float) -> "Params":
        """Outer product of 1-D axes (``indexing="ij"``), other fields at defaults.

        Scalars among `axes` are fixed values. The batch shape is the lengths of
        the 1-D axes in the order given.
        """
        unknown = sorted(set(axes) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"Unknown parameter(s) {unknown}; valid names are {list(PARAM_NAMES)}.")
        arrays = {n: jnp.asarray(v) for n, v in axes.items()}
        swept = [n for n, v in arrays.items() if v.ndim == 1]
        for n, v in arrays.items():
            if v.ndim > 1:
                raise ValueError(f"grid axis {n!r} must be a scalar or 1-D, got shape {v.shape}.")
            if v.ndim == 1 and v.shape[0] == 0:
                raise ValueError(f"grid axis {n!r} is empty.")
        meshes = jnp.meshgrid(*(arrays[n] for n in swept), indexing="ij") if swept else []
        values: dict[str, Any] = {n: arrays[n] for n in arrays if n not in swept}
        values.update(dict(zip(swept, meshes)))
        return cls(**values, check=check)

    @classmethod
    def stack(cls, items: Sequence["Params"]) -> "Params":
        """Stack single configurations along a new leading batch axis."""
        if len(items) == 0:
            raise ValueError("Params.stack needs at least one Params.")
        items = [it.broadcast() for it in items]
        return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *items)

    # -- shapes and dtypes ----------------------------------------------------

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Broadcast shape of all fields (``()`` for a single configuration)."""
        return broadcast_shape({n: getattr(self, n).shape for n in PARAM_NAMES})

    @property
    def dtype(self) -> jnp.dtype:
        return jnp.result_type(*(getattr(self, n) for n in PARAM_NAMES))

    def broadcast(self) -> "Params":
        """All fields broadcast to `batch_shape` with one common dtype."""
        shape, dtype = self.batch_shape, self.dtype
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x.astype(dtype), shape), self)

    def astype(self, dtype: Any) -> "Params":
        """Cast every field; `float64` needs `jax.config.update("jax_enable_x64", True)`."""
        if not jnp.issubdtype(jnp.dtype(dtype), jnp.floating):
            raise ValueError(f"dtype must be a floating dtype, got {jnp.dtype(dtype)}.")
        return super().astype(dtype)

    def __getitem__(self, index: Any) -> "Params":
        """Index the (broadcast) batch axes, e.g. `batch[3]` or `batch[:, 0]`."""
        return jax.tree_util.tree_map(lambda x: x[index], self.broadcast())

    def as_dict(self) -> dict[str, Array]:
        return {n: getattr(self, n) for n in PARAM_NAMES}

    def replace(self, **changes: ArrayLike) -> "Params":
        """Copy with some fields changed (validated like the constructor)."""
        values: dict[str, ArrayLike] = {**self.as_dict(), **changes}
        return Params.from_dict(values)

    # -- derived quantities ---------------------------------------------------

    @property
    def m1(self) -> Array:
        """$m_1 = 2\\hat m$ (eq. 6 with $m_1 + m_2 = 2$)."""
        return 2 * self.mhat

    @property
    def m2(self) -> Array:
        """$m_2 = 2(1-\\hat m)$."""
        return 2 * (1 - self.mhat)

    @property
    def wn1(self) -> Array:
        """Eq. (11): $\\omega_{n1} = \\sqrt{k (m_1 + m_2) / (m_1 m_2)}$ (both slip)."""
        return jnp.sqrt(self.k * (self.m1 + self.m2) / (self.m1 * self.m2))

    @property
    def wn2(self) -> Array:
        """Eq. (12): $\\omega_{n2} = \\sqrt{k / m_1}$ (mass 2 stuck)."""
        return jnp.sqrt(self.k / self.m1)

    @property
    def wn3(self) -> Array:
        """Eq. (12): $\\omega_{n3} = \\sqrt{k / m_2}$ (mass 1 stuck)."""
        return jnp.sqrt(self.k / self.m2)

    @property
    def t_start(self) -> Array:
        """Start of the measurement (Sect. 3): 80 periods of the lowest natural frequency."""
        wmin = jnp.minimum(jnp.minimum(self.wn1, self.wn2), self.wn3)
        return 80 * 2 * math.pi / wmin

    def time_scales(self, waveform: Any = None) -> list[Any]:
        """The resolution guards' scales (`AbstractMechanism.time_scales`): the forcing of
        `waveform` (default the sinusoid of these parameters), the natural period
        $2\\pi/\\omega_{n1}$ (eq. 11; $\\omega_{n1} \\ge \\omega_{n2}, \\omega_{n3}$) and the
        damping time $\\min(m_1, m_2)/c$."""
        from . import _scales as sc
        from ._waveform import Sinusoid

        wave = Sinusoid.from_params(self) if waveform is None else waveform
        omega = sc.flat(wave.omega, self.batch_shape[0])
        return [
            sc.forcing(wave, omega),
            sc.TimeScale("k", "natural period 2*pi/wn1 (eq. 11)", 2 * math.pi / self.wn1, sc.STEPS_PER_PERIOD,
                         "period", {"k": self.k, "mhat": self.mhat}),
            sc.TimeScale("c", "damping time min(m1, m2)/c", jnp.minimum(self.m1, self.m2) / self.c, sc.STEPS_PER_TIME,
                         "damping time", {"c": self.c, "mhat": self.mhat}),
        ]  # fmt: skip

    def start_scale(self) -> Any:
        from ._scales import start_span

        what = "Params.t_start (80 periods of the lowest natural frequency)"
        return start_span(self.t_start, what, {"k": self.k, "mhat": self.mhat})

    # -- validation -----------------------------------------------------------

    def is_valid(self) -> Array:
        """Traceable boolean mask (batch shape) of configurations inside the valid ranges."""
        masks = _validity(self.as_dict(), jnp)
        out = masks[PARAM_NAMES[0]]
        for name in PARAM_NAMES[1:]:
            out = out & masks[name]
        return jnp.broadcast_to(out, self.batch_shape)

    def validate(self) -> "Params":
        """Raise `ValueError` at the first invalid field (name, valid range, batch index)."""
        shape = self.batch_shape
        host = {n: np.broadcast_to(np.asarray(getattr(self, n)), shape) for n in PARAM_NAMES}
        masks = _validity(host, np)
        # lbar and mu_k first: the ranges of d, a and mu_s are stated relative to them.
        order = ("k", "c", "lbar", "d", "a", "omega", "mu_k", "mu_s", "mhat")
        for name in order:
            bad = ~np.broadcast_to(masks[name], shape)
            if bad.any():
                idx = tuple(int(i) for i in np.argwhere(bad)[0]) if shape else ()
                at = f" at batch index {idx}" if shape else ""
                got = {name: float(host[name][idx])}
                if name == "mu_s":
                    got["mu_k"] = float(host["mu_k"][idx])
                if name in ("a", "d"):
                    got["lbar"] = float(host["lbar"][idx])
                got_s = ", ".join(f"{k}={v!r}" for k, v in got.items())
                n_bad = int(bad.sum())
                more = f" ({n_bad} invalid configurations in the batch)" if shape and n_bad > 1 else ""
                raise ValueError(
                    f"Invalid parameter {name!r}{at}: got {got_s}; the valid range is "
                    f"{VALID_RANGES[name]} (and finite){more}."
                )
        return self

    def describe(self) -> str:
        return "the paper's two-mass model"

    def physics(self, waveform: Any = None) -> Any:
        """The paper's model as the two-mass chain (SPEC §8 at $N = 2$): its
        [`AbstractPhysics`][locomotion_jax.AbstractPhysics], for one configuration or a batch.

        `waveform`: the rest length $\\ell_0(t)$, any [`AbstractWaveform`][locomotion_jax.AbstractWaveform]
        (`None`: the sinusoid of eq. 13). Masses $m_1 = 2\\hat m$, $m_2 = 2(1 - \\hat m)$, one spring
        $(k, d, \\bar\\ell)$, damping $c$ on each mass, `Coulomb(mu_s, mu_k)`: the loads of eqs. (2, 5, 8).
        """
        from ._chain import Chain
        from ._waveform import Fourier, Sinusoid

        wave = Sinusoid.from_params(self) if waveform is None else waveform
        if isinstance(wave, (Sinusoid, Fourier)):
            return Chain.from_params(self, wave).physics()
        # Any other waveform drives the spring itself; the phase turns at its base frequency.
        rest = Chain.from_params(self, Sinusoid(jnp.zeros_like(self.a), wave.omega, self.lbar)).physics()
        return eqx.tree_at(lambda P: P.waveforms, rest, (wave,), is_leaf=lambda x: x is None)

    def flat_batch(self, dynamics, *, waveform=None, dtype=None, t_start=None, initial=None, measuring=False,
                   contact="strict", start="paper"):  # fmt: skip
        """As `AbstractMechanism.flat_batch`:
        actuated by `waveform` (default the sinusoid of eq. 13), `initial` a tuple `(x1, v1, x2, v2)`."""
        from ..run._batch import params_batch

        return params_batch(self, dynamics, waveform, dtype, t_start, initial, measuring)

    def own_batch(self):
        """As `AbstractMechanism.own_batch`:
        actuated by the sinusoid of eq. (13)."""
        from .._results import PAPER
        from ..dynamics._flat import FlatBatch
        from ._waveform import Sinusoid

        return FlatBatch(self, self.is_valid(), wave=Sinusoid.from_params(self), wave_axes=0, names=PAPER)

    def gait_problem(self, dynamics, *, waveform=None, contact="strict", start="paper", dtype=None):
        """As `AbstractMechanism.gait_problem`: the two-mass chain of each configuration and its
        waveform, section states $(u, v_1, v_2)$ (`gaits._gait.paper_problem`)."""
        from ..gaits._gait import paper_problem

        return paper_problem(self, dynamics, waveform, contact, start, dtype)

    def branch_setup(self, parameter, stops_of, dynamics, waveform, dtype, contact):
        """As `AbstractMechanism.branch_setup`: `parameter` a field or a waveform's coefficient."""
        from ..gaits._continuation import paper_setup

        return paper_setup(self, parameter, stops_of, dynamics, waveform, dtype)

    def animation(self, traj: Any, **options: Any) -> Any:
        """As `AbstractMechanism.animation`: the paper's two masses and tilted spring (`run._animation`)."""
        from ..run._animation import animate_paper

        return animate_paper(traj, self, **options)

    def optimum(self, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start):
        """As `AbstractMechanism.optimum`: the exact (default) or smoothed optimiser of the paper's model."""
        from ..optimisation._optimise import params_optimum

        return params_optimum(self, v_min, a_max, method, direction, omega, harmonics, settings, sweep, start)


def safe_params(params: Params, wave: Any = None) -> tuple[Params, jax.Array]:
    """Replace an invalid configuration by the defaults (so nothing becomes NaN) and
    return the validity flag; the caller marks it `Status.INVALID` and skips it.

    With the configuration's actuation `wave` (an `AbstractWaveform`), its validity
    (`AbstractWaveform.is_valid`: finite coefficients, a positive rest length) counts too;
    the wave itself is not replaced, so the caller must not advance an invalid configuration."""
    valid = params.is_valid() if wave is None else params.is_valid() & wave.is_valid()
    values = {n: jnp.where(valid, getattr(params, n), jnp.asarray(DEFAULTS[n], params.dtype)) for n in PARAM_NAMES}
    return Params(**values, check=False), valid
