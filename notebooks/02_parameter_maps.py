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
# # 02 · Parameter maps: where does the robot stick-slip, and how fast and cheaply does it move?
#
# This notebook answers: **over the actuation's frequency $\omega$ and amplitude $a$, where is the
# motion stick-slip (SSL) or pure slip (SL), how long does it take to travel a distance $z$
# ($\tau_z$) and at what energy ($e_z$), and how does this relate to the natural frequencies?**
#
# Everything comes from `lj.sweep`, which runs the exact engine's `measure` over a grid in compiled,
# vmapped chunks (sharded over every device JAX sees) and returns an **xarray `Dataset`**: one
# dimension per swept parameter, one variable per measurement. The measurements follow the paper
# (Sect. 3): they start at $t_\text{start}$ = 80 periods of the slowest natural frequency; the regime
# is SSL when a mass is stuck for a positive time in the window $[t_\text{start}, t_\text{start} + 25]$;
# $\tau_z$ is the time after $t_\text{start}$ until the centre of mass has moved $z$ (paper: $z = 5$),
# and $e_z$ the energy dissipated meanwhile (eq. 15).
#
# The default contact reading is the physical one (`contact="strict"`): where a normal force reaches
# zero (**lift-off**) the model no longer applies and the configuration is flagged `Status.LIFTOFF`,
# not silently continued. The maps show those configurations hatched.
#
# All runs here start from the relaxed spring (`start="relaxed"`, $x_2 - x_1 = \sqrt{\bar\ell^2 - d^2}$).
# The paper's start (eq. 14, $x_2 - x_1 = \bar\ell$) pre-stretches the spring, and that kick alone lifts a
# light mass off at $t = 0$ (for $\hat m \lesssim 0.17$, say) in configurations whose steady state keeps
# contact; the relaxed start shows the lift-off that belongs to the steady motion.

# %%
import os


# A CPU is one XLA device unless asked otherwise: one device per core lets `sweep` use every core.
# (This must happen before JAX starts; the command line does the same with --cpu-devices.)
_flags = os.environ.get("XLA_FLAGS", "")
if "xla_force_host_platform_device_count" not in _flags:
    os.environ["XLA_FLAGS"] = f"{_flags} --xla_force_host_platform_device_count={len(os.sched_getaffinity(0))}"

import jax


jax.config.update("jax_enable_x64", True)

import locomotion_jax as lj
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm
from matplotlib.patches import Patch


# CI runs every notebook top to bottom at a small size (tests/test_notebooks.py sets LOCOMOTION_NB_SMALL=1).
SMALL = os.environ.get("LOCOMOTION_NB_SMALL") == "1"
SIZE = (
    dict(
        n_ratio=8, n_a=4, n_tau_ratio=6, n_tau_a=3, z=1.0, horizon=150.0, n_slice=16, n_mhat=5, n_mhat_omega=6, chunk=16
    )
    if SMALL
    else dict(
        n_ratio=128,
        n_a=64,
        n_tau_ratio=64,
        n_tau_a=16,
        z=5.0,
        horizon=1000.0,
        n_slice=200,
        n_mhat=49,
        n_mhat_omega=96,
        chunk=128,
    )
)
Z, HORIZON, WINDOW = SIZE["z"], SIZE["horizon"], 25.0
# One step cap for every sweep (it is a compile-time constant, so all sweeps share one compilation):
# room for the slowest t_start of the notebook (mhat = 0.05 or 0.95: about 98) plus the longest horizon.
DYNAMICS = lj.Exact(dt=0.01, max_steps=int(3 * (100 + HORIZON) / 0.01) + 20_000)
OPTS = dict(dynamics=DYNAMICS, start="relaxed", chunk_size=SIZE["chunk"], progress=False)
IMAGES = os.environ.get("LOCOMOTION_NB_IMAGES")  # set to a directory to save this notebook's picture there
print(f"{len(jax.devices())} device(s); z = {Z}, horizon = {HORIZON}")

base = lj.Params()
WN1, WN2 = float(base.wn1), float(base.wn2)  # 10 and sqrt(50) = 7.07 (wn3 = wn2 for mhat = 0.5)

# %% [markdown]
# ## 1. The SSL / SL map over $(\omega/\omega_{n1}, a)$
#
# Only the regime is needed here, so each configuration runs to the end of the window and no further
# (`horizon = window = 25`). The axis `omega_over_wn1` is a convenience of `sweep`: the dataset then also
# holds the derived `omega`.

# %%
ratios = np.linspace(0.05, 2.5, SIZE["n_ratio"])
amps = np.linspace(0.005, 0.12, SIZE["n_a"])
regime_map = lj.sweep({"omega_over_wn1": ratios, "a": amps}, horizon=WINDOW, window=WINDOW, **OPTS)
regime_map

# %% [markdown]
# ### Reading the dataset
#
# Variables are labelled arrays: select by label with `.sel`, by position with `.isel`, reduce with
# `.mean`, `.sum`... The attributes record everything needed to reproduce the sweep (fixed
# parameters, dynamics, contact reading, start, z, horizon, package version).

# %%
print("dimensions:", dict(regime_map.sizes))
print("fixed parameters:", {k.removeprefix("fixed_"): v for k, v in regime_map.attrs.items() if k.startswith("fixed_")})
print(
    "contact:",
    regime_map.attrs["contact"],
    "| start:",
    regime_map.attrs["start"],
    "| dynamics:",
    regime_map.attrs["dynamics"],
    "| status codes:",
    regime_map.attrs["status_codes"],
)
# The regime at a = 0.05 (nearest grid value) for every frequency, as a small table:
at_a = regime_map[["regime", "status", "mean_speed", "stick_fraction1"]].sel(a=0.05, method="nearest")
print(at_a.to_dataframe().round(4).head(8))
# Counts of each outcome over the map:
codes, counts = np.unique(regime_map.regime.values, return_counts=True)
print(
    {lj.Regime(int(c)).name: int(n) for c, n in zip(codes, counts)},
    "| lift-off:",
    int(regime_map.liftoff.sum()),
    "of",
    regime_map.liftoff.size,
)

# %% [markdown]
# ### The map, with the natural frequencies
#
# Four classes: SSL, SL, *at rest* (both masses stuck through the whole window: SSL by the paper's rule,
# but no locomotion) and lift-off (hatched, outside the model). The dotted lines are the natural
# frequencies of the modes: $\omega_{n1}$ (both slip) and $\omega_{n2} = \omega_{n3}$ (one mass stuck).

# %%
CLASS_NAMES = ["at rest (both stuck)", "SSL", "SL", "lift-off / undetermined"]
CLASS_COLORS = ["#e8e8e8", "#5b9bd5", "#fbe5c8", "#b0b0b0"]


def classes(ds):
    """0 at rest, 1 SSL, 2 SL, 3 lift-off or undetermined, from the dataset's regime and stick fractions."""
    reg = ds.regime.values
    rest = (ds.stick_fraction1.values >= 1 - 1e-9) & (ds.stick_fraction2.values >= 1 - 1e-9)
    out = np.where(reg == lj.Regime.SSL, 1, np.where(reg == lj.Regime.SL, 2, 3))
    return np.where((reg == lj.Regime.SSL) & rest, 0, out)


def hatch_liftoff(ax, x, y, liftoff):
    """Hatch the cells (centred on the samples, like the maps) where a normal force reached zero."""
    if liftoff.any():
        cells = np.ma.masked_where(~np.asarray(liftoff, bool), np.ones(liftoff.shape))
        ax.pcolor(x, y, cells, shading="nearest", hatch="////", facecolor="none", edgecolor="0.35", lw=0)


def natural_frequencies(ax, wn_over_wn1):
    for r, label in wn_over_wn1:
        ax.axhline(r, color="k", ls=":", lw=1)
        ax.annotate(label, (1.0, r), xycoords=("axes fraction", "data"), ha="right", va="bottom", fontsize=8)


cls = classes(regime_map)
fig, ax = plt.subplots(figsize=(7.5, 4.2), layout="constrained")
ax.pcolormesh(
    amps, ratios, cls, cmap=ListedColormap(CLASS_COLORS), norm=BoundaryNorm(np.arange(-0.5, 4), 4), shading="nearest"
)
hatch_liftoff(ax, amps, ratios, regime_map.liftoff.values)
natural_frequencies(ax, [(1.0, r"$\omega_{n1}$"), (WN2 / WN1, r"$\omega_{n2} = \omega_{n3}$")])
ax.set_xlabel("amplitude $a$")
ax.set_ylabel(r"$\omega / \omega_{n1}$")
ax.legend(
    handles=[Patch(color=c, label=n) for c, n in zip(CLASS_COLORS, CLASS_NAMES)]
    + [Patch(fc="none", ec="k", hatch="////", label="lift-off (strict contact)")],
    fontsize=7,
    loc="upper left",
    bbox_to_anchor=(1.01, 1.0),
    frameon=False,
)
ax.set_title(f"Regime over {ratios.size} frequencies x {amps.size} amplitudes (paper defaults otherwise)", fontsize=9)
if IMAGES:
    fig.savefig(os.path.join(IMAGES, "02_parameter_maps.png"), dpi=72)
plt.show()

# %% [markdown]
# SSL lives at low frequency and small amplitude, below the natural frequencies; around
# $\omega_{n1}$ the spring resonates, the normal forces swing through zero and the model's contact
# assumption fails (the paper's $n_i = |N_i|$ reading, `contact="paper"`, integrates through it).

# %% [markdown]
# ## 2. $\tau_z$ and $e_z$ maps
#
# Now the runs continue after the window until the centre of mass has moved $z$ or the horizon ends.
# A configuration that never gets there has `tau_z = inf`, `e_z = inf` and `reached = False`: an
# explicit "not reached", never a number that looks real. On the maps, grey means not reached,
# hatched means lift-off.

# %%
t_ratios = np.linspace(0.05, 2.5, SIZE["n_tau_ratio"])
t_amps = np.linspace(0.02, 0.12, SIZE["n_tau_a"])
tau_map = lj.sweep({"omega_over_wn1": t_ratios, "a": t_amps}, z=Z, horizon=HORIZON, window=WINDOW, **OPTS)

fig, axes = plt.subplots(1, 2, figsize=(10, 4), layout="constrained", sharey=True)
for ax, name, label in (
    (axes[0], "tau_z", rf"$\tau_{{{Z:g}}}$ (time to travel z = {Z:g})"),
    (axes[1], "e_z", rf"$e_{{{Z:g}}}$ (energy dissipated meanwhile)"),
):
    values = tau_map[name].where(tau_map.reached)  # inf (not reached) -> NaN -> drawn grey
    finite = values.values[np.isfinite(values.values)]
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.8")
    norm = LogNorm(finite.min(), finite.max()) if finite.size and finite.min() < finite.max() else None
    m = ax.pcolormesh(t_amps, t_ratios, values, cmap=cmap, norm=norm, shading="nearest")
    hatch_liftoff(ax, t_amps, t_ratios, tau_map.liftoff.values)
    natural_frequencies(ax, [(1.0, r"$\omega_{n1}$"), (WN2 / WN1, r"$\omega_{n2,3}$")])
    fig.colorbar(m, ax=ax, label=label)
    ax.set_xlabel("amplitude $a$")
axes[0].set_ylabel(r"$\omega / \omega_{n1}$")
fig.suptitle(f"grey: z not reached within the horizon ({HORIZON:g} after t_start); hatched: lift-off", fontsize=9)
plt.show()
print(f"reached z in {int(tau_map.reached.sum())} of {tau_map.reached.size} configurations")

# %% [markdown]
# ## 3. Slicing along one parameter
#
# A slice of the map is one `.sel` away. Below, $\tau_z$ and $e_z$ against $\omega/\omega_{n1}$ at the
# amplitude nearest $a = 0.05$, first straight from the map, then from a finer one-dimensional sweep
# (one axis: the dataset has one dimension). The paper's Fig. 8 shows the same curves under its
# $n_i = |N_i|$ reading: fastest near $\omega_{n1}$, local minima near $\omega_{n2} = \omega_{n3}$, and
# sensitive minima in the SSL range $\omega/\omega_{n1} < 0.3$. With the strict reading, the band around
# $\omega_{n1}$ lifts off: the paper's fastest point lies where its own contact assumption fails.

# %%
coarse = tau_map.sel(a=0.05, method="nearest")
fine_ratios = np.linspace(0.05, 2.5, SIZE["n_slice"])
fine = lj.sweep(
    {"omega_over_wn1": fine_ratios}, fixed={"a": float(coarse.a)}, z=Z, horizon=HORIZON, window=WINDOW, **OPTS
)

fig, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True, layout="constrained")
for ax, name, label in ((axes[0], "tau_z", rf"$\tau_{{{Z:g}}}$"), (axes[1], "e_z", rf"$e_{{{Z:g}}}$")):
    ok = fine.reached & ~fine.liftoff
    ax.semilogy(fine_ratios, fine[name].where(ok), ".-", ms=3, label=f"fine sweep ({fine_ratios.size} frequencies)")
    ax.semilogy(coarse.omega_over_wn1, coarse[name].where(coarse.reached), "s", mfc="none", label="slice of the map")
    ssl = (fine.regime == lj.Regime.SSL).values
    ax.fill_between(
        fine_ratios, 0, 1, where=ssl, transform=ax.get_xaxis_transform(), color="#cfe3f7", lw=0, label="SSL"
    )
    ax.fill_between(
        fine_ratios,
        0,
        1,
        where=fine.liftoff.values,
        transform=ax.get_xaxis_transform(),
        facecolor="none",
        edgecolor="0.5",
        hatch="///",
        lw=0,
        label="lift-off",
    )
    for r in (WN2 / WN1, 1.0):
        ax.axvline(r, color="k", ls=":", lw=1)
    ax.set_ylabel(label)
axes[0].legend(fontsize=7)
axes[1].set_xlabel(r"$\omega / \omega_{n1}$  (dotted: $\omega_{n2,3}$ and $\omega_{n1}$)")
axes[0].set_title(f"a = {float(coarse.a):.3g}; gaps: z not reached within the horizon or lift-off", fontsize=9)
plt.show()

ok = (fine.reached & ~fine.liftoff).values
if ok.any():
    best = fine.tau_z.where(fine.reached & ~fine.liftoff).idxmin()
    print(f"fastest: omega/wn1 = {float(best):.3g}, tau = {float(fine.tau_z.sel(omega_over_wn1=best)):.4g}")
else:
    print("z was not reached without lift-off anywhere on this slice")

# %% [markdown]
# ## 4. Where the natural frequencies fall: the $(\hat m, \omega)$ map
#
# The natural frequencies depend on the mass ratio $\hat m = m_1/(m_1 + m_2)$ (eqs. 11-12):
# $\omega_{n1} = \sqrt{k(m_1+m_2)/(m_1 m_2)}$, $\omega_{n2} = \sqrt{k/m_1}$, $\omega_{n3} = \sqrt{k/m_2}$,
# with $m_1 = 2\hat m$, $m_2 = 2(1-\hat m)$. Drawn over the regime and the mean speed on the
# $(\hat m, \omega)$ plane, they show which resonance shapes which part of the map (the paper's Fig. 12).

# %%
mhats = np.linspace(0.05, 0.95, SIZE["n_mhat"])
omegas = np.linspace(0.5, 25.0, SIZE["n_mhat_omega"])
mass_map = lj.sweep({"mhat": mhats, "omega": omegas}, horizon=WINDOW, window=WINDOW, **OPTS)

curve = np.linspace(0.05, 0.95, 200)
pc = lj.Params(mhat=curve)
wn = {r"$\omega_{n1}$": pc.wn1, r"$\omega_{n2} = \sqrt{k/m_1}$": pc.wn2, r"$\omega_{n3} = \sqrt{k/m_2}$": pc.wn3}

fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained", sharey=True)
cls = classes(mass_map)
axes[0].pcolormesh(
    mhats, omegas, cls.T, cmap=ListedColormap(CLASS_COLORS), norm=BoundaryNorm(np.arange(-0.5, 4), 4), shading="nearest"
)
speed = mass_map.mean_speed.where(~mass_map.liftoff).T
lim = float(np.nanmax(np.abs(speed.values))) if np.isfinite(speed.values).any() else 1.0
m = axes[1].pcolormesh(
    mhats, omegas, speed, cmap=plt.get_cmap("RdBu_r").with_extremes(bad="0.8"), vmin=-lim, vmax=lim, shading="nearest"
)
fig.colorbar(m, ax=axes[1], label="mean speed over the window (grey: lift-off)")
for ax in axes:
    hatch_liftoff(ax, mhats, omegas, mass_map.liftoff.values.T)
    for (label, w), style in zip(wn.items(), ("-", "--", "-.")):
        ax.plot(curve, w, color="k", ls=style, lw=1.2, label=label)
    ax.set_ylim(omegas[0], omegas[-1])
    ax.set_xlabel(r"mass ratio $\hat m$")
axes[0].set_ylabel(r"$\omega$")
fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=3, fontsize=8, frameon=False)
axes[0].set_title("regime (colours as above)", fontsize=9)
axes[1].set_title("signed mean speed of the centre of mass", fontsize=9)
plt.show()

# %% [markdown]
# **Next:** `03_optimal_actuation` asks which periodic waveform $\ell_0(t)$, not only which sinusoid,
# reaches a required speed for the least energy. For the paper's figures at full size, see
# `experiments/` (`locomotion-jax figures`). Sweeps can also be written to NetCDF and resumed
# (`lj.sweep(..., path="maps/ssl.nc")`, or `locomotion-jax sweep ... --out maps/ssl.nc`).
