"""Property-based fuzzing of the front ends (issue 29): hostile but fair inputs.

Parameters, chains, waveforms and friction laws are drawn from wide ranges that include
zero, negative, tiny, huge and non-finite values. Whatever comes in, the answer is one of:

- a clear `ValueError` (a message that names what is wrong), raised before any computation;
- a flagged status (`INVALID`, `UNRESOLVED`, `LIFTOFF`, `COLLISION`, `MAX_STEPS`, ...);
- status `OK` with finite results (sentinels `inf` only where documented: a distance not
  reached) that satisfy the energy balance $w = e_d + \\Delta e$.

Never status `OK` with a NaN; never a `CONVERGED` steady gait whose dissipation is not its
actuators' work (its elements drawn from fair ranges, `GAIT_MECHANISM`). Each test fixes the
shapes, the waveform type and the friction law, so that every example reuses one compiled
program; horizons are short. The default run
draws a few hundred examples in all (derandomised, so CI is reproducible); `--slow` draws
`LJ_FUZZ_SCALE` (20) times as many, with a fresh seed.
"""

import math
import os
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from hypothesis import given, HealthCheck, settings, strategies as st
from locomotion_jax.model._params import PARAM_NAMES
from locomotion_jax.run._resolution import chain_scales, two_mass_scales


SCALE = int(os.environ.get("LJ_FUZZ_SCALE", "1"))
SHORT: dict[str, Any] = dict(z=0.2, t_start=0.5, horizon=3.0, window=1.0)
DT = 0.01
BALANCE_RTOL = 1e-6
"""Energy-balance residual allowed relative to the energies' scale, on top of the RK4 error
`_resolution_error`: the exact engine's residual is the integration error, about 1e-7 at the
paper's resolution and growing as $(\\omega\\,\\Delta t)^4$ towards the resolution floor
(4 steps per period, $\\omega\\,\\Delta t = \\pi/2$)."""


def _resolution_error(scales, run: float | None = None) -> float:
    """$r^4$ with $r$ the largest $\\omega\\,\\Delta t$ (periods) or $\\Delta t/\\tau$ (times) of one
    configuration's scales: the relative error a fourth-order step may leave in the energies.
    With `run` (its duration), times the shortest scale's periods in it: near the resolution floor
    the step's energy error piles up period by period (a stiff spring of 9 steps a period loses
    0.6 % of its energy a period at `dt = 0.01`, and converges at fifth order in `dt`)."""
    r, shortest = 0.0, math.inf
    for s in scales:
        t = float(np.asarray(s.time).reshape(-1)[0])
        if np.isfinite(t) and t > 0 and s.unit != "span":
            r = max(r, DT / t * (2 * math.pi if s.unit == "period" else 1.0))
            shortest = min(shortest, t)
    periods = 1.0 if run is None or not math.isfinite(shortest) else max(1.0, run / shortest)
    return min(r, 1e3) ** 4 * periods


def _flat(mech):
    return jax.tree_util.tree_map(lambda x: x.reshape((1,) + x.shape[len(mech.batch_shape) :]), mech.broadcast())


SPECIAL = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e-300, 5e-324, 1e300, -1e300]


def _fuzz(n: int):
    return settings(
        max_examples=n * SCALE,
        deadline=None,
        derandomize=SCALE == 1,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


def fair(lo: float, hi: float, log: bool = False):
    """A value in [lo, hi] (log-uniform if `log`), never special."""
    if log:
        return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10.0**e)
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def wide(lo: float, hi: float, log: bool = False):
    """A value in [lo, hi] (log-uniform if `log`), or, one time in `1 / SPECIAL_RATE`, a hostile
    special value (so that most examples are valid and run, and every kind of bad value comes up)."""
    return rarely(fair(lo, hi, log), st.sampled_from(SPECIAL))


def rarely(usual, unusual, rate: int | None = None):
    """`unusual` one time in `rate` (default `SPECIAL_RATE`), else `usual`."""
    n = SPECIAL_RATE if rate is None else rate
    return st.integers(0, n - 1).flatmap(lambda i: unusual if i == 0 else usual)


SPECIAL_RATE = 25
"""One value in this many is special: with 9 parameters, about 30% of the examples hold one."""


@st.composite
def params_values(draw):
    """The paper's parameters over wide ranges; `d`, `a` relative to `lbar` and `mu_s` above `mu_k`
    mostly, so that the relations between them are met by most and broken by some."""
    lbar = draw(wide(0.1, 10.0))
    mu_k = draw(wide(0.0, 1.5))
    return dict(
        k=draw(wide(1e-3, 1e5, log=True)),
        c=draw(rarely(wide(1e-4, 1e3, log=True), st.just(0.0), 10)),
        d=draw(wide(-1.1, 1.1)) * lbar,
        lbar=lbar,
        a=draw(wide(0.0, 0.3)) * lbar,
        omega=draw(rarely(wide(1e-3, 1e4, log=True), st.just(0.0), 10)),
        mu_s=mu_k + draw(wide(-0.1, 1.0)),
        mu_k=mu_k,
        mhat=draw(rarely(wide(0.02, 0.98), st.sampled_from([0.0, 1e-9, 1 - 1e-9, 1e-310, 1.0]))),
    )


PARAMS = tuple(PARAM_NAMES)


FLOAT_FIELDS = ("tau_z", "e_z", "mean_speed", "cost_of_transport", "e_d", "work", "delta_e", "balance", "t_liftoff")
SENTINEL_INF = ("tau_z", "e_z", "cost_of_transport", "t_liftoff")  # documented `inf`: not reached / none


def _check_measurement(m, i=(), rtol=BALANCE_RTOL, energy=None):
    """`energy()`: the largest energy the mechanism holds during the run, asked for only where the
    residual exceeds `rtol` against the energies exchanged in the window. The fuzz found two runs
    whose residual is the integration error of a much larger stored energy: a frictionless,
    undriven one exchanges nothing (residual 6.6e-10, energy 0.07), and a frictionless stiff
    one (`k = 1000`) exchanges 1e-3 while it holds 0.05 (residual 5e-4 at `dt = 0.01`, 1.6e-5
    at 0.005, 5e-7 at 0.0025: the step's fifth-order convergence)."""
    status = int(np.asarray(m.status)[i])
    assert status in {int(s) for s in lj.Status}
    if status != lj.Status.OK:
        return
    for name in FLOAT_FIELDS:
        v = np.asarray(getattr(m, name))[i]
        assert not np.isnan(v).any(), f"status OK with {name} = NaN"
        if name not in SENTINEL_INF:
            assert np.isfinite(v).all(), f"status OK with {name} = {v}"
    work, e_d, de, bal = (float(np.asarray(getattr(m, k))[i]) for k in ("work", "e_d", "delta_e", "balance"))
    scale = max(abs(work), abs(e_d), abs(de), 1e-12)
    if abs(bal) > rtol * scale + 1e-12 and energy is not None:
        scale = max(scale, abs(energy()))
    assert abs(bal) <= rtol * scale + 1e-12, f"energy balance {bal} against energies of {scale} (rtol {rtol:.3g})"


def _start_energy(p, wave=None):
    """The largest energy (eq. 10) of one configuration of the paper's model over the run."""
    return _held(p, wave)


def _held(mechanism, wave=None):
    """The largest energy one configuration (the paper's model or a chain) holds over the run.
    (Also found at `LJ_FUZZ_SCALE=20`: a frictionless, undriven chain, residual 5e-11 of its
    held energy, none exchanged.)"""
    t = SHORT["t_start"] + SHORT["horizon"]
    kw = {} if wave is None else dict(waveform=wave)
    run = lambda: lj.simulate(mechanism, t, np.linspace(0.0, t, 65), dynamics=lj.Exact(DT), **kw)
    return lambda: float(np.max(np.abs(np.asarray(run().e))))


def _two_mass_rtol(p, wave=None) -> float:
    flat = _flat(p)
    wave = lj.Sinusoid.from_params(flat) if wave is None else wave
    return BALANCE_RTOL + _resolution_error(two_mass_scales(flat, wave))


def _refused_clearly(err: ValueError):
    msg = str(err)
    assert msg and "Traceback" not in msg
    assert any(w in msg for w in ("Invalid parameter", "must", "valid range", "does not resolve", "Parameters")), msg


@_fuzz(150)
@given(params_values())
def test_fuzz_paper_model_measure(values):
    try:
        p = lj.Params(**values)
        m = lj.measure(p, **SHORT, dynamics=lj.Exact(DT))
    except ValueError as err:
        _refused_clearly(err)
        return
    _check_measurement(m, rtol=_two_mass_rtol(p), energy=_start_energy(p))


@_fuzz(25)
@given(st.lists(params_values(), min_size=16, max_size=16))
def test_fuzz_paper_model_batch_is_flagged_never_nan(rows):
    # A batch is never refused for a bad member (check=False): each is flagged in its own result.
    cols = {k: jnp.asarray([r[k] for r in rows]) for k in PARAMS}
    m = lj.measure(lj.Params(**cols, check=False), **SHORT, dynamics=lj.Exact(DT))
    for i in range(16):
        try:
            p = lj.Params(**rows[i], check=False)
            _check_measurement(m, (i,), _two_mass_rtol(p), energy=_start_energy(p))
        except AssertionError as err:
            raise AssertionError(f"{err} at row {i}: {rows[i]}") from None


@_fuzz(60)
@given(
    params_values(),
    st.lists(wide(-0.3, 0.3), min_size=2, max_size=2),
    st.lists(wide(-0.3, 0.3), min_size=2, max_size=2),
)
def test_fuzz_fourier_waveform(values, cos, sin):
    try:
        wave = lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), values["omega"], values["lbar"])
        p = lj.Params(**values)
        m = lj.measure(p, **SHORT, dynamics=lj.Exact(DT), waveform=wave)
    except ValueError as err:
        _refused_clearly(err)
        return
    _check_measurement(m, rtol=_two_mass_rtol(p, wave), energy=_start_energy(p, wave))


def _friction(kind: str, mu_s, mu_k, v_s):
    if kind == "coulomb":
        return lj.Coulomb(mu_s, mu_k)
    if kind == "anisotropic":
        return lj.AnisotropicCoulomb(mu_s, mu_s * 1.2, mu_k, mu_k * 1.1)
    return lj.Stribeck(mu_s, mu_k, v_s)


CHAIN: dict[str, Any] = dict(
    masses=st.lists(wide(1e-3, 1e3, log=True), min_size=3, max_size=3),
    k=st.lists(wide(1e-2, 1e5, log=True), min_size=2, max_size=2),
    d=st.lists(wide(-4.0, 4.0), min_size=2, max_size=2),
    c=wide(1e-4, 1e2, log=True),
    a=wide(0.0, 0.5),
    omega=rarely(wide(1e-3, 1e4, log=True), st.just(0.0), 10),
    phi=wide(-7.0, 7.0),
    mu_s=wide(0.5, 1.5),
    mu_k=wide(0.0, 0.6),
    v_s=wide(1e-6, 1.0, log=True),
)


@pytest.mark.parametrize("kind", ["coulomb", "anisotropic", "stribeck"])
@_fuzz(40)
@given(st.fixed_dictionaries(CHAIN))
def test_fuzz_chain_measure(kind, values):
    v = values
    try:
        chain = lj.Chain(
            masses=jnp.asarray(v["masses"]), k=jnp.asarray(v["k"]), d=jnp.asarray(v["d"]), lbar=3.0, c=v["c"],
            waveforms=lj.TravellingWave(v["a"], v["omega"], v["phi"]),
            friction=_friction(kind, v["mu_s"], v["mu_k"], v["v_s"]),
        )  # fmt: skip
        m = lj.measure(chain, **SHORT, dynamics=lj.Exact(DT))
    except ValueError as err:
        _refused_clearly(err)
        return
    _check_measurement(m, rtol=BALANCE_RTOL + _resolution_error(chain_scales(_flat(chain))), energy=_held(chain))


MECHANISM: dict[str, Any] = dict(
    masses=st.lists(wide(1e-3, 1e3, log=True), min_size=3, max_size=3),
    k=st.lists(wide(1e-2, 1e4, log=True), min_size=3, max_size=3),
    d=wide(-4.0, 4.0),
    rest=wide(0.5, 5.0),
    f=wide(0.0, 5.0),
    g=wide(-2.0, 2.0),
    omega=rarely(wide(1e-3, 1e3, log=True), st.just(0.0), 10),
    c=wide(0.0, 10.0),
    mu_s=wide(0.3, 1.5),
    mu_k=wide(0.0, 0.6),
    x0=wide(-2.0, 2.0),
    v0=wide(-3.0, 3.0),
)


def _mechanism(v) -> lj.Mechanism:
    """Every kind of element at once: a capsule (body 0, anisotropic friction) carrying body 1 on a
    spring and pushing it by a force, tied to the wall; body 2 on Coulomb friction, joined to the
    capsule by a tilted spring of actuated rest length and a damper, pulled by an external force."""
    masses, (k, k_tilted, k_wall), wave = v["masses"], v["k"], lambda a, mean: lj.Sinusoid(a, v["omega"], mean)
    return lj.Mechanism(
        masses=masses, carried_by=[None, 0, None],
        friction=[lj.AnisotropicCoulomb(v["mu_s"], v["mu_s"] * 1.2, v["mu_k"], v["mu_k"] * 1.1), None,
                  lj.Coulomb(v["mu_s"], v["mu_k"])],
        links=[lj.Spring(0, 1, k=k, rest=0.0), lj.Force(0, 1, wave(v["f"], 0.0)),
               lj.TiltedSpring(0, 2, k=k_tilted, d=v["d"], rest=wave(0.1, v["rest"])),
               lj.Spring(lj.WALL, 0, k=k_wall, rest=-3.0), lj.Damper(0, 2, v["c"]),
               lj.ExternalForce(2, wave(v["g"], 0.0))],
        x0=[0.0, v["x0"], v["rest"]], v0=[0.0, v["v0"], 0.0],
    )  # fmt: skip


@pytest.mark.parametrize("contact", ["strict", "hop"])
@_fuzz(60)
@given(st.fixed_dictionaries(MECHANISM))
def test_fuzz_mechanism_measure(contact, values):
    try:
        mech = _mechanism(values)
        m = lj.measure(mech, **SHORT, dynamics=lj.Exact(DT), contact=contact)
    except ValueError as err:
        _refused_clearly(err)
        return
    run = SHORT["t_start"] + SHORT["horizon"]
    _check_measurement(m, rtol=BALANCE_RTOL + _resolution_error(chain_scales(_flat(mech)), run), energy=_held(mech))


FLOAT32_RTOL = 1e-4
"""float32's relative accuracy (docs/limitations.md): the energy balance of a float32 run, on top
of the step's error, against the energies exchanged (or held, as in float64)."""


@pytest.mark.parametrize("contact", ["strict", "hop"])
@_fuzz(40)
@given(st.fixed_dictionaries(MECHANISM))
def test_fuzz_mechanism_measure_float32(contact, values):
    """The mechanism fuzz in float32 (`astype` of the float64 mechanism, whose values were checked):
    refused by name, flagged, or `OK` with finite float32 figures whose energy balance holds to
    float32's accuracy. (A probe of 100 examples per contact found none outside 1e-4.)"""
    try:
        mech = _mechanism(values)
        low = mech.astype(jnp.float32)
        m = lj.measure(low, **SHORT, dynamics=lj.Exact(DT), contact=contact)
    except ValueError as err:
        _refused_clearly(err)
        return
    assert np.asarray(m.balance).dtype == np.float32
    run = SHORT["t_start"] + SHORT["horizon"]
    rtol = FLOAT32_RTOL + _resolution_error(chain_scales(_flat(mech)), run)
    _check_measurement(m, rtol=rtol, energy=_held(low))


@_fuzz(60)
@given(params_values())
def test_fuzz_paper_model_simulate(values):
    try:
        tr = lj.simulate(lj.Params(**values), 2.0, np.linspace(0.0, 2.0, 9), dynamics=lj.Exact(DT))
    except ValueError as err:
        _refused_clearly(err)
        return
    if int(tr.status) == lj.Status.OK:
        for name in ("x1", "v1", "x2", "v2", "X", "e_d", "w", "e"):
            assert np.isfinite(np.asarray(getattr(tr, name))).all(), f"status OK with a non-finite {name}"


GAIT_MECHANISM: dict[str, Any] = dict(
    masses=st.lists(fair(0.1, 10.0, log=True), min_size=3, max_size=3),
    k=st.lists(fair(1.0, 1e3, log=True), min_size=3, max_size=3),
    d=fair(-2.0, 2.0),
    rest=fair(1.0, 4.0),
    f=fair(0.0, 2.0),
    g=fair(-1.0, 1.0),
    omega=fair(0.3, 30.0, log=True),
    c=fair(0.0, 2.0),
    mu_s=fair(0.7, 1.2),
    mu_k=fair(0.0, 0.6),
    x0=fair(-1.0, 1.0),
    v0=fair(-1.0, 1.0),
)
"""`MECHANISM`'s elements over narrower ranges and without special values (whose refusals the
measure fuzz covers), so that a steady gait exists for a fair share of the examples."""


def _section_energy(mech: lj.Mechanism, g: Any) -> float:
    """The energy (SPEC §9) of an anchored mechanism's orbit at its section (phase 0), from the
    gait's state (positions, then velocities): what the orbit holds, in which a step's error
    shows up even where little energy is exchanged."""
    P = mech.broadcast().physics()
    n, s = mech.n_bodies, np.asarray(g.state, float).reshape(-1)
    one = jnp.ones(())
    x, v = tuple(jnp.asarray(s[i]) for i in range(n)), tuple(jnp.asarray(s[n + i]) for i in range(n))
    return float(P.energy(P.loads(P.drive(one, 0 * one), x), v))


@_fuzz(30)
@given(st.fixed_dictionaries(GAIT_MECHANISM))
def test_fuzz_mechanism_steady_gait(values):
    """`steady_gait` of the fuzz's mechanism (every kind of element, strict contact, 3 bodies: the
    array layout): refused by name, or a `GaitStatus`; a converged gait has finite figures and
    dissipates what its actuators do per gait period ($e_d = w$, the energy being periodic) within
    the step's error against the energies exchanged and held at the section. About half the
    derandomised examples converge; a physics that drops its external forces' power fails here
    (checked by hand: $e_d = 0.597$ against $w = -0.329$). A probe of these elements found a tilted
    spring's unresolved turn reported `CONVERGED` with $e_d$ 15 % off $w$ (now `UNRESOLVED`)."""
    try:
        mech = _mechanism(values)
        g = lj.steady_gait(mech, dynamics=lj.Exact(DT), transient=10, periods=(1, 2))
    except ValueError as err:
        _refused_clearly(err)
        return
    status = int(np.asarray(g.status))
    assert status in {int(s) for s in lj.GaitStatus}
    if status != lj.GaitStatus.CONVERGED:
        return
    for name in ("mean_speed", "e_d", "work", "state", "monodromy", "multipliers", "period"):
        assert np.isfinite(np.asarray(getattr(g, name))).all(), f"CONVERGED with a non-finite {name}"
    assert not math.isnan(float(np.asarray(g.cost_of_transport)))
    e_d, work, period = (float(np.asarray(getattr(g, k))) for k in ("e_d", "work", "period"))
    rtol = BALANCE_RTOL + _resolution_error(chain_scales(_flat(mech)), period)
    scale = max(abs(e_d), abs(work), abs(_section_energy(mech, g)), 1e-12)
    assert abs(e_d - work) <= rtol * scale + 1e-12, f"e_d = {e_d} against w = {work} (scale {scale}, rtol {rtol:.3g})"
