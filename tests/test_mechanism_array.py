"""A `Mechanism` in the array layout (`model/_mechanism_array.py`: the bodies one entry, the elements
arrays over the elements of each kind): its loads and their rates equal the unrolled physics' to
rounding, its runs (exact and smoothed, strict and hopping) and steady gaits equal the unrolled ones,
a long mechanism that `layout="auto"` lays out as arrays agrees with the independent reference
(`tests/reference_mechanism.py`), a bad configuration in a batch is flagged alone, and a mechanism the
layout does not serve is refused with the reason."""

from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.model._chain_array import ARRAY_FROM, engine_physics, uses_array
from locomotion_jax.model._friction import MixedFriction, static_at_rest
from locomotion_jax.model._mechanism_array import ArrayMechanismPhysics
from locomotion_jax.model._physics import least_contact_load, load_rates_at, load_second_at, loads_at


pytestmark = pytest.mark.xdist_group("mechanism_array")

OMEGA = 2.0
X0 = [2.0, 3.4, 4.5, 5.6]


def _wave(cos, sin, lbar):
    return lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), OMEGA, lbar)


def _spline(cos, sin, lbar):
    """A periodic spline of 6 control values near the Fourier series `(cos, sin)`."""
    phase = 2 * np.pi * np.arange(6) / 6
    control = sum(a * np.cos((n + 1) * phase) + b * np.sin((n + 1) * phase) for n, (a, b) in enumerate(zip(cos, sin)))
    return lj.Spline(jnp.asarray(control), OMEGA, lbar)


def _topology(layout: str, tilted: bool = True, k_tilt: float = 1.0, splines: bool = False, **kw) -> lj.Mechanism:
    """Four bodies on anisotropic bristles (per-body coefficients): a spring to the wall driven by a
    sinusoid in Fourier form, springs between neighbours and not (a constant, a `Sinusoid`, two
    harmonics), a damper between bodies and one to the wall, an internal force, an external force,
    and (`tilted`) tilted springs between bodies and to the wall; with `splines`, every waveform a
    `Spline` of 6 control values."""
    wave = _spline if splines else _wave
    sinusoid = _spline([0.0], [0.1], 2.5) if splines else lj.Sinusoid(0.1, OMEGA, 2.5)
    links = [lj.Spring(lj.WALL, 0, k=20.0, rest=wave([0.0], [0.3], 2.0)), lj.Spring(0, 1, k=30.0, rest=1.5),
             lj.Spring(0, 2, k=10.0, rest=sinusoid),
             lj.Spring(2, 3, k=12.0, rest=wave([0.05, 0.01], [0.1, -0.02], 1.0)),
             lj.Damper(1, 2, c=0.05), lj.Damper(lj.WALL, 3, c=0.1), lj.Force(1, 3, wave([0.05], [0.02], 0.1)),
             lj.ExternalForce(3, wave([0.05], [0.0], 0.02))]  # fmt: skip
    if tilted:
        links += [lj.TiltedSpring(1, 3, k=5.0 * k_tilt, d=0.5, rest=wave([0.0, 0.0], [0.0, 0.1], 1.8)),
                  lj.TiltedSpring(lj.WALL, 2, k=3.0 * k_tilt, d=0.3, rest=3.0)]  # fmt: skip
    law = lj.AnisotropicCoulomb(jnp.array([0.6, 0.5, 0.55, 0.7]), 0.9, 0.45, 0.7)
    return lj.Mechanism(masses=[1.0, 1.2, 0.5, 0.3], c=[0.02, 0.01, 0.0, 0.03], x0=X0, links=links, friction=law,
                        layout=layout, restitution=[0.3, 0.0, 0.5, 0.1], **kw)  # fmt: skip


def _random_state(rng: np.random.Generator, x0: list[float], hop: bool) -> tuple:
    """Positions near `x0`, velocities and accelerations; under `hop` heights and their two rates."""
    n = len(x0)
    x = jnp.asarray(x0) + rng.normal(size=n) * 0.1
    v, a = jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n))
    y, yd, ya = (jnp.asarray(np.abs(rng.normal(size=n))), jnp.asarray(rng.normal(size=n)),
                 jnp.asarray(rng.normal(size=n))) if hop else (None, None, None)  # fmt: skip
    return x, v, a, y, yd, ya


def _loads(P: Any, x, v, a, y, yd, ya) -> tuple[Any, Any, Any, dict[str, Any]]:
    """`P`'s actuation, loads and their rates at a state, and (stacked over the bodies) the loads, their
    first two rates, the fall in flight and the energy."""
    B: Any = lambda q: None if q is None else P.bodies(q)
    dr = P.drive(jnp.cos(OMEGA * 0.7), jnp.sin(OMEGA * 0.7))
    L = loads_at(P, dr, B(x), y=B(y))
    R = load_rates_at(P, dr, L, B(v), yd=B(yd))
    ddF, ddN = load_second_at(P, dr, L, R, B(v), B(a), yd=B(yd), ya=B(ya))
    return dr, L, R, dict(F=P.stacked(L.F), N=P.stacked(L.N), dF=P.stacked(R.dF), dN=P.stacked(R.dN),
                          ddF=P.stacked(ddF), ddN=P.stacked(ddN), fall=P.stacked(P.fall(L.N)),
                          energy=P.energy(L, B(v)))  # fmt: skip


@pytest.mark.parametrize("tilted, splines", [(False, False), (True, False), (True, True)])
@pytest.mark.parametrize("hop", [False, True])
def test_array_mechanism_rates_equal_unrolled(tilted, splines, hop):
    """At a random state (positions, velocities, accelerations; under `contact="hop"` heights and their
    rates), the loads, their first and second rates, the power and its rate, the energy, the dampers'
    forces and power, the centre of mass, the fall in flight, the rest lengths and tensions of the
    array physics equal the unrolled physics' to 1e-13 relative; with Fourier signals and with
    splines."""
    rng = np.random.default_rng(1 + 2 * tilted + hop)
    unrolled = _topology("unrolled", tilted, splines=splines).physics()
    array = _topology("array", tilted, splines=splines).array_physics()
    assert (array.bank is not None) == splines
    assert isinstance(array, ArrayMechanismPhysics) and array.anchored and unrolled.anchored
    x, v, a, y, yd, ya = _random_state(rng, X0, hop)
    out = []
    for physics in (unrolled, array):
        P: Any = physics
        B: Any = lambda q: None if q is None else P.bodies(q)
        dr, L, R, common = _loads(P, x, v, a, y, yd, ya)
        vf = P.velocity_forces(B(v))
        assert vf is not None
        out.append(common | dict(power=P.power(dr, L, B(v)), power_rate=P.power_rate(dr, L, R, B(v), B(a)),
                                 damper=P.stacked(vf), damper_power=P.velocity_power(B(v), B(a)),
                                 X=P.centre_of_mass(B(x)), l0=P.stacked(dr.l0),
                                 tension=P.stacked(L.aux.tension)))  # fmt: skip
    for key, want in out[0].items():
        np.testing.assert_allclose(np.asarray(out[1][key]), np.asarray(want), rtol=1e-13, atol=1e-13, err_msg=key)
    assert float(jnp.abs(out[0]["dN"]).max()) > (0.1 if tilted else -1)  # the tilted springs move the loads


@pytest.mark.parametrize("contact", ["strict", "hop"])
def test_array_mechanism_runs_equal_unrolled(contact):
    """`simulate` of the topology in both layouts (exact engine, dt = 0.005, t = 0 ... 10): positions,
    velocities, heights, energies, normal loads, rest lengths and tensions equal to 1e-10, and the same
    events; under `contact="hop"` (every waveform a spline) the bodies fly and land. The smoothed engine
    likewise (to 1e-8 at the adaptive solver's rtol of 1e-10: rounding moves its accepted steps)."""
    save = np.linspace(0.0, 10.0, 41)
    k_tilt = 0.2 if contact == "strict" else 1.0  # under the strict reading, loads that stay positive
    splines = contact == "hop"  # the hopping case's waveforms are splines
    runs = [lj.simulate(_topology(layout, k_tilt=k_tilt, splines=splines), 10.0, save, contact=contact,
                        dynamics=lj.Exact(dt=0.005)) for layout in ("unrolled", "array")]  # fmt: skip
    assert int(runs[0].status) == int(runs[1].status) == lj.Status.OK
    assert int(np.asarray(runs[0].n_switch)) == int(np.asarray(runs[1].n_switch)) > 5
    fields = ["x", "v", "e_d", "w", "e", "N", "rest_length", "tension"] + (["y", "vy"] if contact == "hop" else [])
    for name in fields:
        np.testing.assert_allclose(np.asarray(getattr(runs[1], name)), np.asarray(getattr(runs[0], name)), rtol=0,
                                   atol=1e-10, err_msg=name)  # fmt: skip
    if contact == "hop":
        assert int(np.asarray(runs[1].n_land)) == int(np.asarray(runs[0].n_land)) >= 3
        return
    dyn = lj.Smoothed(1e-2, rtol=1e-10, atol=1e-12)
    smooth = [lj.simulate(_topology(layout, k_tilt=k_tilt), 5.0, save[:21], dynamics=dyn)
              for layout in ("unrolled", "array")]  # fmt: skip
    assert int(smooth[1].status) == lj.Status.OK
    np.testing.assert_allclose(np.asarray(smooth[1].x), np.asarray(smooth[0].x), rtol=0, atol=1e-8)


def _pipe(n: int, **kw) -> lj.Mechanism:
    """A worm of `n` segments in a pipe: neighbours joined by springs driven as a travelling wave,
    every third segment to the one after next by a passive spring, the head tied to the pipe's end
    (the wall) by a soft spring and a damper, a drag-like external force on the tail."""
    links: list = []
    for j in range(n - 1):
        phase = 1.1 * j
        links.append(lj.Spring(j, j + 1, k=40.0, rest=_wave([0.08 * np.sin(-phase)], [0.08 * np.cos(-phase)], 1.0)))
    links += [lj.Spring(j, j + 2, k=5.0, rest=2.0) for j in range(0, n - 2, 3)]
    links += [lj.Spring(lj.WALL, 0, k=0.5, rest=1.0), lj.Damper(lj.WALL, 0, c=0.05),
              lj.ExternalForce(n - 1, _wave([0.02], [0.0], -0.05))]  # fmt: skip
    law = lj.AnisotropicCoulomb(0.7, 0.9, 0.5, 0.7)
    return lj.Mechanism(masses=np.linspace(0.8, 1.2, n), c=0.02, x0=1.0 + np.arange(n), links=links, friction=law, **kw)


def test_a_long_mechanism_in_the_array_layout_against_the_reference():
    """A worm of `ARRAY_FROM` (16) segments in a pipe (`_pipe`), which `layout="auto"` runs in the
    array layout, against the independent reference over t = 0 ... 6: positions and velocities within
    1e-6 at dt = 1/200 (the engine's truncation error; measured 1.2e-7), e_d and w within 1e-6, the same worm
    unrolled within 1e-10; w = e_d + Delta e to 1e-8."""
    from reference_mechanism import Body, run, Sig, System

    n = ARRAY_FROM
    worm = _pipe(n)
    assert uses_array(worm) and isinstance(engine_physics(worm), ArrayMechanismPhysics)
    assert not uses_array(_pipe(n - 1))
    save = np.linspace(0.0, 6.0, 13)
    tr = lj.simulate(worm, 6.0, save, dynamics=lj.Exact(dt=1 / 200))
    assert int(tr.status) == lj.Status.OK and int(np.asarray(tr.n_switch)) > 20
    m = np.linspace(0.8, 1.2, n)
    bodies = [Body(float(m[i]), (0.7, 0.9, 0.5, 0.7), c=0.02, x0=1.0 + i) for i in range(n)]
    springs = [(j, j + 1, 40.0, Sig(1.0, (0.08 * np.sin(-1.1 * j),), (0.08 * np.cos(-1.1 * j),), OMEGA))
               for j in range(n - 1)]  # fmt: skip
    springs += [(j, j + 2, 5.0, 2.0) for j in range(0, n - 2, 3)] + [(-1, 0, 0.5, 1.0)]
    system = System(bodies, springs=springs, dampers=[(-1, 0, 0.05)],
                    externals=[(n - 1, Sig(-0.05, (0.02,), (0.0,), OMEGA))])  # fmt: skip
    ref = run(system, 6.0, save)
    assert ref["status"] == "ok"
    err = {k: float(np.abs(np.asarray(getattr(tr, k)) - ref[r]).max()) for k, r in
           (("x", "x"), ("v", "v"), ("e_d", "ed"), ("w", "w"))}  # fmt: skip
    print("against the reference:", err)
    assert max(err.values()) < 1e-6, err
    assert float(np.abs(np.asarray(tr.w - tr.e_d - (tr.e - tr.e[0]))).max()) < 1e-8
    unrolled = lj.simulate(_pipe(n, layout="unrolled"), 6.0, save, dynamics=lj.Exact(dt=1 / 200))
    np.testing.assert_allclose(np.asarray(tr.x), np.asarray(unrolled.x), rtol=0, atol=1e-10)


def test_array_mechanism_steady_gait_equals_unrolled():
    """The steady gait of the anchored topology (strict contact) in the array layout: the unrolled
    layout's section state to 1e-8, the same period and switch count, stable in both, the same
    dissipation, work and least normal load per period (1e-8) and Floquet multipliers (1e-7)."""
    gaits = [lj.steady_gait(_topology(layout, k_tilt=0.2), periods=(1, 2), transient=20,
                            dynamics=lj.Exact(dt=0.01)) for layout in ("unrolled", "array")]  # fmt: skip
    for g in gaits:
        assert int(g.status) == lj.GaitStatus.CONVERGED and bool(g.stable)
    assert int(gaits[0].k) == int(gaits[1].k) and int(gaits[0].n_switch) == int(gaits[1].n_switch)
    np.testing.assert_allclose(np.asarray(gaits[1].state), np.asarray(gaits[0].state), rtol=0, atol=1e-8)
    for name in ("e_d", "work", "min_normal"):  # anchored: it dissipates per period but does not travel
        np.testing.assert_allclose(float(getattr(gaits[1], name)), float(getattr(gaits[0], name)), rtol=1e-8)
    np.testing.assert_allclose(np.abs(np.asarray(gaits[1].multipliers)), np.abs(np.asarray(gaits[0].multipliers)),
                               rtol=0, atol=1e-7)  # fmt: skip


def test_array_mechanism_bad_configuration_flagged_others_unchanged():
    """In a batch of three (`check=False`), the one with a negative mass is flagged `INVALID` in the
    array layout and the two others are their own single runs, to the last bit."""
    masses = np.array([[1.0, 1.2, 0.5, 0.3], [1.0, -1.2, 0.5, 0.3], [1.1, 1.0, 0.6, 0.3]])
    batch = _topology("array", k_tilt=0.2, check=False)
    batch = lj.Mechanism(masses=masses, c=batch.c, x0=X0, links=batch.links, friction=batch.friction[0],
                         layout="array", check=False)  # fmt: skip
    save = np.linspace(0.0, 4.0, 9)
    out = lj.simulate(batch, 4.0, save, dynamics=lj.Exact(dt=0.01))
    status = np.asarray(out.status)
    assert status[1] == lj.Status.INVALID and status[0] == status[2] == lj.Status.OK
    for i in (0, 2):
        one = lj.simulate(batch[i], 4.0, save, dynamics=lj.Exact(dt=0.01))
        np.testing.assert_array_equal(np.asarray(out.x)[i], np.asarray(one.x))


def test_mixed_waveforms_in_the_array_layout_against_the_reference():
    """Springs and forces driven by every kind of signal at once (splines of 4 and of 6 control values, a
    waveform class of a user's own, a `Sinusoid`, a `Fourier` series, constants), a batch of two, in the
    array layout: the waveforms are three groups of the bank (the two 4-value splines one group);
    each configuration within 1e-6 of the independent reference at dt = 1/200 (measured 2.4e-7) and
    within 1e-10 of the unrolled layout; in float32 within 1e-5 of float64."""
    from mechanism_cases import Cubed
    from reference_mechanism import Body, run, Sig, System

    c4 = np.array([[0.08, -0.05, 0.02, -0.05], [0.03, 0.0, -0.06, 0.03]])
    c6 = np.array([0.1, -0.1, 0.2, 0.0, -0.1, 0.0])
    user = Cubed(jnp.asarray(0.15), jnp.asarray(OMEGA), jnp.asarray(1.0))

    def mechanism(layout: str) -> lj.Mechanism:
        links = [lj.Spring(0, 1, k=20.0, rest=lj.Spline(jnp.asarray(c4), OMEGA, 1.0)),
                 lj.Spring(1, 2, k=15.0, rest=1.0),
                 lj.Spring(2, 3, k=12.0, rest=lj.Sinusoid(0.1, OMEGA, 1.0)),
                 lj.Spring(lj.WALL, 0, k=2.0, rest=lj.Spline(jnp.asarray(c4[::-1]), OMEGA, 2.0)),
                 lj.Spring(1, 3, k=8.0, rest=user), lj.Force(0, 2, lj.Spline(jnp.asarray(c6), OMEGA, 0.0)),
                 lj.ExternalForce(3, _wave([0.0, 0.05], [0.05, 0.0], 0.01))]  # fmt: skip
        return lj.Mechanism(masses=[1.0, 0.8, 1.2, 0.6], friction=lj.AnisotropicCoulomb(0.6, 0.8, 0.45, 0.6),
                            x0=[2.0, 3.0, 4.0, 5.0], links=links, layout=layout)  # fmt: skip

    bank = mechanism("array").array_physics().bank
    assert bank is not None and bank.rows == ((0, 3), (4,), (5,)) and bank.size == 7
    save = np.linspace(0.0, 5.0, 11)
    dyn = lj.Exact(dt=1 / 200)
    tr = lj.simulate(mechanism("array"), 5.0, save, dynamics=dyn)
    unrolled = lj.simulate(mechanism("unrolled"), 5.0, save, dynamics=dyn)
    assert (np.asarray(tr.status) == lj.Status.OK).all() and (np.asarray(tr.n_switch) > 5).all()
    np.testing.assert_allclose(np.asarray(tr.x), np.asarray(unrolled.x), rtol=0, atol=1e-10)
    mean, A, B = user.fourier()
    err = 0.0
    for b in range(2):
        springs = [
            (0, 1, 20.0, Sig(1.0, w=OMEGA, control=tuple(c4[b]))),
            (1, 2, 15.0, 1.0),
            (2, 3, 12.0, Sig(1.0, (0.0,), (0.1,), OMEGA)),
            (-1, 0, 2.0, Sig(2.0, w=OMEGA, control=tuple(c4[::-1][b]))),
            (1, 3, 8.0, Sig(mean, A, B, OMEGA)),
        ]
        bodies = [Body(m, (0.6, 0.8, 0.45, 0.6), x0=x0) for m, x0 in zip([1.0, 0.8, 1.2, 0.6], [2.0, 3.0, 4.0, 5.0])]
        system = System(bodies, springs=springs, forces=[(0, 2, Sig(0.0, w=OMEGA, control=tuple(c6)))],
                        externals=[(3, Sig(0.01, (0.0, 0.05), (0.05, 0.0), OMEGA))])  # fmt: skip
        ref = run(system, 5.0, save)
        assert ref["status"] == "ok"
        err = max(err, *(float(np.abs(np.asarray(getattr(tr, k))[b] - ref[k]).max()) for k in ("x", "v")))
    print("against the reference:", err)
    assert err < 1e-6
    # float32 at dt = 1/100 against float64 at the same step: measured 3.3e-7.
    runs = [lj.simulate(mechanism("array"), 5.0, save, dynamics=lj.Exact(dt=1 / 100), dtype=dtype)
            for dtype in (jnp.float32, jnp.float64)]  # fmt: skip
    assert runs[0].x.dtype == jnp.float32 and (np.asarray(runs[0].status) == lj.Status.OK).all()
    np.testing.assert_allclose(np.asarray(runs[0].x, np.float64), np.asarray(runs[1].x), rtol=0, atol=1e-5)


def test_array_layout_of_an_unknown_name_refused():
    """An unknown layout is named in the error; a capsule (a carried body) and bodies under laws of
    different classes take the array layout from the threshold."""
    law = lj.Coulomb(0.7, 0.5)
    capsule: dict[str, Any] = dict(masses=[1.0, 0.5], friction=[law, None], carried_by=[None, 0],
                                   links=[lj.Spring(0, 1, k=10.0)])  # fmt: skip
    with pytest.raises(ValueError, match=r"Invalid parameter 'layout'.*'sparse'"):
        lj.Mechanism(**capsule, layout="sparse")
    mixed: dict[str, Any] = dict(masses=[1.0, 0.5], friction=[law, lj.AnisotropicCoulomb(0.6, 0.9, 0.4, 0.7)],
                 links=[lj.Spring(0, 1, k=10.0, rest=1.0)], x0=[0.0, 1.0])  # fmt: skip
    for kw in (capsule, mixed):
        assert uses_array(lj.Mechanism(**kw), 2) and not uses_array(lj.Mechanism(**kw), 3)


def _capsule(layout: str, k_tilt: float = 1.0, heavy: bool = False, drive: float = 0.6, **kw) -> lj.Mechanism:
    """Six bodies under three classes of law and none: a shell (body 0, anisotropic bristles) carrying an
    internal mass (1) that carries another (2), driven by a force between shell and mass; a body on
    Stribeck friction (3) and one on Coulomb friction (5) tied to the shell and to the internal mass by
    tilted springs (a carried body's lift bears on the shell); a free body (4) on a spring, a damper and
    a tilted spring to the wall, pushed by an external force. `heavy`: masses for which every ground
    reaction stays above the placeholder load 1 of the bodies without contact."""
    links = [lj.Spring(0, 1, k=10.0, rest=0.0), lj.Force(0, 1, _wave([0.0], [drive], 0.0)),
             lj.Spring(1, 2, k=8.0, rest=_wave([0.02], [0.05], 0.1)),
             lj.TiltedSpring(0, 3, k=3.0 * k_tilt, d=0.4, rest=_wave([0.0], [0.1], 1.2)),
             lj.TiltedSpring(1, 5, k=2.0 * k_tilt, d=0.3, rest=2.2), lj.Spring(3, 4, k=6.0, rest=1.0),
             lj.Damper(3, 4, c=0.05), lj.TiltedSpring(lj.WALL, 4, k=k_tilt, d=0.5, rest=3.5),
             lj.ExternalForce(4, _wave([0.05], [0.0], 0.02)),
             lj.Spring(3, 5, k=5.0, rest=_wave([0.0, 0.01], [0.08, 0.0], 1.0)), lj.Damper(lj.WALL, 5, c=0.1),
             lj.Damper(0, 1, c=0.3), lj.Damper(1, 2, c=0.2)]  # fmt: skip
    laws = [lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15), None, None, lj.Stribeck(0.15, 0.1, 0.2), None,
            lj.Coulomb(0.12, 0.1)]  # fmt: skip
    masses = [2.0, 0.5, 0.3, 1.8, 0.6, 1.9] if heavy else [1.0, 0.5, 0.3, 0.8, 0.6, 0.9]
    return lj.Mechanism(masses=masses, friction=laws, carried_by=[None, 0, 1, None, None, None], links=links,
                        x0=CAPSULE_X0, c=[0.02, 0.0, 0.0, 0.01, 0.03, 0.0], restitution=[0.3, 0.0, 0.0, 0.5, 0.2, 0.1],
                        layout=layout, **kw)  # fmt: skip


CAPSULE_X0 = [0.0, 0.0, 0.1, 1.2, 2.3, 2.2]


@pytest.mark.parametrize("hop", [False, True])
def test_array_capsule_rates_equal_unrolled(hop):
    """Carried and free bodies and laws of three classes in one entry (`_capsule`): at a random state
    the loads and their first two rates, the kinetic coefficients and static limits, the fall in
    flight, what a body rides in and lands with, the initial heights and the entries in contact equal
    the unrolled physics' to 1e-13."""
    rng = np.random.default_rng(5 + hop)
    unrolled, array = _capsule("unrolled").physics(), _capsule("array").array_physics()
    assert isinstance(array, ArrayMechanismPhysics) and isinstance(array.friction[0], MixedFriction)
    x, v, a, y, yd, ya = _random_state(rng, CAPSULE_X0, hop)
    out = []
    for physics in (unrolled, array):
        P: Any = physics
        B: Any = lambda q: None if q is None else P.bodies(q)
        _, L, _, common = _loads(P, x, v, a, y, yd, ya)
        sgn = lambda q: jnp.where(q >= 0, 1.0, -1.0)
        mu = tuple(law.kinetic(jnp.abs(q), sgn(q)) for law, q in zip(P.friction, B(v)))
        dmu = tuple(law.kinetic_rate(jnp.abs(q), sgn(q), r) for law, q, r in zip(P.friction, B(v), B(a)))
        y0, w0, e, _ = P.hop()
        # The bodies in contact: a count over them, and their least load.
        count = sum(jnp.sum(q) for q in P.contact_values(B(jnp.arange(1, 7)), 0))
        out.append(common | dict(mu=P.stacked(mu), mu_f=P.stacked(P.mu_f),
                                 dmu=P.stacked(tuple(jnp.zeros(jnp.shape(q)) if r is None else r
                                                     for q, r in zip(mu, dmu))),
                                 ride=P.stacked(P.ride(B(x))), land=P.stacked(P.landing_masses()), y0=y0, w0=w0,
                                 e=P.stacked(e), count=count, least=least_contact_load(P, L.N, x)))  # fmt: skip
    for key, want in out[0].items():
        np.testing.assert_allclose(np.asarray(out[1][key]), np.asarray(want), rtol=1e-13, atol=1e-13, err_msg=key)
    assert int(out[1]["count"]) == 1 + 4 + 6  # bodies 0, 3 and 5
    # Its Stribeck member makes the mixture a law whose kinetic coefficient at rest is the static one.
    coulombs = MixedFriction((lj.Coulomb(0.6, 0.5), lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15)), (0, 1, 0))
    assert static_at_rest(array.friction[0]) and not static_at_rest(coulombs)
    assert float(jnp.abs(out[0]["dmu"]).max()) > 0  # the Stribeck body's coefficient moves


@pytest.mark.parametrize("contact", ["strict", "hop"])
def test_array_capsule_runs_equal_unrolled(contact):
    """`simulate` of `_capsule` in both layouts (exact engine, dt = 0.005, t = 0 ... 10): positions,
    velocities, energies and normal loads equal to 1e-10 with the same events; under `contact="hop"`
    (the shell thrown up, body 5 too) the same landings, the carried bodies' heights their shell's.
    The smoothed engine likewise (1e-8 at rtol 1e-10)."""
    save = np.linspace(0.0, 10.0, 41)
    hop: dict[str, Any] = (
        dict(y0=[0.2, 0.0, 0.0, 0.0, 0.0, 0.1], w0=[0.3, 0.0, 0.0, 0.0, 0.0, 0.25]) if contact == "hop" else {}
    )
    k_tilt = 0.2 if contact == "strict" else 1.0
    runs = [lj.simulate(_capsule(layout, k_tilt, **hop), 10.0, save, contact=contact, dynamics=lj.Exact(dt=0.005))
            for layout in ("unrolled", "array")]  # fmt: skip
    assert int(runs[0].status) == int(runs[1].status) == lj.Status.OK
    assert int(np.asarray(runs[0].n_switch)) == int(np.asarray(runs[1].n_switch)) > 20
    fields = ["x", "v", "e_d", "w", "e", "N"] + (["y", "vy"] if contact == "hop" else [])
    for name in fields:
        np.testing.assert_allclose(np.asarray(getattr(runs[1], name)), np.asarray(getattr(runs[0], name)), rtol=0,
                                   atol=1e-10, err_msg=name)  # fmt: skip
    if contact == "hop":
        tr = runs[1]
        assert tr.y is not None and runs[0].n_land is not None and tr.n_land is not None
        assert int(np.asarray(tr.n_land)) == int(np.asarray(runs[0].n_land)) >= 5
        for i in (1, 2):
            np.testing.assert_array_equal(np.asarray(tr.y)[:, i], np.asarray(tr.y)[:, 0])
        return
    dyn = lj.Smoothed(1e-2, rtol=1e-10, atol=1e-12)
    smooth = [lj.simulate(_capsule(layout, k_tilt), 5.0, save[:21], dynamics=dyn) for layout in ("unrolled", "array")]
    assert int(smooth[1].status) == lj.Status.OK
    np.testing.assert_allclose(np.asarray(smooth[1].x), np.asarray(smooth[0].x), rtol=0, atol=1e-8)


def test_array_capsule_steady_gait_equals_unrolled():
    """The steady gait of `_capsule` (heavy: every ground reaction above the placeholder 1; the shell
    driven to slip) in the array layout: the unrolled layout's section state to 1e-8, the same period,
    switches and stability, and the same least normal load, which leaves the bodies without contact out
    (their placeholder 1 is below it)."""
    gaits = [lj.steady_gait(_capsule(layout, 0.2, heavy=True, drive=3.0), periods=(1, 2), transient=20,
                            dynamics=lj.Exact(dt=0.01)) for layout in ("unrolled", "array")]  # fmt: skip
    for g in gaits:
        assert int(g.status) == lj.GaitStatus.CONVERGED and bool(g.stable) and int(g.n_iter) > 0
    assert int(gaits[0].k) == int(gaits[1].k) and int(gaits[0].n_switch) == int(gaits[1].n_switch)
    np.testing.assert_allclose(np.asarray(gaits[1].state), np.asarray(gaits[0].state), rtol=0, atol=1e-8)
    for name in ("e_d", "work", "min_normal"):
        np.testing.assert_allclose(float(getattr(gaits[1], name)), float(getattr(gaits[0], name)), rtol=1e-8)
    assert 1.0 < float(gaits[1].min_normal) < 2.0
