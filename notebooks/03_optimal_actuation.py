# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 03 · Optimal actuation: which waveform reaches a required speed for the least energy?
#
# The paper (Sect. 2.3) asks for "a framework by which the optimal $\ell_0(t)$ would minimize energy
# consumption while still ensuring that certain performance metrics are satisfied". This notebook
# answers: **for a required mean speed $v_\min$ and a stroke limit $a_\max$, which periodic rest-length
# waveform $\ell_0(t)$ costs the least energy per distance, how much better is it than the best
# sinusoid, and what does it look like?**
#
# `lj.optimise` searches truncated Fourier series
# $\ell_0(t) = \bar\ell + \sum_{n=1}^{N} A_n\cos n\omega t + B_n\sin n\omega t$ (`lj.Fourier`) for
#
# $$\min\ \frac{e_d}{\Delta X}\quad\text{s.t.}\quad \bar v \ge v_\min,\qquad
# \max_t|\ell_0(t) - \bar\ell| \le a_\max,\qquad \text{no lift-off } (N_1, N_2 > 0),$$
#
# directly on the **steady gaits of the exact hybrid model**: each candidate's periodic orbit is
# solved by Newton's method, and the gradients of its speed and cost come from forward-mode
# differentiation through the exact engine and the implicit function theorem. Every figure is an
# average over whole periods of the steady gait (`lj.steady_gait`, strict contact, from the relaxed
# spring), and the optimum must be a stable gait. The baseline is the best sinusoid
# $a\sin\omega t$ ($a \le a_\max$) from an exact sweep over $(a, \omega)$.
#
# This notebook searches the Fourier family (`ExactOptimiseSettings(shape="fourier")`), whose
# coefficients are easy to read; the optimiser's default stroke is a periodic spline of 64 knots
# (`lj.Spline`), which also represents the step-like strokes of the fast gaits (the README's
# "Optimal actuation"). Its default size is kept small: one required speed, 4 harmonics, one local
# run of at most 20 iterations from two starts and a coarse sinusoid sweep, so its numbers are
# illustrative (the default search, `ExactOptimiseSettings(shape="fourier")` at 16 harmonics for
# three speeds, took over ten minutes on a 2-core CPU); the optimiser itself is checked against the event-driven
# reference in `tests/test_optimise.py`. CI runs it at a tiny size (a few iterations).

# %%
import os

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import locomotion_jax as lj
import matplotlib.pyplot as plt
import numpy as np


# CI runs every notebook top to bottom at a small size (tests/test_notebooks.py sets LOCOMOTION_NB_SMALL=1).
SMALL = os.environ.get("LOCOMOTION_NB_SMALL") == "1"
A_MAX = 0.05  # stroke limit: the paper's amplitude
HARMONICS = 4
SPEEDS = (0.01,) if SMALL else (0.02,)  # required mean speeds: one optimum each
V_MIN = SPEEDS[-1]  # the one looked at in detail
if SMALL:
    SETTINGS = lj.ExactOptimiseSettings(
        shape="fourier", local=2, start_frequencies=2, random_shapes=0, tension_periods=2, max_iter=10, stages=1,
        transient=20, refine_baseline=False,
    )  # fmt: skip
    SWEEP = dict(omegas=np.array([1.0, 2.0, 4.0, 6.0]), amplitudes=2, transient=20)
else:
    # Sized to run in minutes, not tens: one local run from the best of two starts, one stage.
    SETTINGS = lj.ExactOptimiseSettings(
        shape="fourier", local=1, start_frequencies=2, random_shapes=0, tension_periods=2, max_iter=20, stages=1,
        transient=20, refine_baseline=False,
    )  # fmt: skip
    SWEEP = dict(omegas=np.geomspace(1.0, 6.0, 8), amplitudes=2, transient=20)  # 2 amplitudes x 8 frequencies
IMAGES = os.environ.get("LOCOMOTION_NB_IMAGES")  # set to a directory to save this notebook's picture there
params = lj.Params(a=A_MAX)  # the paper's defaults; `a` and `omega` are the optimiser's to choose

# %% [markdown]
# ## 1. The baseline: every sinusoid on the exact model
#
# `lj.sinusoid_sweep` solves the steady gait of $a\sin\omega t$ over a grid of amplitudes $a \le a_\max$
# and frequencies in one batched call of the exact engine: mean speed and cost of transport
# $e_d/|\Delta X|$ over whole periods, with lift-off or an unstable or unconverged gait marking a
# configuration infeasible. `lj.best_sinusoid` picks the
# cheapest one fast enough; `lj.pareto_front` keeps the sinusoids that no other one beats in both
# speed and cost.

# %%
sweep = lj.sinusoid_sweep(params, A_MAX, **SWEEP)
baseline = lj.best_sinusoid(sweep, V_MIN, +1)
print(f"{sweep.ok.sum()} of {sweep.ok.size} sinusoids finish without lift-off; fastest: {np.nanmax(sweep.speed):.4f}")
print(f"best sinusoid for v >= {V_MIN}:", baseline)

# %% [markdown]
# ## 2. Optimise
#
# One call per required speed, each also started from the previous speed's optimum (`start=`:
# continuation in $v_\min$). The result (`lj.Optimum`) holds the coefficients, the exact figures,
# which constraints hold on the exact model, the gait's stability, and the comparison with the best
# sinusoid (`opt.sinusoid`; with `refine_baseline=True`, the default, the sweep's best sinusoid is
# first refined on a finer local grid, so the optimum is compared with a well-resolved sinusoid);
# `summary()` prints them.

# %%
optima, previous = {}, None
for v in SPEEDS:
    optima[v] = lj.optimise(params, v, A_MAX, harmonics=HARMONICS, settings=SETTINGS, sweep=sweep, start=previous)
    previous = optima[v] if optima[v].feasible_exact else previous
    print(f"v_min = {v:g}: done in {optima[v].runtime_s:.0f} s", flush=True)
opt = optima[V_MIN]
print(opt.summary())

# %%
for v, o in optima.items():
    print(
        f"v_min = {v:<5g} feasible on the exact model: {o.feasible_exact!s:5}  speed {o.mean_speed_exact:.4f}  "
        f"cost {o.cost_of_transport_exact:.4g}  best sinusoid {o.sinusoid_cost_of_transport:.4g}  "
        f"improvement {100 * o.improvement_vs_sinusoid:+.1f} %"
    )

# %% [markdown]
# ## 3. Check it yourself on the exact model
#
# The optimiser's figures are those of the periodic orbit; here the optimum and the best sinusoid are
# simulated again directly with `lj.simulate` (one batched call: the sinusoid written as a `Fourier`
# series with the same number of harmonics) for 150 periods from the relaxed spring, and speed and
# cost are recomputed from the saved centre of mass $X$ and dissipated energy $e_d$ over the last 20
# whole periods.


# %%
def as_fourier(o):
    """The optimum's waveform, and the best sinusoid (if any is fast enough) as a Fourier series of the same size."""
    waves = {"optimum": lj.Fourier(o.cos, o.sin, o.omega, o.lbar)}
    if o.sinusoid is not None:
        s = o.sinusoid
        waves["best sinusoid"] = lj.Fourier.from_sinusoid(s["a"], s["omega"], o.lbar, harmonics=o.harmonics)
    return waves


waves = as_fourier(opt)
stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x, float) for x in xs]), *waves.values())
# Each configuration's `omega` set to its waveform's base frequency; both runs on the optimum's period grid.
pair = lj.Params.stack([params.replace(omega=float(w.omega)) for w in waves.values()])
periods = np.array([2 * np.pi / float(w.omega) for w in waves.values()])
check = [
    lj.simulate(
        pair[i],
        150 * periods[i],
        save_at=np.linspace(130, 150, 401) * periods[i],
        waveform=jax.tree_util.tree_map(lambda x: x[i], stacked),
        start="relaxed",
    )  # fmt: skip
    for i in range(len(waves))
]
for i, name in enumerate(waves):
    dX = float(check[i].X[-1] - check[i].X[0])
    de = float(check[i].e_d[-1] - check[i].e_d[0])
    print(
        f"{name:14s} speed {dX / (20 * periods[i]):.5f}  cost of transport {de / abs(dX):.5f}  "
        f"status {lj.Status(int(check[i].status)).name}"
    )
print(f"optimiser's figures: optimum speed {opt.mean_speed_exact:.5f} cost {opt.cost_of_transport_exact:.5f}")
if opt.sinusoid is not None:
    print(
        f"                     sinusoid speed {opt.sinusoid['mean_speed']:.5f} "
        f"cost {opt.sinusoid_cost_of_transport:.5f}"
    )

fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), layout="constrained")
for i, name in enumerate(waves):
    t_rel = np.asarray(check[i].t) - float(check[i].t[0])
    axes[0].plot(t_rel, check[i].X - check[i].X[0], label=name)
    axes[1].plot(t_rel, check[i].e_d - check[i].e_d[0], label=name)
t_rel = np.asarray(check[0].t) - float(check[0].t[0])
axes[0].plot(t_rel, V_MIN * t_rel, "k:", label=f"required speed {V_MIN:g}")
axes[0].set_ylabel(r"$X - X(t_0)$")
axes[1].set_ylabel(r"$e_d - e_d(t_0)$")
for ax in axes:
    ax.set_xlabel(r"$t - t_0$ (after 130 periods)")
    ax.legend(fontsize=8)
plt.show()

# %% [markdown]
# ## 4. The optimal waveform, one period of its motion, and the Pareto front
#
# Top left: $\ell_0(t) - \bar\ell$ over one period for the optimum and the best sinusoid, with the stroke
# limit. Bottom left: one steady-state period of the optimum's motion, with the contact modes. Right: cost
# of transport against speed for every sinusoid of the sweep (grey), their Pareto front, and the
# verified optima (stars): a point below the sinusoids' front is a waveform that is cheaper than any
# sinusoid at that speed.

# %%
fig, axes = plt.subplot_mosaic(
    [["wave", "pareto"], ["period", "pareto"]], figsize=(11, 6.4), layout="constrained", width_ratios=[1, 1.15]
)
ax = axes["wave"]
phase = np.linspace(0.0, 1.0, 400)
for (name, wave), style in zip(waves.items(), ("-", "--")):
    l0, _ = wave(jnp.asarray(phase * 2 * np.pi / float(wave.omega)))
    ax.plot(phase, np.asarray(l0) - float(wave.lbar), style, lw=2, label=f"{name}, $\\omega$ = {float(wave.omega):.3g}")
for sign in (1, -1):
    ax.axhline(sign * A_MAX, color="k", ls=":", lw=0.8)
ax.set_xlabel("t / period")
ax.set_ylabel(r"$\ell_0(t) - \bar\ell$")
ax.set_title(f"waveforms for mean speed $\\geq$ {V_MIN:g} (dotted: stroke limit)", fontsize=9)
ax.legend(fontsize=7, loc="lower left")

ax = axes["period"]
period = 2 * np.pi / opt.omega
t_end = 150 * period
one = lj.simulate(
    params.replace(omega=opt.omega),
    t_end,
    save_at=np.linspace(t_end - period, t_end, 401),
    waveform=waves["optimum"],
    start="relaxed",
)
ph = (np.asarray(one.t) - float(one.t[0])) / period
mode = np.asarray(one.mode)
for k, x in ((1, one.x1), (2, one.x2)):
    ax.plot(ph, np.asarray(x) - float(x[0]), label=f"$x_{k} - x_{k}(t_0)$")
stuck1 = np.isin(mode, [lj.Mode.BOTH_STICK, lj.Mode.M2_SLIPS])
stuck2 = np.isin(mode, [lj.Mode.BOTH_STICK, lj.Mode.M1_SLIPS])
ax.fill_between(
    ph, 0, 1, where=stuck1, transform=ax.get_xaxis_transform(), color="C0", alpha=0.15, lw=0, label="m1 stuck"
)
ax.fill_between(
    ph, 0, 1, where=stuck2, transform=ax.get_xaxis_transform(), color="C1", alpha=0.15, lw=0, label="m2 stuck"
)
ax.set_xlabel("(t - t0) / period")
ax.set_ylabel("displacement")
ax.set_title("one steady-state period of the optimum (exact model)", fontsize=9)
ax.legend(fontsize=7, loc="upper left")

ax = axes["pareto"]
good = sweep.ok & np.isfinite(sweep.cost) & (sweep.speed > 0)
ax.scatter(sweep.speed[good], sweep.cost[good], s=8, c="0.7", label="sinusoids (exact sweep)")
front = lj.pareto_front(sweep.speed, sweep.cost, sweep.ok)
ax.plot(sweep.speed[front], sweep.cost[front], "o-", ms=3, color="C0", label="sinusoids' Pareto front")
feasible = [o for o in optima.values() if o.feasible_exact]
ax.plot(
    [o.mean_speed_exact for o in feasible],
    [o.cost_of_transport_exact for o in feasible],
    "*",
    ms=12,
    color="C3",
    label="optimised waveforms (verified)",
)
for v in SPEEDS:
    ax.axvline(v, color="C3", lw=0.6, ls=":")
ax.set_xlabel("mean speed (exact model)")
ax.set_ylabel(r"cost of transport $e_d / |\Delta X|$")
ax.set_yscale("log")
ax.set_title("cost vs speed (dotted: required speeds)", fontsize=9)
ax.legend(fontsize=7)
if IMAGES:
    fig.savefig(os.path.join(IMAGES, "03_optimal_actuation.png"), dpi=60)
plt.show()

# %% [markdown]
# **Reading the result.** The optimiser's figures are only ever the exact model's, over whole periods
# of a stable steady gait. `opt.candidates` lists every refined candidate with its verified figures,
# `opt.history` the starts and the local iterations. The older method (`method="smoothed"`: Adam on a
# smoothed friction model with 3 harmonics, then an exact check) is still available. The same runs are
# available from the command line: `locomotion-jax optimize --v-min 0.02 --a-max 0.05`.
