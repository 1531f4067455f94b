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
# # 01 · A tour of the model: how do two masses and a spring crawl?
#
# This notebook answers: **what does the two-mass model of Zhou, Majidi & O'Reilly (2014)
# do, and what do stick-slip locomotion (SSL) and slip locomotion (SL) look like?**
#
# Two masses $m_1 = 2\hat m$ and $m_2 = 2(1-\hat m)$ sit on a rough line, joined by a
# spring whose ends are at different heights (vertical offset $d$). An actuator changes the
# spring's rest length, $\ell_0(t) = a\sin(\omega t) + \bar\ell$ (eq. 13). Because the spring is
# tilted, its tension also pushes one mass into the ground and lifts the other (eq. 5):
#
# $$\ell = \sqrt{(x_2-x_1)^2 + d^2},\qquad T = k(\ell - \ell_0(t)),\qquad
# f_x = T\,\frac{x_2 - x_1}{\ell},\qquad N_1 = m_1 - T\frac{d}{\ell},\quad N_2 = m_2 + T\frac{d}{\ell}.$$
#
# With $d > 0$, a stretched spring grips $m_2$ harder than $m_1$, a compressed one the other way
# round, so Coulomb friction (static $\mu_s$, kinetic $\mu_k$) holds the masses unevenly and the pair
# crawls forward. Each mass either **sticks** ($v_i = 0$, allowed while $|F_i| \le \mu_s N_i$, eq. 7)
# or **slips** (kinetic friction $\mu_k N_i$ against its velocity, eq. 9), which gives four modes:
#
# | mode | `lj.Mode` | mass 1 | mass 2 |
# |---|---|---|---|
# | 0 | `BOTH_STICK` | stuck | stuck |
# | 1 | `BOTH_SLIP` | slips | slips |
# | 2 | `M1_SLIPS` | slips | stuck |
# | 3 | `M2_SLIPS` | stuck | slips |
#
# The exact engine locates every switch between modes in time (not on a grid). The paper's
# defaults are $k = 50$, $c = 0.01$, $d = 0.5$, $\bar\ell = 3$, $a = 0.05$, $\mu_s = 0.7$, $\mu_k = 0.5$,
# $\hat m = 0.5$. See `../../shared/SPEC.md` (the model with the paper's typos corrected) and the README.

# %%
import os

import jax


jax.config.update("jax_enable_x64", True)

import locomotion_jax as lj
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display, HTML


try:  # the sliders of the last section; `pip install -e ".[notebooks]"` installs them
    import ipywidgets as widgets
except ModuleNotFoundError:
    widgets = None

# CI runs every notebook top to bottom at a small size (tests/test_notebooks.py sets LOCOMOTION_NB_SMALL=1).
SMALL = os.environ.get("LOCOMOTION_NB_SMALL") == "1"
FRAMES = 16 if SMALL else 90  # frames of the inline animations
N_SAVE = 601  # saved states per simulation: one size for every call, so `simulate` compiles once
IMAGES = os.environ.get("LOCOMOTION_NB_IMAGES")  # set to a directory to save this notebook's picture there

# %% [markdown]
# ## Parameters and natural frequencies
#
# `lj.Params` holds the dimensionless parameters (paper defaults unless given). Its natural
# frequencies (eqs. 11-12) mark where the behaviour changes: $\omega_{n1}$ when both masses slip,
# $\omega_{n2} = \sqrt{k/m_1}$ when $m_2$ is stuck and $\omega_{n3} = \sqrt{k/m_2}$ when $m_1$ is stuck.

# %%
base = lj.Params()
print(f"wn1 = {float(base.wn1):.4g}, wn2 = {float(base.wn2):.4g}, wn3 = {float(base.wn3):.4g}")
print(f"the paper's measurements start at t_start = 80 periods of the slowest one = {float(base.t_start):.4g}")

ssl = lj.Params(omega=0.2 * float(base.wn1))  # omega = 2: the paper's stick-slip example (Fig. 5a)
sl = lj.Params(omega=2.3 * float(base.wn1))  # omega = 23: the paper's slip example (Fig. 5b)

# %% [markdown]
# ## Simulate one SSL and one SL case
#
# `lj.simulate(params, t_end, save_at)` integrates from the paper's start (eq. 14, $x_1 = 0$,
# $x_2 = \bar\ell$, at rest) and returns a `Trajectory` with `t, x1, v1, x2, v2, X` (centre of mass,
# eq. 4), `mode`, `e_d` (dissipated energy, eq. 15), the normal forces `N1, N2`, and the run's
# `status` (`lj.Status`: `OK`, or `LIFTOFF` if a normal force reached zero and the model stopped applying).
#
# First the whole run: both crawl forward; the centre of mass $X$ grows about linearly after a short transient.

# %%
T_END = 40.0
full = {
    name: lj.simulate(p, T_END, save_at=np.linspace(0.0, T_END, N_SAVE))
    for name, p in (("SSL, omega = 0.2 wn1", ssl), ("SL, omega = 2.3 wn1", sl))
}
fig, ax = plt.subplots(figsize=(7, 2.6), layout="constrained")
for name, tr in full.items():
    ax.plot(tr.t, tr.X, label=f"{name}: status {lj.Status(int(tr.status)).name}")
ax.set_xlabel("t")
ax.set_ylabel("centre of mass X")
ax.legend()
plt.show()


# %% [markdown]
# Now a closer look at the steady state: two actuation periods for SSL and four for SL (at
# $\omega = 23$ a period lasts only 0.27). Stuck intervals are drawn thick and red. In SSL each mass in
# turn stands still while the other one slides; in SL both always slip, and the masses slide back and
# forth with a small net advance per period.


# %%
def stuck_masks(mode):
    """(stuck1, stuck2) from the mode codes of the table above."""
    mode = np.asarray(mode)
    return np.isin(mode, [lj.Mode.BOTH_STICK, lj.Mode.M2_SLIPS]), np.isin(mode, [lj.Mode.BOTH_STICK, lj.Mode.M1_SLIPS])


def window(p, periods, t_end=T_END):
    """The last `periods` actuation periods before `t_end`, saved at N_SAVE times."""
    t0 = t_end - periods * 2 * np.pi / float(p.omega)
    return lj.simulate(p, t_end, save_at=np.linspace(t0, t_end, N_SAVE))


def plot_case(axes, tr, title):
    """Positions (stuck intervals in red), velocities and mode against time in a column of 3 axes."""
    t = np.asarray(tr.t)
    stuck = stuck_masks(tr.mode)
    for x, s, k in ((tr.x1, stuck[0], 1), (tr.x2, stuck[1], 2)):
        rel = np.asarray(x) - float(x[0])
        axes[0].plot(t, rel, color=f"C{k - 1}", label=f"$x_{k} - x_{k}(t_0)$")
        axes[0].plot(t, np.where(s, rel, np.nan), color="#d62728", lw=3, solid_capstyle="butt")
    axes[0].plot([], [], color="#d62728", lw=3, label="stuck")
    axes[1].plot(t, tr.v1, label="$v_1$")
    axes[1].plot(t, tr.v2, label="$v_2$")
    axes[1].axhline(0, color="0.6", lw=0.6)
    axes[2].step(t, tr.mode, where="post", color="k")
    axes[2].set_yticks([0, 1, 2, 3], ["both stick", "both slip", "m1 slips", "m2 slips"], fontsize=8)
    axes[2].set_ylim(-0.4, 3.4)
    axes[0].set_title(title, fontsize=10)
    axes[0].set_ylabel("displacement")
    axes[1].set_ylabel("velocity")
    axes[2].set_xlabel("t")
    for a in axes[:2]:
        a.legend(fontsize=7, loc="upper left", ncols=3)


zoom_ssl, zoom_sl = window(ssl, 2), window(sl, 4)
fig, axes = plt.subplots(3, 2, figsize=(10, 6.4), sharex="col", layout="constrained")
plot_case(axes[:, 0], zoom_ssl, "SSL: omega = 0.2 wn1 = 2 (stick-slip)")
plot_case(axes[:, 1], zoom_sl, "SL: omega = 2.3 wn1 = 23 (slip)")
if IMAGES:
    fig.savefig(os.path.join(IMAGES, "01_model_tour.png"), dpi=64)
plt.show()

for name, tr in (("SSL", zoom_ssl), ("SL", zoom_sl)):
    s1, s2 = stuck_masks(tr.mode)
    speed = (float(tr.X[-1]) - float(tr.X[0])) / (float(tr.t[-1]) - float(tr.t[0]))
    print(f"{name}: m1 stuck {s1.mean():5.1%} of the time, m2 stuck {s2.mean():5.1%}, mean speed {speed:.4f}")

# %% [markdown]
# ### Why it crawls: the normal forces
#
# The tilt makes the normal forces (eq. 5) oscillate in opposite phase. A mass can only stay stuck
# while the horizontal spring force stays below its static limit $\mu_s N_i$; the lightly loaded mass
# breaks free first, and the heavily loaded one holds. Below, the SSL case: each mass sticks while
# $|f_x|$ (black) is under its limit.

# %%
p = ssl
l = np.hypot(np.asarray(zoom_ssl.x2 - zoom_ssl.x1), float(p.d))
tension = float(p.k) * (l - np.asarray(zoom_ssl.l0))
fx_spring = tension * np.asarray(zoom_ssl.x2 - zoom_ssl.x1) / l  # horizontal spring force on m1, eq. (8)
fig, ax = plt.subplots(figsize=(7, 2.8), layout="constrained")
t = np.asarray(zoom_ssl.t)
ax.plot(t, np.abs(fx_spring), color="k", label="$|f_x|$ (spring, horizontal)")
ax.plot(t, float(p.mu_s) * np.asarray(zoom_ssl.N1), color="C0", label="$\\mu_s N_1$ (limit of mass 1)")
ax.plot(t, float(p.mu_s) * np.asarray(zoom_ssl.N2), color="C1", label="$\\mu_s N_2$ (limit of mass 2)")
s1, s2 = stuck_masks(zoom_ssl.mode)
ax.fill_between(
    t, 0, 1, where=s1, transform=ax.get_xaxis_transform(), color="C0", alpha=0.15, lw=0, label="mass 1 stuck"
)
ax.fill_between(
    t, 0, 1, where=s2, transform=ax.get_xaxis_transform(), color="C1", alpha=0.15, lw=0, label="mass 2 stuck"
)
ax.set_xlabel("t")
ax.set_ylabel("force")
ax.legend(fontsize=7, ncols=2, loc="upper left")
ax.set_ylim(0, None)
plt.show()

# %% [markdown]
# ## The animation
#
# `lj.animate(trajectory, params)` draws the masses and the tilted spring to scale, one frame per
# saved state: a **stuck mass is red with an anchor under it**, a slipping one blue. The panel below
# the scene shows the displacements since the first frame with the stuck intervals in red, so the
# staircase of stick-slip motion is visible even though each step (a few hundredths) is small
# against the spring (length 3). `anim.to_jshtml()` renders it inline; `lj.save_gif(anim, "ssl.gif")`
# or the command line (`locomotion-jax animate --omega 2 --out ssl.gif`) writes a GIF.

# %%
anim = lj.animate(
    zoom_ssl, ssl, max_frames=FRAMES, interval=80, title="SSL, omega = 0.2 wn1: red = stuck (anchored), blue = slipping"
)
HTML(anim.to_jshtml(default_mode="loop"))

# %% [markdown]
# The SL case for contrast: no mass ever turns red.

# %%
anim_sl = lj.animate(zoom_sl, sl, max_frames=FRAMES, interval=80, title="SL, omega = 2.3 wn1: both always slip")
HTML(anim_sl.to_jshtml(default_mode="loop"))

# %% [markdown]
# ## Explore: move the sliders
#
# With a live kernel the sliders below re-simulate (a fraction of a second once compiled: the
# parameters are traced arrays, so new values do not recompile) and redraw the last two periods.
# Things to try: $d = 0$ (the symmetric spring does not crawl), $d < 0$ (it crawls backwards),
# $\hat m$ away from 0.5, or a large $a$ at high $\omega$ (a normal force reaches zero: **lift-off**,
# where the model does not apply, and the simulation stops there). Without a front end (CI, a
# static viewer) the panel runs once with the defaults; without `ipywidgets` installed there is no
# panel, and `explore` runs once with the defaults (call it with other values in a new cell).

# %%
T_EXPLORE = 30.0


def explore(omega=2.0, a=0.05, d=0.5, mhat=0.5):
    p = lj.Params(omega=omega, a=a, d=d, mhat=mhat)
    periods = max(2, int(np.ceil(2 * float(p.omega) / 2.0)))  # at least ~6 time units
    tr = window(p, periods, T_EXPLORE)
    fig, axes = plt.subplots(3, 1, figsize=(7, 5.2), sharex=True, layout="constrained")
    status = lj.Status(int(tr.status))
    note = f", LIFT-OFF at t = {float(tr.t_liftoff):.3g}" if bool(tr.liftoff) else ""
    plot_case(
        axes,
        tr,
        f"omega = {omega:.3g} ({omega / float(p.wn1):.2f} wn1), a = {a:.3g}, d = {d:.2g}, "
        f"mhat = {mhat:.2g}: {status.name}{note}",
    )
    plt.show()
    return tr


if widgets is None:
    print('No sliders: ipywidgets is not installed (pip install -e ".[notebooks]").')
    result = explore()
else:
    slider = dict(continuous_update=False, readout_format=".3g")
    panel = widgets.interactive(
        explore,
        omega=widgets.FloatSlider(value=2.0, min=0.5, max=30.0, step=0.1, description="omega", **slider),
        a=widgets.FloatSlider(value=0.05, min=0.0, max=0.15, step=0.005, description="a", **slider),
        d=widgets.FloatSlider(value=0.5, min=-1.0, max=1.0, step=0.05, description="d", **slider),
        mhat=widgets.FloatSlider(value=0.5, min=0.05, max=0.95, step=0.01, description="mhat", **slider),
    )
    display(panel)
    result = panel.result

# %%
# `interactive` ran `explore` once with the defaults. A widget callback only prints its errors,
# so check here that it returned a trajectory (this makes a broken panel fail CI).
assert isinstance(result, lj.Trajectory), "explore() failed: see the traceback in the panel above"
print("explore ready:", lj.Status(int(result.status)).name)

# %% [markdown]
# **Next:** `02_parameter_maps` maps the SSL and SL regions and the travel time over
# $(\omega, a)$ with the sweep engine; `03_optimal_actuation` asks which waveform $\ell_0(t)$ moves
# the robot at a required speed for the least energy.
