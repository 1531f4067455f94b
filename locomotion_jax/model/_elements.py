"""The elements of a [`Mechanism`][locomotion_jax.Mechanism] (SPEC §9): springs (linear or tilted)
between any two bodies or to a wall, dampers, internal force actuators and external forces.

Each element names the bodies it acts on by their index (static: part of the mechanism's
structure, not of its values) or `lj.WALL`, a fixed point at $x = 0$ of
the line. Its values are arrays with the mechanism's batch axes (a scalar is broadcast).
A signal (a rest length or a force) is a number, constant in time, or any
[`AbstractWaveform`][locomotion_jax.AbstractWaveform] of the mechanism's base frequency:
its value at time $t$ is the waveform's $\\ell_0(t)$, its mean `lbar` included (so
`Sinusoid(a=0.6, omega=3.0, lbar=0.0)` is the force $0.6\\sin 3t$).
"""

import abc
import dataclasses
from typing import Any, Final, Literal

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike
from ._checks import real_array
from ._waveform import AbstractWaveform


WALL: Final = "wall"
"""A fixed anchor at $x = 0$ of the line: `Spring(0, WALL, k=1.0, rest=0.0)` ties body 0 to it."""

End = int | Literal["wall"]
"""A body index or `lj.WALL`."""

Signal = Array | AbstractWaveform
"""A constant value (array) or a waveform of time."""


def _end(name: str, owner: str, value: Any) -> "int | str":
    if isinstance(value, str):
        if value != WALL:
            raise ValueError(f"{owner}: {name} must be a body index or lj.WALL, got {value!r}.")
        return WALL
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{owner}: {name} must be a body index (an int >= 0) or lj.WALL, got {value!r}.")
    return value


def _signal(name: str, owner: str, value: Any) -> Signal:
    if isinstance(value, AbstractWaveform):
        return value
    return real_array(name, value, owner)


def signal_at(s: Signal, c1: Array, s1: Array) -> tuple[Array, Array | None, Array | None]:
    """A signal's value and first two time derivatives at phase $(\\cos\\omega t, \\sin\\omega t)$
    (`None`: zero, for a constant)."""
    if isinstance(s, AbstractWaveform):
        return s.at_phase(c1, s1)
    return jnp.broadcast_to(jnp.asarray(s, jnp.result_type(c1)), jnp.shape(c1)), None, None


def signal_fields(s: AbstractWaveform) -> list[tuple[str, Array, int]]:
    """Every array field of a waveform, `(name, array, number of its trailing non-batch axes)`: its
    coefficient arrays have one (`AbstractWaveform.coefficients`), its other fields none."""
    coeffs = s.coefficients()
    out = []
    for f in dataclasses.fields(s):
        x = getattr(s, f.name)
        if eqx.is_array(x):
            out.append((f.name, x, 1 if f.name in coeffs and jnp.ndim(coeffs[f.name]) == jnp.ndim(x) else 0))
    return out


def signal_nodes(s: Signal) -> list[tuple[Array, int]]:
    """Every array of a signal with the number of its trailing (non-batch) axes ([`signal_fields`][])."""
    if not isinstance(s, AbstractWaveform):
        return [(s, 0)]
    return [(x, tail) for _, x, tail in signal_fields(s)]


def signal_checks(s: Signal) -> list[tuple[str, Array, str]]:
    """`(field, valid mask, range)` of a signal: finite values and $\\omega \\ge 0$ (a force's or a
    rest length's mean may be any number, so a waveform's `lbar` and stroke are not checked)."""
    if not isinstance(s, AbstractWaveform):
        return [("value", jnp.isfinite(s), "finite")]
    out = [(n, jnp.isfinite(x).all(-1), "finite") for n, x in s.coefficients().items()]
    out.append(("lbar", jnp.isfinite(s.lbar), "finite"))
    out.append(("omega", jnp.isfinite(s.omega) & (s.omega >= 0), "omega >= 0 and finite"))
    return out


class AbstractElement(eqx.Module):
    """Base class of a mechanism's elements (abstract/final pattern)."""

    @abc.abstractmethod
    def bodies(self) -> tuple["int | str", ...]:
        """The bodies (or `WALL`) it acts on."""

    def describe(self) -> str:
        """How messages name it, e.g. `Spring(0, WALL)`."""
        ends = ", ".join("WALL" if e == WALL else str(e) for e in self.bodies())
        return f"{type(self).__name__}({ends})"

    def signals(self) -> tuple[Signal, ...]:
        return ()

    def values(self) -> dict[str, Array]:
        """Its constant arrays by name (each with the batch axes only)."""
        return {}


class Spring(AbstractElement):
    """A linear spring between bodies `a` and `b` (or a body and `lj.WALL`), signed
    (SPEC §9): $f = k\\,(x_b - x_a - r(t))$, $+f$ on `a` and $-f$ on `b`, so $x_b - x_a$ may change
    sign (a capsule's internal spring). Its elastic energy is $f^2/(2k)$; an actuated rest
    length $r(t)$ (a waveform) does the work $-f\\,\\dot r$.

    **Arguments:** `a`, `b`: body indices or `WALL` (not both; `a != b`); `k > 0`; `rest`: a
    number or a waveform $r(t)$ (default 0).
    """

    a: "int | str" = eqx.field(static=True)
    b: "int | str" = eqx.field(static=True)
    k: Array
    rest: Signal

    def __init__(self, a: End, b: End, k: ArrayLike = 1.0, rest: "ArrayLike | AbstractWaveform" = 0.0):
        self.a, self.b = _end("a", "Spring", a), _end("b", "Spring", b)
        self.k = real_array("k", k, "Spring")
        self.rest = _signal("rest", "Spring", rest)

    def bodies(self) -> tuple["int | str", ...]:
        return (self.a, self.b)

    def signals(self) -> tuple[Signal, ...]:
        return (self.rest,)

    def values(self) -> dict[str, Array]:
        return {"k": self.k}


class TiltedSpring(AbstractElement):
    """A tilted spring between bodies `a` and `b` (or a body and `lj.WALL`) (SPEC §9), as a chain's
    spring (SPEC §8, eq. 2): with $u = x_b - x_a$ and the vertical offset $d$ of `b` above `a`, its
    length is $\\ell = \\sqrt{u^2 + d^2}$ and its tension $T = k\\,(\\ell - r(t))$; it pulls `a` by
    $T\\,(u, d)/\\ell$ and `b` by the opposite, so its vertical force lightens `a`'s normal load by
    $T d/\\ell$ and loads `b`'s by as much (a carried body's share goes to the body that carries
    it; a free body's is borne by the line). Under `contact="hop"` it acts along
    $(u, d + y_b - y_a)$ (SPEC §10). Its elastic energy is $T^2/(2k)$; an actuated rest length
    $r(t)$ does the work $-T\\,\\dot r$.

    **Arguments:** `a`, `b`: body indices or `WALL` (not both; `a != b`); `k > 0`; `d`: the vertical
    offset (any finite number, default 0: a horizontal spring of length $|u|$); `rest`: a number or
    a waveform $r(t)$ (default 0).

    A horizontal one ($d = 0$) keeps `b` ahead of `a`, as a chain's springs do: its force turns
    over where its ends meet, so a run in which they do stops there with `Status.COLLISION`
    ([`AbstractPhysics.gaps`][locomotion_jax.AbstractPhysics.gaps]), and the mechanism's `x0` must
    put `b` ahead of `a` (else refused by name, or flagged `Status.INVALID` with `check=False`). A
    signed spring whose ends may pass each other is a [`Spring`][locomotion_jax.Spring]. A tilted
    one's force turns over within $|u| \\lesssim |d|$: an exact step that passes $u = 0$ while moving
    $u$ by more than $|d|/2$ stops the run with `Status.UNRESOLVED` (docs/engines.md).
    """

    a: "int | str" = eqx.field(static=True)
    b: "int | str" = eqx.field(static=True)
    k: Array
    d: Array
    rest: Signal

    def __init__(self, a: End, b: End, k: ArrayLike = 1.0, d: ArrayLike = 0.0,
                 rest: "ArrayLike | AbstractWaveform" = 0.0):  # fmt: skip
        self.a, self.b = _end("a", "TiltedSpring", a), _end("b", "TiltedSpring", b)
        self.k = real_array("k", k, "TiltedSpring")
        self.d = real_array("d", d, "TiltedSpring")
        self.rest = _signal("rest", "TiltedSpring", rest)

    def bodies(self) -> tuple["int | str", ...]:
        return (self.a, self.b)

    def signals(self) -> tuple[Signal, ...]:
        return (self.rest,)

    def values(self) -> dict[str, Array]:
        return {"k": self.k, "d": self.d}


class Force(AbstractElement):
    """An internal force actuator between bodies `a` and `b` (SPEC §9): a prescribed $f(t)$, $+f$ on
    `b` and $-f$ on `a` (a positive force pushes `b` forward); its power is $f\\,(v_b - v_a)$.

    **Arguments:** `a`, `b`: body indices (or `WALL`: then it pushes the other body alone);
    `waveform`: a waveform $f(t)$ or a constant number.
    """

    a: "int | str" = eqx.field(static=True)
    b: "int | str" = eqx.field(static=True)
    waveform: Signal

    def __init__(self, a: End, b: End, waveform: "ArrayLike | AbstractWaveform"):
        self.a, self.b = _end("a", "Force", a), _end("b", "Force", b)
        self.waveform = _signal("waveform", "Force", waveform)

    def bodies(self) -> tuple["int | str", ...]:
        return (self.a, self.b)

    def signals(self) -> tuple[Signal, ...]:
        return (self.waveform,)


class ExternalForce(AbstractElement):
    """A prescribed external force $g_i(t)$ on body `i` (SPEC §9), positive forward; its power is
    $g_i v_i$. The inertial force $-m\\,\\ddot s(t)$ of a prescribed internal motion $s(t)$ is one.

    **Arguments:** `i`: the body index; `waveform`: a waveform $g(t)$ or a constant number.
    """

    i: int = eqx.field(static=True)
    waveform: Signal

    def __init__(self, i: int, waveform: "ArrayLike | AbstractWaveform"):
        end = _end("i", "ExternalForce", i)
        if end == WALL:
            raise ValueError("ExternalForce: i must be a body index, not lj.WALL.")
        self.i = int(end)
        self.waveform = _signal("waveform", "ExternalForce", waveform)

    def bodies(self) -> tuple["int | str", ...]:
        return (self.i,)

    def signals(self) -> tuple[Signal, ...]:
        return (self.waveform,)


class Damper(AbstractElement):
    """A linear damper between bodies `a` and `b` (or a body and `lj.WALL`) (SPEC §9):
    $f = c\\,(v_b - v_a)$, $+f$ on `a` and $-f$ on `b`; it dissipates $c\\,(v_b - v_a)^2$.

    Its force enters $F_i$ (so the stick and slip decisions) and its dissipation $e_d$. A damper to
    a `WALL` (at rest) is ground damping on its body, $c_i \\mathrel{+}= c$, and runs as such; one
    between two bodies runs through the physics' `velocity_forces` (the engine adds them to the
    position-dependent loads).

    **Arguments:** `a`, `b`: body indices or `WALL` (not both; `a != b`); `c >= 0`.
    """

    a: "int | str" = eqx.field(static=True)
    b: "int | str" = eqx.field(static=True)
    c: Array

    def __init__(self, a: End, b: End, c: ArrayLike = 1.0):
        self.a, self.b = _end("a", "Damper", a), _end("b", "Damper", b)
        self.c = real_array("c", c, "Damper")

    def bodies(self) -> tuple["int | str", ...]:
        return (self.a, self.b)

    def values(self) -> dict[str, Array]:
        return {"c": self.c}
