"""Mutation check: do the tests catch real bugs?

Applies each deliberate bug of `MUTATIONS` on its own to a copy of the package (in a
temporary directory; the working tree is never modified) and runs the tests meant to
catch it, the comparisons with the independent reference solvers first. A mutation is
*killed* when a test fails. The unmutated copy runs the same tests first: they must pass.

    python tests/mutations.py                 # all mutations
    python tests/mutations.py paper_n_signed  # some, by name
    python tests/mutations.py --list

The reference solvers' results are kept on disk (`LJ_REFERENCE_CACHE`, default a folder
under the system's temporary directory) between runs: they do not depend on the package.
Takes about 2 minutes per mutation on 2 cores.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple


ROOT = Path(__file__).resolve().parent.parent
REF = "tests/test_against_reference.py"


class Mutation(NamedTuple):
    name: str
    what: str
    path: str  # relative to the repository root
    edits: tuple[tuple[str, str], ...]  # (old, new): each `old` must occur exactly once
    tests: tuple[str, ...]  # pytest arguments, run in this order with -x
    equivalent: str | None = None  # why no test can kill it (its results are the unmutated ones)


CHAIN = "locomotion_jax/dynamics/_engine.py"
CHAIN_MOTION = "locomotion_jax/dynamics/_motion.py"
MEASURE = "locomotion_jax/dynamics/_measure.py"
NUMERICS = "locomotion_jax/dynamics/_numerics.py"
PARAMS = "locomotion_jax/model/_params.py"
CHAIN_MODEL = "locomotion_jax/model/_chain.py"
FRICTION = "locomotion_jax/model/_friction.py"
RESOLUTION = "locomotion_jax/run/_resolution.py"
VALIDATION = "tests/test_validation.py"
RESOLUTION_TESTS = "tests/test_resolution.py"
GUARDS_TESTS = "tests/test_resolution_guards.py"
GAIT_GUARDS = tuple(
    f"{GUARDS_TESTS}::{t}"
    for t in (
        "test_steady_gait_refuses_an_unresolved_configuration",
        "test_steady_gait_flags_it_in_a_batch_and_leaves_the_others_bitwise_equal",
        "test_chain_steady_gait_flags_it_in_a_batch_and_leaves_the_others_bitwise_equal",
    )
)
MECHANISM_GUARDS = tuple(
    f"{GUARDS_TESTS}::{t}"
    for t in (
        "test_mechanism_scales_match_closed_forms",
        "test_an_unresolved_mechanism_is_refused",
        "test_an_unresolved_mechanism_is_flagged_in_a_batch",
    )
)
SCALES = "locomotion_jax/model/_scales.py"
BODIES = "locomotion_jax/model/_bodies.py"

MUTATIONS = [
    # -- the bugs an outside audit found uncaught ----------------------------------------------
    Mutation(
        "wrong_wn1",
        "wn1 = sqrt(2 k / m1) (right only for m1 = m2)",
        "locomotion_jax/model/_params.py",
        (
            (
                "jnp.sqrt(self.k * (self.m1 + self.m2) / (self.m1 * self.m2))",
                "jnp.sqrt(self.k / self.m1 + self.k / self.m1)",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "regime_window_length",
        "the regime window is 25 whatever `window` says",
        MEASURE,
        (("ws, ws + window, te", "ws, ws + 25.0, te"),),
        (REF,),
    ),
    Mutation(
        "regime_window_start",
        "stick time counted from t = 0, not from t_start",
        MEASURE,
        (("inside = info.commit & started & (info.t1 <= f.we)", "inside = info.commit & (info.t1 <= f.we)"),),
        (REF,),
    ),
    Mutation(
        "queue_done_mask",
        "work queue: every active lane is taken as done when one finishes",
        "locomotion_jax/dynamics/_queue.py",
        (("done = (pos < count) & ~running_all(fixed, dyn)", "done = pos < count"),),
        (REF,),
    ),
    # -- more of the same kind ------------------------------------------------------------------
    Mutation(
        "dense_output_basis",
        "a coefficient of the quintic Hermite basis",
        NUMERICS,
        (("H4 = -4 * t3 + 7 * t4 - 3 * t5", "H4 = -4 * t3 + 7 * t4 - 2.9 * t5"),),
        (REF,),
    ),
    Mutation(
        "t_start_from_wn1",
        "t_start from wn1 instead of the lowest natural frequency",
        "locomotion_jax/model/_params.py",
        (("return 80 * 2 * math.pi / wmin", "return 80 * 2 * math.pi / self.wn1"),),
        (REF,),
    ),
    Mutation(
        "exact_figures_energy",
        "the optimiser's exact cost of transport as the energy per period instead of per distance",
        "locomotion_jax/optimisation/_pareto.py",
        (("cost = np.asarray(gait.cost_of_transport, dtype=float)", "cost = np.asarray(gait.e_d, dtype=float)"),),
        ("tests/test_optimise.py::test_optimum_verified_on_the_reference",),
    ),
    Mutation(
        "cli_omega_over_wn1",
        "--omega-over-wn1 multiplies the default wn1 (10), not the configuration's",
        "locomotion_jax/cli/_mechanism.py",
        (
            (
                'params.replace(omega=number("omega_over_wn1", ratio) * float(params.wn1))',
                'params.replace(omega=number("omega_over_wn1", ratio) * 10.0)',
            ),
        ),
        ("tests/test_cli_options.py",),
    ),
    # -- the N-mass engine ----------------------------------------------------------------------
    Mutation(
        "chain_paper_n_signed",
        "chain, paper reading: n = N instead of |N|",
        CHAIN_MOTION,
        (
            ("return tuple(jnp.abs(q) for q in N)", "return N"),
            ("return tuple(s * q for s, q in zip(side, N))", "return N"),
        ),
        (f"{REF}::test_chain_liftoff_against_reference", REF),
    ),
    Mutation(
        "chain_paper_kink_not_located",
        "chain, paper reading: a sign change of N is not an event",
        CHAIN_MOTION,
        (
            ("return tuple(s * q for s, q in zip(side, N))", "return tuple(jnp.abs(q) for q in N)"),
            ("g += list(n)", "g += [jnp.abs(q) + 1 for q in n]"),
        ),
        (f"{REF}::test_chain_liftoff_against_reference", REF),
    ),
    Mutation(
        "chain_liftoff_not_stopping",
        "chain, strict reading: lift-off is flagged but does not stop the run",
        CHAIN,
        (
            ('stop0 = lifted0 if contact == "strict" else jnp.asarray(False)', "stop0 = jnp.asarray(False)"),
            ("lift = stop0 | lift_cut", "lift = stop0"),
        ),
        (f"{REF}::test_chain_liftoff_against_reference", REF),
    ),
    Mutation(
        "chain_no_recheck",
        "chain: after a switch only the located masses switch (no re-check)",
        CHAIN,
        (("fire = tuple(kp(pe | (g < 0)) for pe, g in zip(st.pend, gA))", "fire = tuple(kp(pe) for pe in st.pend)"),),
        (REF,),
    ),
    Mutation(
        "chain_decision_rate_sign",
        "chain margins: sign of F_i's rate in a stopped mass's stick-or-reverse rate",
        CHAIN,
        (
            (
                "hold_rate = motion.stick_margin_rate(P, F0, nA, D0.dF, dnA)",
                "hold_rate = motion.stick_margin_rate(P, F0, nA, tuple(-q for q in D0.dF), dnA)",
            ),
        ),
        ("tests/test_margins.py::test_chain_margins_equal_the_two_mass_engines",),
    ),
    Mutation(
        "chain_no_recheck_one_event",
        "chain: no re-check and one event located per step (simultaneous switches lost)",
        CHAIN,
        (
            ("fire = tuple(kp(pe | (g < 0)) for pe, g in zip(st.pend, gA))", "fire = tuple(kp(pe) for pe in st.pend)"),
            (
                "first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]",
                "first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]\n"
                "    first = [f & ~num.union([jnp.asarray(False)] + first[:i]) for i, f in enumerate(first)]",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "chain_one_event_per_step",
        "chain: one event located per step (of simultaneous crossings only the first flagged)",
        CHAIN,
        (
            (
                "first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]",
                "first = [kp(c & (q <= th_min)) for c, q in zip(crossed, thl)]\n"
                "    first = [f & ~num.union([jnp.asarray(False)] + first[:i]) for i, f in enumerate(first)]",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "chain_friction_sign_in_jerk",
        "chain: sign of the friction term in the second derivative (the dense output's curvature)",
        CHAIN_MOTION,
        (("jnp.where(st, 0, (f - c * ai - sd * fr) * im)", "jnp.where(st, 0, (f - c * ai + sd * fr) * im)"),),
        (REF,),
    ),
    Mutation(
        "chain_event_slope_sign",
        "chain: sign of |F_i|'s rate in a stuck mass's event slope (prediction, location, margins)",
        CHAIN_MOTION,
        (("out.append(mf * dq - s * df)", "out.append(mf * dq + s * df)"),),
        (REF,),
    ),
    Mutation(
        "chain_reversal_keeps_direction",
        "chain, jump at v_i = 0: a slipping mass that does not stick keeps its old friction direction",
        CHAIN,
        (
            (
                "sdir = tuple(jnp.where(fi, jnp.where(f >= 0, 1.0, -1.0).astype(dtype), s) for fi, f, s in zip("
                "fire, F0, st_sdir))",
                "sdir = tuple(jnp.where(fi & ss, jnp.where(f >= 0, 1.0, -1.0).astype(dtype), s)\n"
                "                 for fi, f, s, ss in zip(fire, F0, st_sdir, st_stuck))",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "chain_stick_test_kinetic",
        "chain, jump at v_i = 0: the stick test uses mu_k instead of mu_s",
        CHAIN,
        (
            (
                "holds = [p >= 0 for p in margin]",
                "holds = [law.kinetic(jnp.zeros_like(f), jnp.sign(f)) * q - jnp.abs(f) >= 0\n"
                "             for law, f, q in zip(P.friction, F0, nA)]",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "chain_energy_integrand",
        "chain: the e_d integrand misses the damping of every mass but the first",
        CHAIN_MOTION,
        (
            (
                "_sum([m * q * s + c * vi * vi for m, q, s, c, vi in zip(mu, n, speed, P.c, v)])",
                "_sum([m * q * s + c * vi * vi * (i == 0)\n"
                "        for i, (m, q, s, c, vi) in enumerate(zip(mu, n, speed, P.c, v))])",
            ),
        ),
        (REF,),
    ),
    Mutation(
        "chain_target_com_weights",
        "chain: the target event uses the unweighted midpoint of the end masses, not the centre of mass",
        CHAIN_MOTION,
        (("rel = P.centre_of_mass(x) - target.X0", "rel = 0.5 * (x[0] + x[-1]) - target.X0"),),
        (REF,),
    ),
    # -- derivatives -------------------------------------------------------------------------------------
    Mutation(
        "event_time_fixed",
        "derivatives: an event's time does not move with the parameters (no implicit-function tangent)",
        NUMERICS,
        (("return th, jnp.where(ok, -dp / jnp.where(ok, slope, 1), 0)", "return th, jnp.zeros_like(th)"),),
        ("tests/test_gradients.py",),
    ),
    # -- validation at the boundary and the resolution guards (issue 29) --------------------------------
    Mutation(
        "params_mu_s_bound_flipped",
        "validation: Params' mu_s >= mu_k flipped to mu_s <= mu_k",
        PARAMS,
        (('"mu_s": p["mu_s"] >= p["mu_k"],', '"mu_s": p["mu_s"] <= p["mu_k"],'),),
        (f"{VALIDATION}::test_params_bounds",),
    ),
    Mutation(
        "params_d_check_dropped",
        "validation: Params' |d| < lbar not checked",
        PARAMS,
        (('"d": xp.abs(p["d"]) < p["lbar"],', '"d": xp.abs(p["d"]) >= 0,'),),
        (f"{VALIDATION}::test_params_bounds",),
    ),
    Mutation(
        "params_k_subnormal_allowed",
        "validation: Params' k only > 0 (a subnormal k flushed to zero in the engines)",
        PARAMS,
        (('"k": normal_positive(p["k"], xp),', '"k": p["k"] > 0,'),),
        (f"{VALIDATION}::test_params_bounds",),
    ),
    Mutation(
        "params_lbar_square_unchecked",
        "validation: Params' lbar only > 0 (its square may under- or overflow)",
        PARAMS,
        (('"lbar": normal_positive(p["lbar"], xp, 2),', '"lbar": p["lbar"] > 0,'),),
        (f"{VALIDATION}::test_params_bounds",),
    ),
    Mutation(
        "chain_mass_bound_loosened",
        "validation: a chain's masses m_i >= 0 allowed (zero mass)",
        CHAIN_MODEL,
        (('("masses", normal_positive(c.m), ', '("masses", c.m >= 0, '),),
        (f"{VALIDATION}::test_chain_bounds",),
    ),
    Mutation(
        "chain_damping_check_dropped",
        "validation: a chain's c_i >= 0 not checked",
        CHAIN_MODEL,
        (('("c", c.c >= 0, "c_i >= 0", "mass"),', '("c", c.c == c.c, "c_i >= 0", "mass"),'),),
        (f"{VALIDATION}::test_chain_bounds",),
    ),
    Mutation(
        "coulomb_mu_k_check_dropped",
        "validation: Coulomb's mu_k >= 0 not checked",
        FRICTION,
        (('"mu_k": self.mu_k >= 0}', '"mu_k": self.mu_k == self.mu_k}'),),
        (f"{VALIDATION}::test_friction_bounds",),
    ),
    Mutation(
        "stribeck_v_s_square_unchecked",
        "validation: Stribeck's v_s only > 0 (1/v_s**2 may overflow)",
        FRICTION,
        (("v_s_ok = (self.v_s > 0) & jnp.isfinite(1 / (self.v_s * self.v_s))", "v_s_ok = self.v_s > 0"),),
        (f"{VALIDATION}::test_stribeck_tiny_v_s",),
    ),
    Mutation(
        "params_waveform_not_validated",
        "validation: a waveform given to Params with known values is not checked by the front end",
        "locomotion_jax/run/_batch.py",
        (("            waveform.validate()  # under", "            pass  # under"),),
        (f"{VALIDATION}::test_waveform_of_params_is_validated",),
    ),
    Mutation(
        "resolution_guard_dropped",
        "resolution guard: no scale is compared with the step",
        RESOLUTION,
        (("bad = bad | s.exceeded(dt)", "bad = bad | (dt > jnp.inf)"),),
        (RESOLUTION_TESTS,),
    ),
    Mutation(
        "resolution_threshold_halved",
        "resolution guard: 2 steps per period instead of 4",
        SCALES,
        (("STEPS_PER_PERIOD = 4", "STEPS_PER_PERIOD = 2"),),
        (RESOLUTION_TESTS,),
    ),
    Mutation(
        "resolution_natural_period_ignored",
        "resolution guard: the natural periods are not checked (only the forcing)",
        PARAMS,
        (("2 * math.pi / self.wn1, sc.STEPS_PER_PERIOD", "jnp.inf * self.wn1, sc.STEPS_PER_PERIOD"),),
        (RESOLUTION_TESTS,),
    ),
    Mutation(
        "unresolved_flagged_invalid",
        "resolution guard: an unresolved configuration of a batch flagged INVALID, not UNRESOLVED",
        RESOLUTION,
        (("xp.where(mask, Status.UNRESOLVED, status)", "xp.where(mask, Status.INVALID, status)"),),
        (RESOLUTION_TESTS,),
    ),
    # -- the guards of steady gaits, a Mechanism's own scales and the default start ----------------
    Mutation(
        "gait_guard_dropped",
        "steady_gait (two masses): the resolution guard is not asked",
        "locomotion_jax/gaits/_gait.py",
        (("flat, unresolved = guard_two_mass(dynamics, flat, wave, shape)", "unresolved = None"),),
        GAIT_GUARDS,
    ),
    Mutation(
        "gait_unresolved_not_flagged",
        "steady_gait (two masses): the resolution guard's mask is not passed on (an unresolved "
        "configuration of a batch not flagged)",
        "locomotion_jax/gaits/_gait.py",
        (("paper_physics, valid, unresolved, shape", "paper_physics, valid, None, shape"),),
        GAIT_GUARDS,
    ),
    Mutation(
        "chain_gait_guard_dropped",
        "steady_gait (chains): the resolution guard is not asked",
        "locomotion_jax/gaits/_shooting.py",
        (("valid, unresolved = guard_chain(dynamics, flat, valid, shape)", "unresolved = None"),),
        GAIT_GUARDS,
    ),
    Mutation(
        "mechanism_springs_ignored",
        "Mechanism.time_scales: the springs' stiffness left out of the natural period",
        BODIES,
        (("K = K.at[:, a, a].add(k)", "K = K.at[:, a, a].add(0 * k)"),),
        MECHANISM_GUARDS,
    ),
    Mutation(
        "mechanism_wall_springs_ignored",
        "Mechanism.time_scales: a spring to the wall left out (only springs between two bodies)",
        BODIES,
        (("for a in ends:", "for a in ends if len(ends) == 2 else []:"),),
        MECHANISM_GUARDS,
    ),
    Mutation(
        "mechanism_forcing_ignored",
        "Mechanism.time_scales: the forcing's period not compared with the step",
        BODIES,
        (("scales.append(sc.forcing(fastest, sc.flat(fastest.omega, size)))", "pass"),),
        MECHANISM_GUARDS,
    ),
    Mutation(
        "mechanism_carried_load_ignored",
        "Mechanism.time_scales: a friction time over the body's own weight, not the load it carries",
        BODIES,
        (("t = sc.flat(scale[0], size) * self.m[:, i] / load", "t = sc.flat(scale[0], size)"),),
        MECHANISM_GUARDS,
    ),
    Mutation(
        "default_start_unbounded",
        "measure: the default t_start of the paper's model is not bounded",
        "locomotion_jax/run/_batch.py",
        (
            (
                "guard_two_mass(dynamics, flat, wave, shape, default_start=measuring and ts is None)",
                "guard_two_mass(dynamics, flat, wave, shape, default_start=False)",
            ),
        ),  # fmt: skip
        (GUARDS_TESTS + "::test_every_measurement_path_asks_for_the_default_start",),
    ),
    Mutation(
        "default_start_bound_loosened",
        "the default start may take 1e12 steps instead of 1e8",
        SCALES,
        (("MAX_START_STEPS = 10**8", "MAX_START_STEPS = 10**12"),),
        (GUARDS_TESTS + "::test_the_limit_is_on_the_steps",),
    ),
    Mutation(
        "optimise_guard_skipped",
        "optimise (the paper's model): the entry guard of the search's step is not called",
        "locomotion_jax/optimisation/_optimise.py",
        (("_guard_search(params, omega, shape, cast(ExactSettings, settings))", "pass"),),
        (GUARDS_TESTS + "::test_optimisers_refuse_a_step_that_does_not_resolve_the_mechanism",),
    ),
    Mutation(
        "search_at_dt",
        "optimise (the paper's model): the screen and the local runs step at dt, not at search_dt",
        "locomotion_jax/optimisation/_exact.py",
        (("return settings.dt if settings.search_dt is None else settings.search_dt", "return settings.dt"),),
        ("tests/test_optimise.py::test_the_search_steps_at_search_dt_which_the_guard_checks",),
    ),
    Mutation(
        "simulation_check_blind_to_recurrence",
        "optimise (a chain or a mechanism): the direct simulation check reports every motion as the gait's",
        "locomotion_jax/optimisation/_element_local.py",
        (
            (
                "simulated_recurrence=recurrence(states, tol)",
                "simulated_recurrence=1",
            ),
        ),
        ("tests/test_optimise.py::test_the_direct_simulation_names_a_second_attractor",),
    ),
    Mutation(
        "simulation_check_refused_by_the_guard",
        "optimise: the direct simulation check steps at dt even where the guard refuses it (a fine spline)",
        "locomotion_jax/optimisation/_element_local.py",
        (('dt = resolved_step(model, run.get("waveform"), settings.dt)', "dt = settings.dt"),),
        ("tests/test_resolution_guards.py::test_the_optimums_direct_simulation_steps_where_the_guard_asks",),
    ),
    Mutation(
        "simulation_check_over_ten_periods",
        "optimise (a chain or a mechanism): the direct simulation check averages over 10 gait periods",
        "locomotion_jax/optimisation/_element_local.py",
        (("AVERAGED = 12", "AVERAGED = 10"),),
        ("tests/test_optimise.py::test_the_direct_simulation_names_a_second_attractor",),
    ),
    Mutation(
        "element_verify_at_search_dt",
        "optimise (a chain): the verification steps at the search's step, not at dt",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "screen.solve(base, cos, sin, om, checked, control=control)",
                "screen.solve(base, cos, sin, om, search, control=control)",
            ),
        ),
        ("tests/test_optimise.py::test_a_coarser_search_step_reports_the_figures_at_dt",),
    ),
    Mutation(
        "element_baseline_at_search_dt",
        "optimise (a chain): the baseline wave's figures are the screen's at the search step, not the verification's",
        "locomotion_jax/optimisation/_chain.py",
        (("        baseline = local.verified_baseline(screen.as_dict(sc, best), v)\n", "        pass\n"),),
        ("tests/test_optimise.py::test_a_coarser_search_step_reports_the_figures_at_dt",),
    ),
    Mutation(
        "verify_at_search_dt",
        "optimise (the paper's model): the verification steps at the search's step, not at dt",
        "locomotion_jax/optimisation/_exact.py",
        (("gait = gaits(theta, settings.dt)", "gait = gaits(theta, search_step(settings))"),),
        ("tests/test_optimise.py::test_the_verification_steps_at_dt_whatever_the_search_step",),
    ),
    Mutation(
        "search_step_unguarded",
        "optimise (the paper's model): the entry guard does not check search_dt",
        "locomotion_jax/optimisation/_optimise.py",
        (('for name in ("dt", "search_dt"):', 'for name in ("dt",):'),),
        ("tests/test_optimise.py::test_the_search_steps_at_search_dt_which_the_guard_checks",),
    ),
    Mutation(
        "mechanism_optimise_unguarded",
        "optimise (a mechanism): a step that resolves not even the screen's slowest sinusoid is not refused",
        "locomotion_jax/optimisation/_mechanism.py",
        (
            (
                "    local.refuse_steps(slowest, settings,",
                "    (lambda *a: None)(slowest, settings,",
            ),
        ),
        (GUARDS_TESTS + "::test_optimisers_refuse_a_step_that_does_not_resolve_the_mechanism",),
    ),
    Mutation(
        "chain_optimise_guards_its_own_waves",
        "optimise (a chain): the guard checks the chain's own actuation, not the fastest stroke the search reaches",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "local.refuse_steps(fastest, settings,",
                "local.refuse_steps(base, settings,",
            ),
        ),
        (GUARDS_TESTS + "::test_optimisers_refuse_a_step_that_does_not_resolve_the_mechanism",),
    ),
    Mutation(
        "chain_screen_keeps_every_wave",
        "the chain optimiser's screen: its transient-speed threshold dropped (every wave solved)",
        "locomotion_jax/optimisation/_chain_screen.py",
        (("keep = fast >= fraction * v_min", "keep = fast >= -np.inf"),),
        ("tests/test_optimise.py::test_screen_filter_keeps_the_fast_waves",),
    ),
    Mutation(
        "transient_speed_wrong_span",
        "transient_speed: the displacement divided by the whole transient instead of its last periods",
        "locomotion_jax/gaits/_shooting.py",
        (("omega / (2 * np.pi * last)", "omega / (2 * np.pi * transient)"),),
        ("tests/test_gait.py::test_transient_speed_equals_simulation_and_the_gait",),
    ),
    Mutation(
        "search_settings_skip_transient",
        "the exact optimisers' settings check: transient no longer checked",
        "locomotion_jax/optimisation/_search_settings.py",
        (('        count(self, "transient", self.least_transient)\n', ""),),
        ("tests/test_optimise.py::test_bad_settings_raise",),
    ),
    Mutation(
        "compact_batches_unsorted",
        "steady gaits with compact=True: the quarter-size batches of a period taken in the batch's order",
        "locomotion_jax/gaits/_shooting.py",
        (('        order = np.argsort(np.asarray(key, float), kind="stable")\n', "        order = np.arange(B)\n"),),
        ("tests/test_gait.py::test_compact_batch_for_the_longer_periods",),
    ),
    Mutation(
        "runners_up_only_of_failed_runs",
        "the exact optimiser's verification: a runner-up of a run that passed is never verified, however cheap",
        "locomotion_jax/optimisation/_exact.py",
        (
            (
                "    go = [not held[f[3]] or f[2] < cheapest * (1 - FALLBACK_RTOL) for f in fallbacks]\n",
                "    go = [not held[f[3]] for f in fallbacks]\n",
            ),
        ),
        ("tests/test_optimise.py::test_runners_up_are_verified_where_their_run_fails_or_might_be_cheaper",),
    ),
    Mutation(
        "descent_never_stalls",
        "the local descent: no stop where its merit stalls, whatever its stall_rtol",
        "locomotion_jax/optimisation/_descent.py",
        (("        if stall_rtol > 0 and _stalled(best, rtol):\n            return\n", ""),),
        ("tests/test_descent.py",),
    ),
    Mutation(
        "descent_far_stall_dropped",
        "the local descent: a run far from feasible stalls at the caller's tolerance alone",
        "locomotion_jax/optimisation/_descent.py",
        (("rtol = max(stall_rtol, FAR_STALL_RTOL) if _far(fig) else stall_rtol", "rtol = stall_rtol"),),
        ("tests/test_descent.py::test_descent_far_from_feasible_stops_at_the_looser_stall",),
    ),
    Mutation(
        "descent_far_means_any_violation",
        "the local descent: any violation, however small, counts as far from feasible",
        "locomotion_jax/optimisation/_descent.py",
        (("np.max(-np.asarray(fig.c, float)) > FAR)", "np.max(-np.asarray(fig.c, float)) > 0)"),),
        ("tests/test_descent.py",),
    ),
    Mutation(
        "local_run_reports_its_last_point",
        "an optimiser's local run: its last point with an orbit reported, not the cheapest feasible one",
        "locomotion_jax/optimisation/_local.py",
        (('                    if rank < best["key"]:\n', "                    if True:\n"),),
        ("tests/test_descent.py::test_local_run_reports_its_cheapest_feasible_point_and_runners_up",),
    ),
    Mutation(
        "precompile_process_default_device",
        "the exact optimiser's background compilation ignores the caller's default device",
        "locomotion_jax/optimisation/_exact.py",
        (("with jax.default_device(self.device):", "with jax.default_device(None):"),),
        ("tests/test_optimise.py::test_precompile_compiles_for_the_callers_default_device",),
    ),
    Mutation(
        "precompile_wrong_verification_batch",
        "the exact optimiser's background compilation: the verification's placeholder batch of the wrong size",
        "locomotion_jax/optimisation/_exact.py",
        (
            (
                "th = np.zeros(((2 + settings.local) * len(shape.origins)",
                "th = np.zeros(((3 + settings.local) * len(shape.origins)",
            ),
        ),
        ("tests/test_optimise.py::test_precompiled_verification_is_the_verifications_program",),
    ),
    Mutation(
        "simulate_saves_not_padded",
        "simulate: a chain's save times not padded to their bucket (a program per save count)",
        "locomotion_jax/dynamics/_simulate.py",
        (("out = _simulate_batch(C, ok, times.pad(save), contact,", "out = _simulate_batch(C, ok, save, contact,"),),
        ("tests/test_batch_independence.py::test_save_counts_of_one_bucket_share_a_program",),
    ),
    Mutation(
        "sweep_chunks_not_bucketed",
        "sweep: a chunk padded to whole SIMD vectors only, not to its size bucket (a program per chunk size)",
        "locomotion_jax/maps/_sharding.py",
        (("    rows = batch_rows(share)\n", "    rows = share\n"),),
        ("tests/test_sweep.py::test_sweeps_of_other_horizons_caps_and_sizes_share_a_program",),
    ),
    Mutation(
        "sweep_cap_static",
        "sweep: the step cap a static argument of the chunk program (a program per horizon)",
        "locomotion_jax/maps/_sharding.py",
        (
            (
                '_run_chunk = engine_jit(_run_chunk, ("contact", "start", "mesh", "micro_batch"))',
                '_run_chunk = engine_jit(_run_chunk, ("contact", "start", "max_steps", "mesh", "micro_batch"))',
            ),
            (
                "    cap = jnp.asarray(min(int(max_steps), np.iinfo(np.int32).max), jnp.int32)\n",
                "    cap = int(max_steps)\n",
            ),
        ),
        ("tests/test_sweep.py::test_sweeps_of_other_horizons_caps_and_sizes_share_a_program",),
    ),
    Mutation(
        "sweep_exact_cap_static",
        "sweep: `Exact.max_steps` compiled into the chunk program (a program per step cap)",
        "locomotion_jax/dynamics/_exact_dynamics.py",
        (
            (
                "        return dataclasses.replace(self, max_steps=None), self.max_steps or 0\n",
                "        return self, self.max_steps or 0\n",
            ),
        ),
        ("tests/test_sweep.py::test_sweeps_of_other_horizons_caps_and_sizes_share_a_program",),
    ),
    Mutation(
        "sweep_exact_cap_dropped",
        "sweep: `Exact.max_steps` left out of the chunk program (each configuration capped by its own span)",
        "locomotion_jax/dynamics/_exact_dynamics.py",
        (
            (
                "        return dataclasses.replace(self, max_steps=None), self.max_steps or 0\n",
                "        return dataclasses.replace(self, max_steps=None), 0\n",
            ),
        ),
        ("tests/test_sweep.py::test_sweeps_of_other_horizons_caps_and_sizes_share_a_program",),
    ),
    Mutation(
        "sweep_inner_cap_ignored",
        "sweep: an `Exact` called by another dynamics' `measure_chunk` drops its own `max_steps` for the sweep's 0",
        "locomotion_jax/dynamics/_exact_dynamics.py",
        (("            own = cap if dyn.max_steps is None else None\n", "            own = cap\n"),),
        ("tests/test_dynamics_extension.py::test_sweep",),
    ),
    Mutation(
        "exact_local_retries_every_stage",
        "the paper's exact optimiser: its local runs retry failed orbits in every stage, not in the last alone",
        "locomotion_jax/optimisation/_exact.py",
        (
            (
                '        ev.retry = settings.retry == "every" or j == len(iters) - 1\n',
                "        ev.retry = True\n",
            ),
        ),
        ("tests/test_optimise.py::test_the_exact_local_runs_retry_in_their_last_stage_only",),
    ),
    Mutation(
        "given_start_ignored",
        "the chain optimiser: a given start does not take the last lane (the screen's start keeps it)",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "        starts[-1] = local.given_start(start, S, H, M if spline else 0, a_max, lo, hi, "
                "sc.gaits.y[best])\n",
                "        local.check_start(start, S)\n",
            ),
        ),
        ("tests/test_optimise.py::test_a_given_start_is_refined_in_the_last_lane_and_is_a_candidate",),
    ),
    Mutation(
        "given_start_not_a_candidate",
        "the chain optimiser: a given start is refined but not verified as a candidate itself",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "    given = [] if start is None else [local.decision(starts[-1], a_max, M if spline else 0)]\n",
                "    given = []\n",
            ),
        ),
        ("tests/test_optimise.py::test_a_given_start_is_refined_in_the_last_lane_and_is_a_candidate",),
    ),
    Mutation(
        "given_start_time_not_moved",
        "a given start's Fourier series is not moved in time: its first signal's A_1, which the decision "
        "vector leaves out, is dropped",
        "locomotion_jax/optimisation/_element_local.py",
        (
            (
                "    cos, sin = normalise_phase(cos, sin)\n",
                "",
            ),
        ),
        ("tests/test_optimise.py::test_a_given_start_is_refitted_to_the_searchs_family",),
    ),
    Mutation(
        "gait_min_normal_of_every_body",
        "a steady gait's smallest normal load includes the placeholder load of a body without ground contact",
        "locomotion_jax/gaits/_shooting.py",
        (
            (
                "low = num.least([inf, *contact_loads(P, lows, inf)])",
                "low = num.least([inf, *lows])",
            ),
        ),
        ("tests/test_gait.py::test_capsule_gait_is_a_fixed_point_of_a_direct_simulation",),
    ),
    Mutation(
        "gait_start_gaps_unchecked",
        "steady_gait takes a chain's section state whose masses are out of order",
        "locomotion_jax/gaits/_shooting.py",
        (("            mechanism.check_section(y)", "            pass"),),
        ("tests/test_gait.py::test_chain_gait_bad_input",),
    ),
    Mutation(
        "measure_horizon_past_window",
        "measure's steps end at the window's end, not at an earlier horizon (the run overshoots it)",
        "locomotion_jax/dynamics/_measure.py",
        (("jnp.where(s.t < f.we, jnp.minimum(f.we, f.te), f.te)", "jnp.where(s.t < f.we, f.we, f.te)"),),
        ("tests/test_exact.py::test_measure_ends_at_its_horizon_when_the_window_is_longer",),
    ),
    Mutation(
        "fit_tuple_items_unreached",
        "fit_trajectory cannot name an item of a tuple (a mechanism's links[0].k)",
        "locomotion_jax/optimisation/_fit.py",
        (
            (
                "        if m.group(2) is not None:\n            i = int(m.group(2))",
                "        if False:\n            i = 0",
            ),
        ),
        ("tests/test_mechanism_features.py::test_fit_of_the_capsules_spring_and_friction",),
    ),
    Mutation(
        "builder_store_digest_ignored",
        "a chain map's Zarr store does not record its builder: another builder's map is resumed into it",
        "locomotion_jax/maps/_builder_sweep.py",
        (('"mechanism": _digest(build, values, shape, mode, fixed, first),', '"mechanism": {},'),),
        ("tests/test_zarr.py::test_a_chain_map_into_a_store_equals_memory_resumes_and_refuses_another_builder",),
    ),
    Mutation(
        "builder_map_in_run_order",
        "a builder's map in cost order is returned in the order it ran, not put back in grid order",
        "locomotion_jax/maps/_sweep.py",
        (
            (
                "_in_grid_order(np.concatenate([results[i][k] for i in range(n_chunks)]), perm) for k",
                "np.concatenate([results[i][k] for i in range(n_chunks)]) for k",
            ),
        ),
        ("tests/test_sweep.py::test_a_mechanism_map_in_cost_order_equals_grid_order_and_its_pilot_predicts_the_cost",),
    ),
    Mutation(
        "builder_pilot_without_start",
        "the cost order's pilot of a builder's map counts no measurement start: short runs sort by speed alone",
        "locomotion_jax/maps/_schedule.py",
        (("    cost = iterations(pr, ts, z=z,", "    cost = iterations(pr, 0 * ts, z=z,"),),
        ("tests/test_sweep.py::test_a_mechanism_map_in_cost_order_equals_grid_order_and_its_pilot_predicts_the_cost",),
    ),
    Mutation(
        "hop_start_heights_ignored",
        "a hopping gait's given start loses its heights and vertical velocities: every body starts on the ground",
        "locomotion_jax/dynamics/_runs.py",
        (('if contact == "hop" and row.shape[-1] == 4 * n:', 'if contact == "hop" and row.shape[-1] == -1:'),),
        ("tests/test_gait.py::test_hopping_gait_is_the_limit_of_a_long_simulation",),
    ),
    Mutation(
        "array_hop_second_rate_untilted",
        "a hopping chain in the array layout drops the heights' terms from the springs' second derivatives",
        "locomotion_jax/model/_chain_array.py",
        (("            ddl = ddl + (dh * dh + h * ddh) * il\n", ""),),
        ("tests/test_chain_array.py::test_array_layout_hop_equals_unrolled",),
    ),
    Mutation(
        "array_hop_heights_ignored",
        "a hopping chain in the array layout keeps its springs' offsets d: the heights never tilt them",
        "locomotion_jax/model/_chain_array.py",
        (("h = None if y is None else self.d + (y[0][1:] - y[0][:-1])", "h = None"),),
        ("tests/test_chain_array.py::test_array_layout_hopping_worm_against_reference",),
    ),
    Mutation(
        "hop_landing_at_once_after_liftoff",
        "a body airborne at height 0 with no vertical velocity looks for its landing at once: at a grazing lift-off "
        "it lands and lifts off again at one instant",
        "locomotion_jax/dynamics/_engine.py",
        (("[c & ~r for c, r in zip(crossed[n_mass : 2 * n_mass], at_rest)]", "crossed[n_mass : 2 * n_mass]"),),
        ("tests/test_hop_reference.py::test_grazing_liftoff_does_not_stall_a_coarse_step",),
    ),
    Mutation(
        "carried_landing_own_mass_only",
        "a carrier's landing stops its own fall only: its normal impulse, which bounds the tangential one, "
        "leaves out the masses it carries",
        "locomotion_jax/model/_mechanism_physics.py",
        (("        return self.normal\n", "        return self.m\n"),),
        ("tests/test_hop_carried.py::test_a_hopping_capsule_against_the_reference",),
    ),
    Mutation(
        "carried_body_keeps_its_own_height",
        "a carried body keeps its own (zero) height and vertical velocity instead of riding in its carrier",
        "locomotion_jax/model/_mechanism_physics.py",
        (
            (
                "    ride = lambda q: tuple(q[..., g] for g in ground)",
                "    ride = lambda q: tuple(q[..., i] for i in range(n))",
            ),
        ),
        ("tests/test_hop_carried.py::test_a_hopping_capsule_against_the_reference",),
    ),
    Mutation(
        "tilted_spring_load_on_its_own_body",
        "a tilted spring's vertical force on a carried body is left out of every normal load instead of "
        "landing on the body that carries it",
        "locomotion_jax/model/_mechanism_physics.py",
        (
            (
                "                if end != WALL and contact[self.ground[int(end)]]:",
                "                if end != WALL and contact[int(end)]:",
            ),
            (
                "                    _add(lift, self.ground[int(end)], b, sign)",
                "                    _add(lift, end, b, sign)",
            ),
        ),
        ("tests/test_tilted_springs.py::test_tilted_springs_between_any_bodies_against_the_reference",),
    ),
    Mutation(
        "tilted_spring_horizontal",
        "a tilted spring's vertical force never reaches the normal loads: a mechanism's loads stay its weights",
        "locomotion_jax/model/_mechanism_physics.py",
        (
            (
                "        F, N = self._tilt_terms(F, self.normal, sp.fx, sp.fy)\n",
                "        F, N = self._tilt_terms(F, self.normal, sp.fx, tuple(0 * q for q in sp.fy))\n",
            ),
        ),
        ("tests/test_tilted_springs.py::test_tilted_springs_between_neighbours_are_the_chain",),
    ),
    Mutation(
        "tilted_wall_spring_does_not_anchor",
        "a tilted spring to the wall does not anchor a mechanism: its gait's section state drops the positions",
        "locomotion_jax/model/_mechanism_physics.py",
        (
            (
                "        return any(WALL in (s.a, s.b) for s in (*self.springs, *self.tilted))\n",
                "        return any(WALL in (s.a, s.b) for s in self.springs)\n",
            ),
        ),
        ("tests/test_tilted_springs.py::test_a_steady_gait_of_a_mechanism_tied_to_the_wall_by_a_tilted_spring",),
    ),
    Mutation(
        "carried_section_state_untied",
        "a gait's section state gives a carried body its own height and vertical velocity: spurious multipliers",
        "locomotion_jax/gaits/_shooting.py",
        (
            (
                "    h = P.stacked(P.ride(P.bodies(y[base : base + n])))\n"
                "    w = P.stacked(P.ride(P.bodies(y[base + n : base + 2 * n])))\n",
                "    h, w = y[base : base + n], y[base + n : base + 2 * n]\n",
            ),
        ),
        ("tests/test_tilted_springs.py::test_the_floquet_multipliers_of_a_hopping_capsule_against_the_reference",),
    ),
    Mutation(
        "carried_body_lifts_alone",
        "a carried body rides on its own entries: it lifts off on its placeholder load, never with its carrier",
        "locomotion_jax/model/_mechanism_physics.py",
        (("        return tuple(q[g] for g in self.ground)\n", "        return q\n"),),
        ("tests/test_tilted_springs.py::test_tilted_springs_lift_bodies_and_what_they_carry_as_the_reference_does",),
    ),
    Mutation(
        "sequence_code_ignored",
        "continuation compares the switch and landing counts only: events that pass each other go unseen",
        "locomotion_jax/gaits/_bifurcation.py",
        (
            (
                "            if sw[0] != sw[1] or nl[0] != nl[1] or sq[0] != sq[1]:\n",
                "            if sw[0] != sw[1] or nl[0] != nl[1]:\n",
            ),
        ),
        ("tests/test_continuation.py::test_hopping_events_that_pass_each_other_are_no_torus",),
    ),
    Mutation(
        "sequence_step_sums_bodies",
        "the sequence code adds a step's changes body by body: changes made in one step at other bodies collide",
        "locomotion_jax/gaits/_shooting.py",
        (
            (
                "        terms.append(jnp.where(old != new, (new.astype(jnp.uint32) + 1) * digit, jnp.uint32(0)))\n",
                "        terms.append(jnp.where(old != new, 4 * jnp.asarray(offset, jnp.uint32)"
                " + 4 * jnp.arange(n, dtype=jnp.uint32).reshape(jnp.shape(new)) + new.astype(jnp.uint32) + 1, 0))\n",
            ),
        ),
        ("tests/test_continuation.py::test_the_sequence_code_sees_events_pass_each_other",),
    ),
    Mutation(
        "mechanism_array_force_sign",
        "the array layout of a mechanism pushes an internal force the wrong way: +f on its a, -f on its b",
        "locomotion_jax/model/_mechanism_array.py",
        (
            (
                "    for base, els, sign in ((0, springs, 1.0), (S, tilts, 1.0), (S + T, forces, -1.0)):\n",
                "    for base, els, sign in ((0, springs, 1.0), (S, tilts, 1.0), (S + T, forces, 1.0)):\n",
            ),
        ),
        ("tests/test_mechanism_array.py::test_array_mechanism_rates_equal_unrolled",),
    ),
    Mutation(
        "mechanism_array_tilt_lifts_the_wrong_body",
        "the array layout of a mechanism puts a tilted spring's vertical force on the wrong end's normal load",
        "locomotion_jax/model/_mechanism_array.py",
        (
            (
                "for end, sign in ((e.a, 1.0), (e.b, -1.0))\n            if end != WALL",
                "for end, sign in ((e.a, -1.0), (e.b, 1.0))\n            if end != WALL",
            ),
        ),
        ("tests/test_mechanism_array.py::test_array_mechanism_rates_equal_unrolled",),
    ),
    Mutation(
        "mechanism_wall_dampers_dropped",
        "a mechanism leaves out a damper to the wall (its ground damping), in either layout",
        "locomotion_jax/model/_mechanism_physics.py",
        (("            c[i] = c[i] + el.c\n", "            c[i] = c[i] + 0 * el.c\n"),),
        ("tests/test_mechanism_array.py::test_a_long_mechanism_in_the_array_layout_against_the_reference",),
    ),
    Mutation(
        "mechanism_array_bank_mean_twice",
        "the array layout of a mechanism adds a spline's mean (lbar) to its row of Fourier coefficients as well as "
        "reading it from the bank: the rest lengths twice their mean",
        "locomotion_jax/model/_mechanism_array.py",
        (
            (
                "    mean = jnp.zeros((), like.dtype) if isinstance(s, AbstractWaveform)",
                "    mean = s.lbar if isinstance(s, AbstractWaveform)",
            ),
        ),
        ("tests/test_mechanism_array.py::test_array_mechanism_rates_equal_unrolled",),
    ),
    Mutation(
        "chain_forcing_guard_of_its_coefficients",
        "a chain driven by its own waveforms (splines, a user's class) is guarded on its Fourier coefficients' "
        "harmonics, not on its waveforms'",
        "locomotion_jax/model/_chain.py",
        (
            (
                "        fastest = self.waves if self.signals is None else max(self.signals, key=sc.harmonics)\n",
                "        fastest = self.waves\n",
            ),
        ),
        ("tests/test_resolution_guards.py::test_a_waveform_of_your_own_is_resolved_at_its_fastest_harmonic",),
    ),
    Mutation(
        "waveform_fastest_harmonic_ignored",
        "the step guards take every waveform's shortest time scale as its base period",
        "locomotion_jax/model/_scales.py",
        (("        return int(wave.fastest_harmonic())\n", "        return 1\n"),),
        ("tests/test_resolution_guards.py::test_a_waveform_of_your_own_is_resolved_at_its_fastest_harmonic",),
    ),
    Mutation(
        "wave_bank_rows_reversed",
        "a group of the bank of waveforms puts its members' signals in its rows in reverse order",
        "locomotion_jax/model/_bank.py",
        (
            (
                "            out = out.at[..., jnp.asarray(rows)].add(q)\n",
                "            out = out.at[..., jnp.asarray(rows[::-1])].add(q)\n",
            ),
        ),
        ("tests/test_mechanism_array.py::test_mixed_waveforms_in_the_array_layout_against_the_reference",),
    ),
    Mutation(
        "chain_array_bank_mean_kept_under_force",
        "a chain's array layout under the internal-force actuator drives each spring by its waveform's value, not its "
        "deviation from its own mean",
        "locomotion_jax/model/_chain_array.py",
        (
            (
                "            return self.lbar, l0 - self.bank.lbar, rate, acc\n",
                "            return self.lbar, l0, rate, acc\n",
            ),
        ),
        ("tests/test_chain_array.py::test_array_layout_splines_equal_unrolled",),
    ),
    Mutation(
        "mechanism_layout_ignored",
        "the engines run every mechanism unrolled, whatever its layout",
        "locomotion_jax/model/_chain_array.py",
        (
            (
                "    return mechanism.array_physics() if uses_array(mechanism, start) else mechanism.physics()",
                "    return mechanism.physics()",
            ),
        ),
        ("tests/test_mechanism_array.py::test_a_long_mechanism_in_the_array_layout_against_the_reference",),
    ),
    Mutation(
        "smoothed_ignores_layout",
        "the smoothed engine integrates every chain unrolled, whatever its layout",
        "locomotion_jax/dynamics/_smoothed_dynamics.py",
        (
            (
                "        P = engine_physics(M)  # a chain's layout (`_chain_array`)\n"
                "        return smoothed.measure_one",
                "        P = M.physics()\n        return smoothed.measure_one",
            ),
        ),
        ("tests/test_chain_array.py::test_array_layout_smoothed_runs_equal_unrolled",),
    ),
    Mutation(
        "rollout_ignores_layout",
        "the optimisers' smoothed rollout integrates every chain unrolled, whatever its layout",
        "locomotion_jax/optimisation/_objective.py",
        (
            (
                "        return engine_physics(model.with_fourier(cos, sin, omega), GAIT_ARRAY_FROM)\n",
                "        return model.with_fourier(cos, sin, omega).physics()\n",
            ),
        ),
        ("tests/test_optimise.py::test_element_rollout_in_either_layout",),
    ),
    Mutation(
        "smoothed_event_times_to_float64_tolerance",
        "the smoothed engine locates event times to 1e-10 in float32 too: every float32 measurement fails",
        "locomotion_jax/dynamics/_smoothed.py",
        (("rtol=max(1e-10, 10 * eps), atol=max(1e-12, 10 * eps)", "rtol=1e-10, atol=1e-12"),),
        ("tests/test_smooth.py::test_the_smoothed_engine_in_float32",),
    ),
    Mutation(
        "smoothed_events_in_state_dtype",
        "the smoothed engine's event conditions return the state's dtype: a float32 run under x64 does not trace",
        "locomotion_jax/dynamics/_smoothed.py",
        (("jnp.asarray(c(t, y, args, **kw), float)", "c(t, y, args, **kw)"),),
        ("tests/test_smooth.py::test_the_smoothed_engine_in_float32",),
    ),
    Mutation(
        "eigensolver_per_held_mass",
        "the natural frequencies call the batched eigensolver once per held mass (calls that can deadlock "
        "XLA's CPU thread pool when they run concurrently)",
        "locomotion_jax/model/_chain.py",
        (
            (
                "        keep = np.array([[i for i in range(n) if i != held] for held in range(n)])\n"
                "        return jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(Kn[..., keep[:, :, None], "
                "keep[:, None, :]]), 0))\n",
                "        rows = [[i for i in range(n) if i != held] for held in range(n)]\n"
                "        return jnp.stack([jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(Kn[..., np.array(r)[:, None], "
                "np.array(r)[None, :]]), 0)) for r in rows], -2)\n",
            ),
        ),
        ("tests/test_smooth.py::test_natural_frequencies_call_the_eigensolver_once",),
    ),
    Mutation(
        "smoothed_start_inside_program",
        "the smoothed engine computes a chain's default measurement start inside its program",
        "locomotion_jax/dynamics/_smoothed_dynamics.py",
        (
            (
                "        ts = jnp.asarray(batch.mechanism.t_start if batch.t_start is None "
                "else batch.t_start, batch.dtype)\n",
                "        ts = jnp.full((batch.size,), jnp.inf, batch.dtype) if batch.t_start is None "
                "else batch.t_start\n",
            ),
            (
                "def _measure_bodies(M, valid, ws, z, horizon, window, contact, start, initial, dyn):\n",
                "def _measure_bodies(M, valid, ws, z, horizon, window, contact, start, initial, dyn):\n"
                "    ws = jnp.where(jnp.isfinite(ws), ws, M.t_start).astype(ws.dtype)\n",
            ),
        ),
        ("tests/test_smooth.py::test_the_smoothed_program_of_a_chain_has_no_eigensolver",),
    ),
    Mutation(
        "stribeck_breakaway_stops_at_once",
        "a mass that breaks away with no acceleration along its slip looks for its stop at once: at a grazing "
        "Stribeck breakaway it sticks and breaks away again at one instant",
        "locomotion_jax/dynamics/_engine.py",
        (("[c & ~r for c, r in zip(crossed[:n_mass], grazing)]", "crossed[:n_mass]"),),
        ("tests/test_against_reference.py::test_grazing_stribeck_breakaway_against_reference",),
    ),
    Mutation(
        "guard_by_class",
        "the resolution guard tests for the Exact class: a fixed-step dynamics of one's own runs unguarded",
        "locomotion_jax/run/_resolution.py",
        (
            (
                "    dt = dynamics.nominal_step()\n    if dt is None:",
                "    dt = dynamics.dt if isinstance(dynamics, Exact) else None\n    if dt is None:",
            ),
        ),
        ("tests/test_dynamics_extension.py::test_a_fixed_step_dynamics_of_ones_own_is_guarded_at_its_step",),
    ),
    Mutation(
        "chain_given_screen_ignored",
        "a chain's optimiser solves its screen again though an earlier one is given (sweep=)",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "    if sweep is None:\n        size = settings.amplitudes",
                "    if True:\n        size = settings.amplitudes",
            ),
        ),
        ("tests/test_optimise.py::test_a_chain_takes_an_earlier_screen",),
    ),
    Mutation(
        "smoothed_time_not_moved",
        "the smoothed stage's candidates keep their lanes' time origins: the first signal's A_1, which the "
        "decision vector leaves out, is dropped",
        "locomotion_jax/optimisation/_element_smoothed.py",
        (
            (
                "        xs.append(local.pack(*normalise_phase(cos, sin), math.exp(float(log_omega))))\n",
                "        xs.append(local.pack(cos, sin, math.exp(float(log_omega))))\n",
            ),
        ),
        ("tests/test_optimise.py::test_the_smoothed_stage_moves_each_lanes_time_origin",),
    ),
    Mutation(
        "given_start_not_rescaled",
        "a given start above the stroke bound is not rescaled onto it",
        "locomotion_jax/optimisation/_element_local.py",
        (("    scale = 1 / np.maximum(strokes(cos, sin) / a_max, 1.0)\n", "    scale = np.ones(len(cos))\n"),),
        ("tests/test_optimise.py::test_a_given_start_is_refitted_to_the_searchs_family",),
    ),
    Mutation(
        "chain_period_plot_not_relaxed",
        "a chain optimum's period figure runs from the default start, not from the relaxed springs of the "
        "optimiser's direct simulation",
        "locomotion_jax/optimisation/_element_optimum.py",
        (('        return self.chain, dict(start="relaxed")\n', "        return self.chain, {}\n"),),
        ("tests/test_optimise.py::test_period_figure_of_a_chain_optimum_moves_at_its_gaits_speed",),
    ),
    Mutation(
        "travelling_wave_drawn_backwards",
        "the waveform figure draws the best travelling wave with its phase lag reversed",
        "locomotion_jax/optimisation/_element_optimum.py",
        (("np.sin(phase[None] - np.arange(self.cos.shape[0])", "np.sin(phase[None] + np.arange(self.cos.shape[0])"),),
        ("tests/test_optimise.py::test_waveform_figure_draws_a_chain_optimum_of_either_family",),
    ),
    Mutation(
        "element_rollout_wide_bump",
        "a chain's or a mechanism's smoothed rollout keeps the smoothed engine's static bump sqrt(eps), not the "
        "optimiser's narrower one",
        "locomotion_jax/optimisation/_objective.py",
        (
            (
                'smoothed.rates_and_normal(P, "paper", eps, t, y, jnp.sqrt(EPS_REF * eps))',
                'smoothed.rates_and_normal(P, "paper", eps, t, y)',
            ),
        ),
        ("tests/test_optimise.py::test_element_rollout_is_the_papers_on_its_two_mass_chain",),
    ),
    Mutation(
        "signals_projected_together",
        "the smoothed stage's projection rescales a chain's signals as one, not each onto its own stroke bound",
        "locomotion_jax/optimisation/_optimise.py",
        (('stroke = cons.project_stroke if theta["cos"].ndim == 1 else', "stroke = cons.project_stroke if True else"),),
        ("tests/test_optimise.py::test_projection_of_several_signals_rescales_each_one",),
    ),
    Mutation(
        "smoothed_spline_accepted",
        "method='smoothed' runs a spline search (its local stage optimises Fourier series)",
        "locomotion_jax/optimisation/_element_local.py",
        (('    if method == "smoothed" and settings.shape != "fourier":\n', "    if False:\n"),),
        ("tests/test_optimise.py::test_bad_input_raises",),
    ),
    Mutation(
        "paper_start_checked_late",
        "the paper's optimiser checks its start= only when it builds its starts, after the sinusoid sweep",
        "locomotion_jax/optimisation/_optimise.py",
        (
            (
                "    start_waveform(start)  # a start that is not the paper's model's is refused before the baseline\n",
                "",
            ),
        ),
        ("tests/test_optimise.py::test_the_papers_start_may_be_an_optimums_dict",),
    ),
    Mutation(
        "evaluator_retry_ignored",
        "the optimisers' evaluator retries a failed orbit whatever its `retry`",
        "locomotion_jax/optimisation/_evaluator.py",
        (("        if not orb.ok.all() and (rested or self.retry):\n", "        if not orb.ok.all():\n"),),
        ("tests/test_optimise.py::test_a_batch_without_retry_leaves_its_failures_unsolved",),
    ),
    Mutation(
        "oracle_step_ignored",
        "the paper's orbit oracle: its transient at a fixed step, not the oracle's `dt`",
        "locomotion_jax/gaits/_orbit.py",
        (
            (
                "                     jnp.asarray(self.dt, self.dtype), self.max_steps)  # fmt: skip",
                "                     jnp.asarray(0.01, self.dtype), self.max_steps)  # fmt: skip",
            ),
        ),
        ("tests/test_optimise.py::test_oracles_of_any_step_and_iteration_cap_share_their_programs",),
    ),
    Mutation(
        "oracle_iteration_cap_ignored",
        "the paper's orbit oracle: Newton's iteration cap fixed, not the oracle's `max_iter`",
        "locomotion_jax/gaits/_orbit.py",
        (("jnp.asarray(self.max_iter, jnp.int32)", "jnp.asarray(30, jnp.int32)"),),
        ("tests/test_optimise.py::test_oracles_of_any_step_and_iteration_cap_share_their_programs",),
    ),
    Mutation(
        "steady_gait_not_bucketed",
        "steady_gait: the batch solved as it is, not as its bucket's rows (a program per batch size)",
        "locomotion_jax/gaits/_gait.py",
        (
            (
                "dynamics=dynamics, contact=contact, say=say, bucket=True)",
                "dynamics=dynamics, contact=contact, say=say)",
            ),
        ),
        ("tests/test_gait.py::test_batch_sizes_of_a_bucket_share_the_solver",),
    ),
    Mutation(
        "precompile_skips_the_check",
        "the exact optimiser's background compilation: not the direct-simulation check's program",
        "locomotion_jax/optimisation/_exact.py",
        (
            (
                "_simulated(params, wave, (True, 1.0, 1.0, 0.5, 2 * math.pi / hi), settings, periods=1)",
                "(params, wave, (True, 1.0, 1.0, 0.5, 2 * math.pi / hi), settings)",
            ),
        ),
        ("tests/test_optimise.py::test_precompiled_verification_is_the_verifications_program",),
    ),
    Mutation(
        "newton_orbit_never_gives_up",
        "the orbit oracle's Newton method: no stop on a stalled residual, whatever its patience",
        "locomotion_jax/gaits/_orbit.py",
        (
            (
                "        return ~started | (~done & ok & (it < max_iter) & (since < patience))\n",
                "        return ~started | (~done & ok & (it < max_iter))\n",
            ),
        ),
        ("tests/test_optimise.py::test_newton_orbit_gives_up_a_cycle",),
    ),
    Mutation(
        "stuck_gait_tried_at_longer_periods",
        "steady gaits: every unstable orbit is tried at the longer periods, one the transient ended on too",
        "locomotion_jax/gaits/_select.py",
        (('~r["stable"] & (np.asarray(r["it"]) > 0)', '~r["stable"]'),),
        ("tests/test_gait.py::test_a_stuck_gait_is_not_tried_at_longer_periods",),
    ),
    Mutation(
        "lane_loop_batched_by_fixpoint",
        "lane_while_loop: the initial carry left as it is, so that vmap batches the loop's body by a fixpoint again",
        "locomotion_jax/_loops.py",
        (("    if not firsts:\n        return tree", "    if True:\n        return tree"),),
        ("tests/test_loops.py::test_lane_while_loop_batches_its_body_once",),
    ),
    Mutation(
        "verification_never_gives_up",
        "the exact optimiser's verification: Newton's method runs every iteration of each gait period, cycling or not",
        "locomotion_jax/optimisation/_exact.py",
        (("guarded=False, patience=orbit.PATIENCE)", "guarded=False, patience=None)"),),
        ("tests/test_optimise.py::test_runners_up_are_verified_where_their_run_fails_or_might_be_cheaper",),
    ),
    Mutation(
        "rested_batch_repeats_its_transient",
        "the orbit evaluator's retry of a batch already rested: the transient from rest and the period-1 solve again",
        "locomotion_jax/optimisation/_evaluator.py",
        (("            if rested:\n", "            if False:\n"),),
        ("tests/test_optimise.py::test_a_rested_batch_retries_its_failures_as_period_2_gaits_alone",),
    ),
    Mutation(
        "sqp_step_ignores_the_multipliers",
        "the SQP step of the local descent: the active constraints' correction dropped (the free step)",
        "locomotion_jax/optimisation/_descent.py",
        (("            d = free + HA @ lam_a\n", "            d = free\n"),),
        ("tests/test_descent.py",),
    ),
    Mutation(
        "mechanism_array_carried_weight_lost",
        "in the array layout a carried body's weight loads itself, not its carrier",
        "locomotion_jax/model/_mechanism_array.py",
        (("normal=M.m if plain else jnp.stack(normal_loads(M), -1)", "normal=M.m"),),
        ("tests/test_mechanism_array.py::test_array_capsule_rates_equal_unrolled",),
    ),
    Mutation(
        "mechanism_array_carried_lift_on_itself",
        "in the array layout a tilted spring lifts a carried body's own load, not its carrier's",
        "locomotion_jax/model/_mechanism_array.py",
        (("lift = [(ground[int(end)], j, sign)", "lift = [(int(end), j, sign)"),),
        ("tests/test_mechanism_array.py::test_array_capsule_rates_equal_unrolled",),
    ),
    Mutation(
        "mechanism_array_carried_body_rides_alone",
        "in the array layout a carried body keeps its own height and flies alone instead of riding in its carrier",
        "locomotion_jax/model/_mechanism_array.py",
        (("        return (q[0][..., np.asarray(self.ground, np.int32)],)\n", "        return q\n"),),
        (
            "tests/test_hop_carried.py::test_a_hopping_capsule_in_the_array_layout_against_the_reference",
            "tests/test_mechanism_array.py::test_array_capsule_runs_equal_unrolled",
        ),
    ),
    Mutation(
        "mechanism_array_contact_unmasked",
        "in the array layout the placeholder load of a body without ground contact counts among the ground reactions",
        "locomotion_jax/model/_mechanism_array.py",
        (("        if all(self.contact):\n            return q\n", "        return q\n"),),
        ("tests/test_mechanism_array.py::test_array_capsule_steady_gait_equals_unrolled",),
    ),
    Mutation(
        "mixed_friction_first_class_only",
        "bodies under laws of several classes in one entry all read the first class's law",
        "locomotion_jax/model/_friction.py",
        (("        for k in range(1, len(values)):\n", "        for k in range(1, 1):\n"),),
        ("tests/test_mechanism_array.py::test_array_capsule_rates_equal_unrolled",),
    ),
    Mutation(
        "mixed_friction_static_at_rest_lost",
        "a mixture of friction laws with a Stribeck member is not taken as static at rest",
        "locomotion_jax/model/_friction.py",
        (("        return any(static_at_rest(q) for q in law.laws)\n", "        return False\n"),),
        ("tests/test_mechanism_array.py::test_array_capsule_rates_equal_unrolled",),
    ),
    Mutation(
        "newton_step_by_solve",
        "Newton's step divides by a zero singular value: a family of orbits (a body stuck all period) fails",
        "locomotion_jax/gaits/_corrector.py",
        (
            (
                "    return jnp.where(jnp.all(jnp.isfinite(step)), step, jnp.linalg.lstsq(A, F)[0])\n",
                "    return step\n",
            ),
        ),
        ("tests/test_gait.py::test_an_anchored_gait_with_a_body_stuck_all_period",),
    ),
    Mutation(
        "tension_waves_isotropic",
        "the idealised inchworm's break-away forces read each mass's forward static coefficient in both directions",
        "locomotion_jax/optimisation/_starts.py",
        (
            (
                "    mu0, mu1 = (fwd[:-1], bwd[1:]) if sign > 0 else (bwd[:-1], fwd[1:])\n",
                "    mu0, mu1 = (fwd[:-1], fwd[1:])\n",
            ),
        ),
        (
            "tests/test_shapes.py::test_tension_waves_of_a_chain_jump_by_each_springs_tension_step_at_its_lagged_switches",
        ),
    ),
    Mutation(
        "tension_waves_lag_ignored",
        "every spring of an idealised inchworm switches its tension at once, whatever the phase lag",
        "locomotion_jax/optimisation/_starts.py",
        (
            (
                "    shift = np.rint(np.arange(S) * lag / (2 * math.pi) * grid).astype(int)\n",
                "    shift = np.zeros(S, int)\n",
            ),
        ),
        (
            "tests/test_shapes.py::test_tension_waves_of_a_chain_jump_by_each_springs_tension_step_at_its_lagged_switches",
        ),
    ),
    Mutation(
        "chain_inchworms_not_refined",
        "the chain optimiser solves its idealised inchworms' gaits but refines the travelling waves only",
        "locomotion_jax/optimisation/_chain.py",
        (
            (
                "        better = np.flatnonzero(screen.preferred(worm_keys, keys[0][0]))\n",
                "        better = np.zeros(0, int)\n",
            ),
        ),
        (
            "tests/test_optimise.py::test_the_chain_optimiser_refines_an_idealised_inchworm_where_no_wave_is_fast_enough",
        ),
    ),
    Mutation(
        "chain_screen_slow_gaits_unordered",
        "the chain screen ranks the stable gaits that miss the requirement in grid order, not by speed",
        "locomotion_jax/optimisation/_chain_screen.py",
        (("np.where(g.ok, np.nan_to_num(-v, nan=np.inf), 0.0))", "np.where(g.ok, 0.0 * v, 0.0))"),),
        ("tests/test_optimise.py::test_screen_ranks_feasible_gaits_by_cost_then_stable_ones_by_speed",),
    ),
    Mutation(
        "chain_inchworms_always_compete",
        "an idealised inchworm worse than the best travelling wave still competes with the waves for a local run",
        "locomotion_jax/optimisation/_chain_screen.py",
        (
            (
                "    return (keys[:, 0] < than[0]) | ((keys[:, 0] == than[0]) & (keys[:, 1] < than[1]))\n",
                "    return keys[:, 0] < 3\n",
            ),
        ),
        ("tests/test_optimise.py::test_screen_ranks_feasible_gaits_by_cost_then_stable_ones_by_speed",),
    ),
    Mutation(
        "chain_spline_verified_unresolved",
        "a spline search (a chain's, a mechanism's) verifies its candidates at dt even where dt does not resolve "
        "their knots",
        "locomotion_jax/optimisation/_element_local.py",
        (
            (
                "    return settings if dt == settings.dt else dataclasses.replace(settings, dt=dt, search_dt=None)\n",
                "    return settings\n",
            ),
        ),
        (
            "tests/test_optimise.py::test_the_chain_optimiser_refines_an_idealised_inchworm_where_no_wave_is_fast_enough",
        ),
    ),
    Mutation(
        "chain_spline_search_guarded",
        "the chain optimiser's search skips the splines whose knots its step does not resolve",
        "locomotion_jax/optimisation/_chain_screen.py",
        (
            (
                "        g = solve(chain, None, None, omega, settings, say, need, control=control, guarded=False)\n",
                "        g = solve(chain, None, None, omega, settings, say, need, control=control)\n",
            ),
        ),
        (
            "tests/test_optimise.py::test_the_chain_optimiser_refines_an_idealised_inchworm_where_no_wave_is_fast_enough",
        ),
    ),
    Mutation(
        "mechanism_spline_verified_unresolved",
        "a mechanism's spline search verifies its candidates at dt even where dt does not resolve their knots",
        "locomotion_jax/optimisation/_mechanism.py",
        (
            (
                "        checked = local.resolved(_spline(base, np.zeros((S, M)), fastest), settings)\n",
                "        pass\n",
            ),
        ),
        ("tests/test_optimise.py::test_a_mechanism_spline_search_verifies_at_a_step_that_resolves_its_knots",),
    ),
    Mutation(
        "chain_inchworms_in_every_search",
        "a chain's Fourier search solves the idealised inchworms by default too",
        "locomotion_jax/optimisation/_chain_screen.py",
        (("else (10 if knots else 0)", "else 10"),),
        ("tests/test_optimise.py::test_inchworm_starts_by_default_in_a_spline_search_of_rest_lengths_only",),
    ),
    Mutation(
        "still_gait_costs_rounding",
        "a gait that dissipates nothing costs its energy over the rounding of its distance (0) instead of inf",
        "locomotion_jax/gaits/_select.py",
        (("    still = (dist == 0) | (e == 0)\n", "    still = dist == 0\n"),),
        ("tests/test_mechanism_features.py::test_a_capsule_stuck_all_period_does_not_move",),
    ),
    Mutation(
        "simulated_agreement_divides_by_zero",
        "the optimum's direct-simulation check divides by the gait's speed and cost as Python floats",
        "locomotion_jax/optimisation/_element_local.py",
        (
            (
                "        agreement = float(np.maximum(abs(speed_s / speed - 1), abs(cost_s / cost - 1)))\n",
                "        agreement = max(abs(float(speed_s) / speed - 1), abs(float(cost_s) / cost - 1))\n",
            ),
        ),
        ("tests/test_mechanism_features.py::test_a_capsule_stuck_all_period_does_not_move",),
    ),
    Mutation(
        "anchored_gait_travels_its_residual",
        "an anchored mechanism's gait moves by Newton's residual over its period",
        "locomotion_jax/gaits/_shooting.py",
        (("    return jnp.zeros_like(dX) if P.anchored else dX\n", "    return dX\n"),),
        ("tests/test_gait.py::test_siconos_oscillator_with_a_harmonic_wall_force_against_the_reference",),
    ),
    Mutation(
        "choose_ignores_the_tie_of_costs",
        "the cheapest candidate is reported by rounding among equally cheap ones, not the most stable",
        "locomotion_jax/optimisation/_optimum.py",
        (("            k = int(np.argmin(np.where(tied, radius, np.inf)))\n", "            pass\n"),),
        ("tests/test_optimise.py::test_choose_takes_the_cheapest_feasible_else_the_fastest_stable_gait",),
    ),
    Mutation(
        "mechanism_screen_in_phase",
        "a mechanism's screen drives every element in phase whatever its lag",
        "locomotion_jax/optimisation/_mechanism.py",
        (
            (
                "    shift = phase[:, None] - np.arange(S)[None] * lag[:, None]\n",
                "    shift = phase[:, None] + 0 * lag[:, None]\n",
            ),
        ),
        ("tests/test_optimise.py::test_a_mechanisms_screen_drives_its_elements_as_travelling_waves",),
    ),
    Mutation(
        "mechanism_lags_from_chain_dropped",
        "a chain's settings reach a mechanism with the default lags, not its phases",
        "locomotion_jax/optimisation/_element_optimum.py",
        (("        return cls(**own, lags=s.phases)\n", "        return cls(**own)\n"),),
        ("tests/test_optimise.py::test_mechanism_optimise_settings",),
    ),
    Mutation(
        "element_half_step_ignored",
        "a chain's or a mechanism's candidate counts as stable whatever its gait at half the step",
        "locomotion_jax/optimisation/_element_local.py",
        (
            (
                "    g = dict(g, ok=steady_at_half_step(full_ok > 0, full_v, full_c, half_ok > 0, half_v, half_c))\n",
                "    g = dict(g)\n",
            ),
        ),
        ("tests/test_optimise.py::test_a_candidate_is_stable_only_where_half_the_step_agrees",),
    ),
    Mutation(
        "actuator_fields_batched_unrolled",
        "the unrolled chain physics carries its actuator's fields as batched values",
        "locomotion_jax/model/_chain_physics.py",
        (("    actuator: AbstractActuator = eqx.field(static=True)\n", "    actuator: AbstractActuator\n"),),
        ("tests/test_docs_examples.py::test_the_bellows_is_an_internal_force_of_area_times_pressure",),
    ),
    Mutation(
        "actuator_fields_batched_array",
        "the array-layout chain physics carries its actuator's fields as batched values",
        "locomotion_jax/model/_chain_array.py",
        (("    actuator: AbstractActuator = eqx.field(static=True)\n", "    actuator: AbstractActuator\n"),),
        ("tests/test_docs_examples.py::test_the_bellows_is_an_internal_force_of_area_times_pressure",),
    ),
    Mutation(
        "actuator_array_field_taken",
        "an actuator's field of several values is taken, not refused",
        "locomotion_jax/model/_chain.py",
        (
            (
                "            if np.ndim(value):  # the actuator is static",
                "            if False:  # the actuator is static",
            ),
        ),
        ("tests/test_docs_examples.py::test_an_actuator_is_one_for_the_whole_batch",),
    ),
    Mutation(
        "oracle_tolerance_grows_unbounded",
        "the optimisers' orbit oracle: Newton's convergence test scaled by the iterate's size, however large",
        "locomotion_jax/gaits/_orbit.py",
        (
            (
                "        return residual(y, val) <= tol * (1 + tolerance_scale(y, y0))",
                "        return residual(y, val) <= tol * (1 + jnp.max(jnp.abs(y)))",
            ),
        ),
        ("tests/test_optimise.py::test_newton_does_not_accept_an_orbit_that_ran_off",),
    ),
    Mutation(
        "steady_gait_tolerance_grows_unbounded",
        "steady_gait's corrector: Newton's convergence test scaled by the iterate's size, however large",
        "locomotion_jax/gaits/_corrector.py",
        (("tol * (1 + tolerance_scale(z[:n], z0[:n]))", "tol * (1 + jnp.max(jnp.abs(z[:n])))"),),
        ("tests/test_optimise.py::test_newton_does_not_accept_an_orbit_that_ran_off",),
    ),
    Mutation(
        "tilted_spring_start_unchecked",
        "a horizontal tilted spring's start with its ends out of order is accepted (it stops at its first step)",
        "locomotion_jax/model/_bodies.py",
        (
            (
                "out.append((owner, name, (el.d != 0) | (u > 0), valid, u))",
                "out.append((owner, name, u == u, valid, u))",
            ),
        ),
        (
            "tests/test_collision.py::test_a_horizontal_tilted_spring_starts_with_its_ends_in_order",
            "tests/test_mechanism.py::test_bad_input_names_the_element_and_the_body",
        ),
    ),
    Mutation(
        "tilted_spring_turn_unchecked",
        "the exact engine lets a tilted spring's ends pass each other in a step that does not resolve its turn",
        "locomotion_jax/dynamics/_engine.py",
        (("    if turned:\n", "    if turned and False:\n"),),
        ("tests/test_collision.py::test_a_tilted_spring_whose_turn_a_step_does_not_resolve_stops_unresolved",),
    ),
    Mutation(
        "mechanism_inchworms_not_refined",
        "the mechanism optimiser solves its idealised inchworms' gaits but refines the sinusoids only",
        "locomotion_jax/optimisation/_mechanism.py",
        (
            (
                "        better = np.flatnonzero(screen.preferred(worm_keys, keys[0]))\n",
                "        better = np.zeros(0, int)\n",
            ),
        ),
        (
            "tests/test_optimise.py::test_the_mechanism_optimiser_refines_an_idealised_inchworm_where_no_sinusoid_is_fast_enough",
        ),
    ),
    Mutation(
        "mechanism_tension_waves_carried_weight_ignored",
        "a mechanism's idealised inchworm breaks a body away against its own weight, not the weights it carries",
        "locomotion_jax/optimisation/_starts.py",
        (
            (
                "    return mu * float(P.normal[i]) / den if den > 0 else math.inf\n",
                "    return mu * float(P.m[i]) / den if den > 0 else math.inf\n",
            ),
        ),
        (
            "tests/test_shapes.py::test_tension_waves_of_a_capsules_internal_force_alternate_by_the_capsules_break_away_force",
        ),
    ),
    Mutation(
        "mechanism_tension_waves_tilt_ignored",
        "a mechanism's idealised inchworm breaks a tilted spring's ends away as if it were horizontal",
        "locomotion_jax/optimisation/_starts.py",
        (
            (
                "        h, q = (abs(u) / length, d / length) if isinstance(el, TiltedSpring) else (1.0, 0.0)\n",
                "        h, q = (abs(u) / length, 0.0) if isinstance(el, TiltedSpring) else (1.0, 0.0)\n",
            ),
        ),
        ("tests/test_shapes.py::test_tension_waves_of_a_mechanism_are_its_chains",),
    ),
]


def _copy(dest: Path) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache")
    for name in ("locomotion_jax", "tests"):
        shutil.copytree(ROOT / name, dest / name, ignore=ignore)
    # The pages whose classes the tests read (`tests/docs_examples.py`).
    shutil.copytree(ROOT / "docs", dest / "docs", ignore=shutil.ignore_patterns("*.png", "*.gif", "*.ipynb"))
    shutil.copy2(ROOT / "pyproject.toml", dest / "pyproject.toml")


def _apply(dest: Path, m: Mutation) -> None:
    path = dest / m.path
    text = path.read_text()
    for old, new in m.edits:
        count = text.count(old)
        if count != 1:
            raise RuntimeError(f"{m.name}: {old!r} occurs {count} times in {m.path} (expected once)")
        text = text.replace(old, new)
    path.write_text(text)


def _run_tests(dest: Path, tests: tuple[str, ...], workers: int, cache: str) -> tuple[bool, str, float]:
    """Run `tests` in the copy at `dest`; returns (all passed, first failing test or error, seconds)."""
    env = {**os.environ, "PYTHONPATH": str(dest), "LJ_REFERENCE_CACHE": cache}
    # --slow: a mutation runs the tests named for it, those marked slow included.
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "--slow"]
    if workers > 1:
        cmd += ["-n", str(workers)]
    t = time.time()
    res = subprocess.run(cmd + list(tests), cwd=dest, env=env, capture_output=True, text=True)
    took = time.time() - t
    if res.returncode == 0:
        return True, "", took
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", res.stdout, re.M)
    return False, failed[0] if failed else f"pytest exit {res.returncode}: {res.stdout[-300:]}", took


def _check_import(dest: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(dest)}
    out = subprocess.run(
        [sys.executable, "-c", "import locomotion_jax; print(locomotion_jax.__file__)"],
        cwd=dest, env=env, capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    if not out.startswith(str(dest)):
        raise RuntimeError(f"the copy at {dest} is not the package imported ({out})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("names", nargs="*", help="mutations to run (default: all)")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--workers", type=int, default=1, help="pytest-xdist workers per run (default 1)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the run of the unmutated copy")
    ap.add_argument(
        "--cache", default=os.environ.get("LJ_REFERENCE_CACHE", str(Path(tempfile.gettempdir()) / "lj-reference")),
        help="where the reference results are kept between runs",
    )  # fmt: skip
    args = ap.parse_args(argv)
    chosen = [m for m in MUTATIONS if not args.names or m.name in args.names]
    unknown = set(args.names) - {m.name for m in MUTATIONS}
    if unknown:
        ap.error(f"unknown mutation(s) {sorted(unknown)}; --list shows them")
    if args.list:
        for m in MUTATIONS:
            print(f"{m.name:30s} {m.what}")
        return 0

    with tempfile.TemporaryDirectory(prefix="lj-mutations-") as tmp:
        if not args.no_baseline:
            base = Path(tmp) / "baseline"
            _copy(base)
            _check_import(base)
            tests = tuple(dict.fromkeys(t for m in chosen for t in m.tests))
            ok, failed, took = _run_tests(base, tests, args.workers, args.cache)
            print(f"baseline (unmutated): {'passes' if ok else 'FAILS: ' + failed} ({took:.0f} s)", flush=True)
            if not ok:
                return 2
        rows = []
        for m in chosen:
            dest = Path(tmp) / m.name
            _copy(dest)
            _apply(dest, m)
            ok, failed, took = _run_tests(dest, m.tests, args.workers, args.cache)
            rows.append((m, not ok, failed))
            status = f"killed by {failed}" if not ok else "survived (equivalent)" if m.equivalent else "SURVIVED"
            print(f"{m.name:30s} {status} ({took:.0f} s)", flush=True)
            shutil.rmtree(dest)
    killed = sum(k for _, k, _ in rows)
    equivalent = [m for m, k, _ in rows if m.equivalent and not k]
    print(f"\n{killed}/{len(rows) - len(equivalent)} mutations killed, {len(equivalent)} equivalent")
    for m in equivalent:
        print(f"  {m.name} is equivalent: {m.equivalent}")
    print("\n| mutation | what | killed by |\n|---|---|---|")
    for m, k, failed in rows:
        verdict = f"`{failed}`" if k else "equivalent (no observable change)" if m.equivalent else "**survived**"
        print(f"| `{m.name}` | {m.what} | {verdict} |")
    return 0 if killed + len(equivalent) == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
