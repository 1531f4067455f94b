"""Geometry, forces and energy of the two-mass model (eqs. 2, 4, 5, 8, 10, 15, 16); eq. 9 with smooth friction.

Pure functions of one configuration; batching is done by the callers with `vmap`.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Contact
from ._params import Params
from ._waveform import AbstractWaveform


class Forces(NamedTuple):
    """Everything the dynamics needs at one instant; positions and time only.

    The spring forces do not depend on velocities or on the contact modes, so a
    mode switch reuses them (the integrator's first-same-as-last trick).
    """

    l0: Array  # rest length, eq. (13)
    dl0: Array  # its rate
    tension: Array  # T = k (l - l0)
    fx: Array  # horizontal spring force on m1, eq. (8); -fx on m2
    N1: Array  # signed normal forces, eq. (5)
    N2: Array
    n1: Array  # normal forces entering friction (|N| under the paper's reading)
    n2: Array


def spring_length(params: Params, x1: Array, x2: Array) -> Array:
    """Eq. (2): $\\ell = \\sqrt{(x_2 - x_1)^2 + d^2}$."""
    dx = x2 - x1
    return jnp.sqrt(dx * dx + params.d * params.d)


def forces(params: Params, wave: AbstractWaveform, t: ArrayLike, x1: Array, x2: Array, contact: Contact) -> Forces:
    """Spring and normal forces at time `t` (see [`spring_forces`][])."""
    l0, dl0 = wave(t)
    return spring_forces(params, l0, dl0, x1, x2, contact)


def spring_forces(params: Params, l0: Array, dl0: Array, x1: Array, x2: Array, contact: Contact) -> Forces:
    """Spring and normal forces for a given rest length $\\ell_0$ and rate.

    - Tension $T = k(\\ell - \\ell_0(t))$; horizontal force on $m_1$ (eq. 8, in the
      corrected form of SPEC §1) $f_x = T (x_2 - x_1)/\\ell$, on $m_2$ $-f_x$.
    - Normal forces, eq. (5): $N_1 = m_1 - f_y$, $N_2 = m_2 + f_y$ with $f_y = T d / \\ell$.
    - `contact="paper"` uses $n_i = |N_i|$ (eq. 6 as printed); `"strict"` uses
      $n_i = N_i$, valid only while $N_i > 0$ (callers stop at lift-off).
    """
    dx = x2 - x1
    length = jnp.sqrt(dx * dx + params.d * params.d)
    tension = params.k * (length - l0)
    per_len = tension / length
    fx = per_len * dx
    fy = per_len * params.d
    N1 = params.m1 - fy
    N2 = params.m2 + fy
    if contact == "paper":
        n1, n2 = jnp.abs(N1), jnp.abs(N2)
    else:
        n1, n2 = N1, N2
    return Forces(l0, dl0, tension, fx, N1, N2, n1, n2)


def centre_of_mass(params: Params, x1: ArrayLike, x2: ArrayLike) -> Array:
    """Eq. (4): $X = (m_1 x_1 + m_2 x_2)/(m_1 + m_2)$, with $m_1 + m_2 = 2$."""
    return params.mhat * x1 + (1 - params.mhat) * x2


def total_energy(params: Params, l0: ArrayLike, x1, v1, x2, v2) -> Array:
    """Eq. (10): $e = \\tfrac12 m_1 v_1^2 + \\tfrac12 m_2 v_2^2 + \\tfrac12 k (\\ell - \\ell_0)^2$."""
    stretch = spring_length(params, x1, x2) - l0
    return 0.5 * (params.m1 * v1 * v1 + params.m2 * v2 * v2 + params.k * stretch * stretch)


def smoothed_rates(
    params: Params, f: Forces, v1: Array, v2: Array, mu: Callable[[Array], Array]
) -> tuple[Array, Array, Array]:
    """Eq. (9) with a smooth friction law $\\mu(v)$ (odd in $v$) in place of stick and slip.

    Returns the accelerations $a_1$, $a_2$ and the dissipated power
    $\\mu(v_1) n_1 v_1 + \\mu(v_2) n_2 v_2 + c (v_1^2 + v_2^2)$ (integrand of eq. 15).
    The smoothed engine and the optimiser's objective share it with different laws.
    """
    fr1 = f.n1 * mu(v1)
    fr2 = f.n2 * mu(v2)
    a1 = (f.fx - params.c * v1 - fr1) / params.m1
    a2 = (-f.fx - params.c * v2 - fr2) / params.m2
    p_d = fr1 * v1 + fr2 * v2 + params.c * (v1 * v1 + v2 * v2)
    return a1, a2, p_d


def initial_gap(params: Params, start: str) -> Array:
    """$x_2 - x_1$ at $t = 0$: eq. (14) (`"paper"`) or the relaxed spring (`"relaxed"`)."""
    if start == "paper":
        return params.lbar + 0 * params.d
    if start == "relaxed":
        return jnp.sqrt(params.lbar**2 - params.d**2)
    raise ValueError(f"start must be 'paper' (eq. 14) or 'relaxed', got {start!r}.")


def check_contact(contact: str, hop: bool = False) -> None:
    """Validate a `contact` reading; `"hop"` raises `NotImplementedError` unless the caller's path
    supports it (`hop=True`)."""
    if contact == "hop" and not hop:
        raise NotImplementedError(
            "contact='hop' (flight and landing, SPEC section 10) is not implemented yet for the paper's "
            "model (Params) on this path (lj.simulate and lj.measure run it); use contact='strict' or 'paper'."
        )
    if contact not in ("strict", "paper", "hop"):
        raise ValueError(f"contact must be 'strict', 'paper' or 'hop', got {contact!r}.")
