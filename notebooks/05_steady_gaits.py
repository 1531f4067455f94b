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
# # 05 · Steady gaits: periodic orbits, their stability, and where stick-slip turns into slip
#
# This notebook answers: **what is the steady gait of a configuration, is it stable, and at which
# parameter value exactly does stick-slip locomotion (SSL) become slip locomotion (SL)?**
#
# A steady gait is a periodic orbit: after one actuation period the gap `u = x2 - x1` and both
# velocities repeat, while the robot has moved on. `lj.steady_gait` solves it by Newton's method on
# that period map, and its Floquet multipliers (the eigenvalues of the period map's Jacobian) say
# whether nearby motions settle on it. `lj.continuation` follows a gait as one parameter varies
# and locates the changes along the way (README, "Steady gaits").

# %%
import os

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import locomotion_jax as lj
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display, HTML


# CI runs every notebook top to bottom at a small size (tests/test_notebooks.py sets LOCOMOTION_NB_SMALL=1).
SMALL = os.environ.get("LOCOMOTION_NB_SMALL") == "1"
POINTS = 12 if SMALL else 200

# %% [markdown]
# ## Two steady gaits
#
# At `omega = 2` (0.2 wn1, the paper's Fig. 5a) the masses stick for part of each period; at
# `omega = 16` they slip all the time. Mean speed and cost of transport are exact averages over
# one period of the orbit.

# %%
g = lj.steady_gait(lj.Params(omega=jnp.array([2.0, 16.0])))
rows = "".join(
    f"<tr><td>{w:g}</td><td>{lj.Regime(int(r)).name}</td><td>{v:.6f}</td><td>{c:.4f}</td>"
    f"<td>{np.max(np.abs(m)):.4f}</td><td>{bool(s)}</td></tr>"
    for w, r, v, c, m, s in zip(
        [2.0, 16.0], np.asarray(g.regime), np.asarray(g.mean_speed), np.asarray(g.cost_of_transport),
        np.asarray(g.multipliers), np.asarray(g.stable),
    )
)  # fmt: skip
display(HTML("<table><tr><th>omega</th><th>regime</th><th>mean speed</th><th>cost of transport</th>"
             f"<th>largest |multiplier|</th><th>stable</th></tr>{rows}</table>"))  # fmt: skip

# %% [markdown]
# ## Where does stick-slip end? Continuation along the amplitude
#
# At `omega = 6` small amplitudes give stick-slip and large ones slip. Continuing the gait along `a`
# from 0.05 down to 0.02, and from 0.02 up to 0.05 (two branches, one batch), each branch finds the
# boundary as the zero of the gait's slip margin: the smallest `|F_i| - mu_s n_i` at the instants
# where a slipping mass comes to rest (negative: it sticks there).

# %%
b = lj.continuation(lj.Params(omega=6.0, a=jnp.array([0.05, 0.02])), "a", jnp.array([0.02, 0.05]),
                    max_points=POINTS)  # fmt: skip
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6), layout="constrained")
for i in range(2):
    n = int(b.n_points[i])
    lam, speed, margin = (np.asarray(x[i, :n]) for x in (b.lam, b.mean_speed, b.slip_margin))
    ssl = np.asarray(b.regime[i, :n]) == lj.Regime.SSL
    ax[0].plot(lam[ssl], speed[ssl], "o", color="C0", ms=3, label="SSL" if i == 0 else None)
    ax[0].plot(lam[~ssl], speed[~ssl], "o", color="C1", ms=3, label="SL" if i == 0 else None)
    ax[1].plot(lam, margin, ".-", color=f"C{i + 2}", ms=3, label=f"from a = {float(lam[0]):g}")
ssl_sl = np.asarray(b.events.kind) == lj.EventKind.SSL_SL
a_star = np.asarray(b.events.lam)[ssl_sl]
for axis in ax:
    for x in a_star:
        axis.axvline(x, color="k", lw=0.8, ls=":")
ax[0].set(xlabel="amplitude a", ylabel="mean speed", title="steady gait along a (omega = 6)")
ax[1].axhline(0, color="0.5", lw=0.8)
ax[1].set(xlabel="amplitude a", ylabel="slip margin", title="its zero: the SSL/SL boundary")
ax[0].legend()
ax[1].legend()
plt.show()
print("SSL/SL boundary located from each side:", [f"{x:.12f}" for x in a_star])

# %% [markdown]
# Both branches locate the same amplitude, to far below the tolerance of `1e-10` asked of the
# root solve. The independent reference solver in `tests/reference.py` sticks on the orbit just below
# it and not on the orbit just above (`tests/test_continuation.py`).
#
# ## Coexisting gaits
#
# With the paper's defaults, near `omega = 4.9` a stick-slip gait and a slip gait are both
# stable. Which one the robot settles on depends on how it starts: `lj.basins` labels each
# start (gap and velocities at phase 0) with the gait it reaches.

# %%
starts = np.array([[2.90, 0.08, -0.08], [2.98, 0.08, -0.08]])
basin = lj.basins(lj.Params(omega=4.9), starts)
for start, label in zip(starts, np.asarray(basin.label)):
    gait = basin.gaits
    print(f"start u = {start[0]:.2f}: {lj.Regime(int(gait.regime[label])).name} gait, "
          f"mean speed {float(gait.mean_speed[label]):.6f}")  # fmt: skip
