"""Chain configurations on which the package's exact engine is compared with tests/reference_chain.py.

Each case is a dict with

* ``name``: a short identifier;
* ``config``: keyword arguments of ``reference_chain.chain_config`` (CHAIN_CONVENTIONS.md); a travelling wave
  is given as ``a``/``phi`` (``s_j = a sin(omega t - j phi)``, phi > 0 travels towards the front, phi < 0
  towards the rear), any other waveform as Fourier coefficients ``wave_A``/``wave_B`` of shape (N-1, H);
* ``contact``, ``start``: as in ``reference_chain_measure``;
* ``t_start`` (optional): the measurement start where the default (80 periods of the lowest natural frequency
  with one mass held fixed) would make the run long; absent means the default.

Measurement for all: ``z = Z``, ``t_start`` as above, ``horizon = HORIZON`` after it, regime window 25.
Every case reaches ``z = 5`` within the horizon, none lifts off under its contact, and the masses stay well
apart (no resonance pushes them through each other).  No reference numbers are stored here: tests run the
reference live.

``python tests/chain_cases.py [name ...]`` prints, per case, the reference's tau_5 (or the mean speed where
5 is not reached), e_5, regime, stick fractions and run time.
"""

import math


Z = 5.0
HORIZON = 1200.0
P = math.pi
# Anisotropic Coulomb: backward harder than forward (bristles pointing backwards).
ANISO = dict(mu_s_fwd=0.7, mu_s_bwd=0.9, mu_k_fwd=0.5, mu_k_bwd=0.7)


def _two_harmonic_wave(n_springs: int, a1: float, a2: float, phi: float) -> dict:
    """``s_j = a1 sin(omega t - j phi) + a2 sin(2 omega t - 2 j phi + pi/3)`` as Fourier coefficients."""
    rows_A, rows_B = [], []
    for j in range(n_springs):
        rows_A.append([-a1 * math.sin(j * phi), a2 * math.sin(P / 3 - 2 * j * phi)])
        rows_B.append([a1 * math.cos(j * phi), a2 * math.cos(P / 3 - 2 * j * phi)])
    return dict(wave_A=rows_A, wave_B=rows_B)


CASES = [
    # --- rest-length actuator, Coulomb friction ------------------------------------------------------------
    # N = 3, isotropic, d = 0.5, wave towards the front, stick-slip (all three masses stick); relaxed start.
    dict(
        name="n3_iso_fwd_ssl",
        config=dict(masses=[1.0] * 3, omega=3.0, a=0.08, phi=2 * P / 3),
        contact="strict",
        start="relaxed",
    ),
    # N = 3, isotropic, d = 0.5, wave towards the rear, only the middle mass sticks; paper start (pre-stretched).
    dict(
        name="n3_iso_bwd_ssl",
        config=dict(masses=[1.0] * 3, omega=6.0, a=0.05, phi=-2 * P / 3),
        contact="strict",
        start="paper",
    ),
    # N = 3, unequal masses and stiffnesses, offsets of both signs, paper contact (n = |N|), phase lag 1 rad.
    dict(
        name="n3_unequal_paper",
        config=dict(masses=[0.8, 1.2, 1.0], k=[50.0, 40.0], d=[0.4, -0.2], omega=5.0, a=0.08, phi=1.0),
        contact="paper",
        start="relaxed",
    ),
    # N = 3, anisotropic, d = 0, between the natural frequencies: pure slip (SL) driven by anisotropy alone.
    dict(
        name="n3_aniso_d0_sl",
        config=dict(masses=[1.0] * 3, d=0.0, omega=9.0, a=0.05, phi=2 * P / 3, **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 3, isotropic, d = 0.2, above the natural frequencies: pure slip (SL) driven by the normal-force
    # modulation (the paper's SL mechanism); explicit t_start to keep the run short.
    dict(
        name="n3_iso_d02_sl",
        config=dict(masses=[1.0] * 3, d=0.2, omega=14.0, a=0.03, phi=2 * P / 3),
        contact="strict",
        start="relaxed",
        t_start=60.0,
    ),
    # N = 4, anisotropic, d = 0.5, wave towards the front, stick-slip.
    dict(
        name="n4_aniso_fwd_ssl",
        config=dict(masses=[1.0] * 4, omega=3.0, a=0.07, phi=P / 2, **ANISO),
        contact="strict",
        start="relaxed",
    ),
    # N = 4, anisotropic, d = 0 (constant normal forces), wave towards the rear, stick-slip.
    dict(
        name="n4_aniso_d0_bwd_ssl",
        config=dict(masses=[1.0] * 4, d=0.0, omega=3.0, a=0.08, phi=-P / 2, **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 4, anisotropic, d = 0, between the natural frequencies: pure slip (SL), fast.
    dict(
        name="n4_aniso_d0_sl",
        config=dict(masses=[1.0] * 4, d=0.0, omega=9.0, a=0.05, phi=P / 2, **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 4, isotropic, d = 0.5, a two-harmonic waveform of a different shape on every spring (Fourier input).
    dict(
        name="n4_fourier_iso",
        config=dict(
            masses=[1.0] * 4,
            d=0.5,
            omega=3.0,
            wave_A=[[0.03, 0.01]] * 3,
            wave_B=[[0.06, 0.0], [0.0, 0.02], [-0.06, 0.01]],
        ),
        contact="strict",
        start="relaxed",
    ),
    # N = 4, isotropic, d = 0, equal masses: a two-harmonic travelling wave (s(t + T/2) != -s(t)) locomotes
    # although neither d nor the friction picks a direction.
    dict(
        name="n4_iso_d0_two_harmonic",
        config=dict(masses=[1.0] * 4, d=0.0, omega=1.5, **_two_harmonic_wave(3, 0.1, 0.08, P / 2)),
        contact="strict",
        start="paper",
    ),
    # N = 6, isotropic, d = 0.5, wave towards the front (phase lag pi/3), stick-slip.
    dict(
        name="n6_iso_fwd_ssl",
        config=dict(masses=[1.0] * 6, omega=4.0, a=0.05, phi=P / 3),
        contact="strict",
        start="relaxed",
    ),
    # N = 6, anisotropic, d = 0.3, wave towards the rear, stick-slip.
    dict(
        name="n6_aniso_bwd_ssl",
        config=dict(masses=[1.0] * 6, d=0.3, omega=4.0, a=0.05, phi=-P / 3, **ANISO),
        contact="strict",
        start="relaxed",
    ),
    # N = 6, anisotropic, d = 0, low frequency: long stuck phases of several masses at once.
    dict(
        name="n6_aniso_d0_fwd_ssl",
        config=dict(masses=[1.0] * 6, d=0.0, omega=2.0, a=0.08, phi=P / 3, **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 6, anisotropic, d = 0, wave towards the rear, pure slip (SL); explicit t_start to keep the run short.
    dict(
        name="n6_aniso_d0_bwd_sl",
        config=dict(masses=[1.0] * 6, d=0.0, omega=9.0, a=0.05, phi=-P / 3, **ANISO),
        contact="strict",
        start="paper",
        t_start=100.0,
    ),
    # --- internal-force actuator ---------------------------------------------------------------------------
    # N = 3, force actuator, d = 0, anisotropic: a force wave ratchets the chain forward.
    dict(
        name="n3_force_aniso_d0",
        config=dict(masses=[1.0] * 3, d=0.0, omega=2.0, a=4.0, phi=2 * P / 3, actuator="force", **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 4, force actuator, d = 0.2 (the moving masses tilt the springs and modulate the normal forces),
    # anisotropic, wave towards the rear.
    dict(
        name="n4_force_aniso_d02",
        config=dict(masses=[1.0] * 4, d=0.2, omega=3.0, a=4.0, phi=-P / 2, actuator="force", **ANISO),
        contact="strict",
        start="relaxed",
    ),
    # N = 6, force actuator, d = 0.2, anisotropic, wave towards the front.
    dict(
        name="n6_force_aniso_d02",
        config=dict(masses=[1.0] * 6, d=0.2, omega=3.0, a=4.0, phi=P / 3, actuator="force", **ANISO),
        contact="strict",
        start="relaxed",
    ),
    # --- Stribeck kinetic law ------------------------------------------------------------------------------
    # N = 3, isotropic Stribeck (v_s = 0.2), d = 0.5, wave towards the rear.
    dict(
        name="n3_stribeck",
        config=dict(masses=[1.0] * 3, omega=6.0, a=0.05, phi=-2 * P / 3, friction="stribeck", v_s=0.2),
        contact="strict",
        start="paper",
    ),
    # N = 4, anisotropic Stribeck (each direction its own mu_s, mu_k), d = 0.
    dict(
        name="n4_stribeck_aniso_d0",
        config=dict(masses=[1.0] * 4, d=0.0, omega=6.0, a=0.05, phi=-P / 2, friction="stribeck", v_s=0.3, **ANISO),
        contact="strict",
        start="paper",
    ),
    # N = 6, anisotropic Stribeck, d = 0.3, wave towards the rear.
    dict(
        name="n6_stribeck_aniso_d03",
        config=dict(masses=[1.0] * 6, d=0.3, omega=4.0, a=0.05, phi=-P / 3, friction="stribeck", v_s=0.3, **ANISO),
        contact="strict",
        start="relaxed",
    ),
]


def main(names: list[str]) -> None:
    """Print the reference's measurement of every case (or of the named ones)."""
    import os
    import sys
    import time

    import numpy as np

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from reference_chain import chain_config, reference_chain_measure

    print(
        f"{'case':22s} {'N':>2s} {'t_start':>8s} {'tau_5':>10s} {'e_5':>9s} {'speed':>9s} {'regime':6s} "
        f"{'min gap':>7s} {'stick fractions':24s} {'cpu_s':>5s} {'wall_s':>6s}"
    )
    for case in CASES:
        if names and case["name"] not in names:
            continue
        cfg = chain_config(**case["config"])
        wall, cpu = time.perf_counter(), time.process_time()
        m = reference_chain_measure(
            cfg, z=Z, t_start=case.get("t_start"), horizon=HORIZON, contact=case["contact"], start=case["start"]
        )
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        tau = f"{m['tau_z']:10.4f}" if m["reached"] else f"{'not hit':>10s}"
        sf = " ".join(f"{s:.2f}" for s in np.asarray(m["stick_fraction"]))
        flag = " LIFTOFF" if m["liftoff"] else ""
        print(
            f"{case['name']:22s} {cfg['m'].size:2d} {m['t_start']:8.2f} {tau} {m['e_z']:9.4f} {m['mean_speed']:+9.5f} "
            f"{str(m['regime']):6s} {m['min_gap']:7.3f} {sf:24s} {cpu:5.1f} {wall:6.1f}{flag}",
            flush=True,
        )


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
