"""A capsule (vibration-driven) robot mapped over the frequency and amplitude of its internal force, and
a published capsule result checked against its closed form.

**The map.** A body (mass M, friction on the ground) carries an internal mass m on a spring k; an internal
force F0 sin(omega t) acts between them (SPEC §9, `lj.Mechanism`). Every (omega, F0) of a grid is one
configuration of a batched `lj.Mechanism`, mapped by `lj.sweep(axes, mechanism=...)` (chunks of one
compiled shape, no Python loop over configurations): the mean speed, the cost of transport (dissipated
energy per distance) and the regime: forward, backward, stuck (the body never slips after the
transient) or rocking (it slips but goes nowhere, |speed| < 1e-3). Two grounds: isotropic Coulomb
friction, and anisotropic (easier backward), the friction of `examples/capsule.toml`.

**The published result** (`experiments/REPRODUCTION.md`): a body with an internal mass whose motion
relative to the body is prescribed, s(t) = b sin(omega t), on non-symmetric Coulomb friction f+ (forward),
f- (backward). Fang and Xu (Multibody Syst. Dyn. 27 (2012) 455-485) state that a module stays at rest
while the internal mass's inertial force stays below the friction at rest, (M + m) f+ g forward and
(M + m) f- g backward. With P = m b omega^2 / ((M + m) g) and f+ < f-, this gives three regimes: at rest
(P <= f+), forward slips only (f+ < P <= f-), slips both ways (P > f-). In the middle band the motion of
each period has a closed form (derived in REPRODUCTION.md), which the engine is compared with.

**The cheapest force waveform at one speed**: `lj.optimise` of the capsule on isotropic ground over
internal forces of three harmonics under a force bound (`optimal_force`), checked by a direct simulation,
against a batched sweep of sinusoids and against the floor of the cost of transport.

Writes `capsule.png`, `capsule_fang_xu.png`, `capsule_waveform.png` and `capsule.json` to the output folder.

Usage: python experiments/capsule.py [--quick] [--out DIR]
"""

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any, cast

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

import jax.numpy as jnp
import locomotion_jax as lj
import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Rectangle
from scipy.optimize import brentq


M, m, K = 1.0, 0.5, 10.0
GROUNDS = {
    "isotropic Coulomb(0.5, 0.4)": lj.Coulomb(0.5, 0.4),
    "anisotropic (0.5, 0.2, 0.4, 0.15)": lj.AnisotropicCoulomb(0.5, 0.2, 0.4, 0.15),
}
SETTLE, HORIZON = 60.0, 20 * math.pi  # transient and averaging time
"""The averaging time is a whole number of periods for every omega on the grid (multiples of 0.1), so the
internal mass's oscillation adds nothing to the mean speed of the centre of mass."""
MOVING = 1e-3
REGIMES = ("stuck", "rocking", "forward", "backward")


def capsule_batch(omega: np.ndarray, f0: np.ndarray, friction: lj.AbstractFriction) -> lj.Mechanism:
    """One capsule per (omega, f0) pair (flat arrays of equal length), as one batched Mechanism."""
    wave = lj.Sinusoid(a=jnp.asarray(f0), omega=jnp.asarray(omega), lbar=0.0)
    return lj.Mechanism(masses=[M, m], friction=[friction, None], carried_by=[None, 0],
                        links=[lj.Spring(0, 1, k=K, rest=0.0), lj.Force(0, 1, wave)])  # fmt: skip


def capsule_map(n_omega: int, n_force: int) -> dict:
    step = round(8.5 / (n_omega - 1), 1)
    omegas = 0.5 + step * np.arange(n_omega)  # multiples of 0.1: HORIZON holds whole periods of each
    forces = np.linspace(0.05, 3.0, n_force)
    W, F = (q.ravel() for q in np.meshgrid(omegas, forces, indexing="ij"))
    out: dict = {"omega": omegas.tolist(), "F0": forces.tolist(), "M": M, "m": m, "k": K,
                 "settle": SETTLE, "horizon": HORIZON, "grounds": {}}  # fmt: skip
    for name, law in GROUNDS.items():
        t0 = time.perf_counter()
        build = lambda omega, F0, law=law: capsule_batch(omega, F0, law)
        res = lj.sweep({"omega": omegas, "F0": forces}, mechanism=build, z=1e6, horizon=HORIZON, window=HORIZON,
                       t_start=SETTLE, progress=False)  # fmt: skip
        wall = time.perf_counter() - t0
        flat = lambda name: np.asarray(res[name]).reshape(W.size, *np.shape(res[name])[2:])
        ok = flat("status") == lj.Status.OK
        speed = np.where(ok, flat("mean_speed"), np.nan)
        ed = flat("e_d")
        stuck = flat("stick_fraction")[:, 0] >= 1.0
        moving = ok & (np.abs(speed) > MOVING)
        cot = np.where(moving, ed / np.where(moving, np.abs(speed) * HORIZON, 1.0), np.nan)
        regime = np.where(stuck, 0, np.where(~moving, 1, np.where(speed > 0, 2, 3)))
        shape = (n_omega, n_force)
        out["grounds"][name] = {
            "mean_speed": speed.reshape(shape).tolist(), "cost_of_transport": cot.reshape(shape).tolist(),
            "regime": regime.reshape(shape).tolist(), "ok": bool(ok.all()), "wall_s": wall,
            "balance_max": float(np.nanmax(np.abs(flat("balance")))),
        }  # fmt: skip
        counts = {r: int((regime == j).sum()) for j, r in enumerate(REGIMES)}
        best, worst = int(np.nanargmax(speed)), int(np.nanargmin(speed))
        print(f"{name}: {W.size} capsules in {wall:.1f} s, all OK: {bool(ok.all())}; regimes {counts}; "
              f"fastest forward {speed[best]:.4g} at omega={W[best]:.3g}, F0={F[best]:.3g} (cost of transport "
              f"{cot[best]:.3g}); fastest backward {speed[worst]:.4g} at omega={W[worst]:.3g}, "
              f"F0={F[worst]:.3g}")  # fmt: skip
    return out


# -- the cheapest force waveform at one speed: lj.optimise ------------------------------------------------------

OPT: dict[str, Any] = dict(omega=3.0, f_max=2.0, harmonics=3, v_min=0.05, friction="isotropic Coulomb(0.5, 0.4)")
"""The requirement: forward at `v_min` or faster with max_t |f(t)| <= `f_max` (the force bound, `a_max`), on
isotropic ground, at a fixed omega."""


def _force_capsules(cos: np.ndarray, sin: np.ndarray, omega: float) -> lj.Mechanism:
    wave = lj.Fourier(jnp.asarray(cos), jnp.asarray(sin), omega, 0.0)
    return lj.Mechanism(masses=[M, m], friction=[GROUNDS[OPT["friction"]], None], carried_by=[None, 0],
                        links=[lj.Spring(0, 1, k=K, rest=0.0), lj.Force(0, 1, wave)])  # fmt: skip


def _speed_cost(cos: np.ndarray, sin: np.ndarray, settle: int = 20, periods: int = 10) -> tuple[np.ndarray, ...]:
    """Mean speed and cost of transport of a batch of force waveforms (rows) by a direct simulation
    (`lj.measure`, one batched call), over whole periods after `settle` periods from rest; and the energy
    dissipated per the body's own displacement in units of mu_k (M + m) g (`lj.simulate`: the centre of
    mass also carries the internal mass's free oscillation, which whole forcing periods need not cancel)."""
    T = 2 * math.pi / OPT["omega"]
    capsules = _force_capsules(cos, sin, OPT["omega"])
    res = lj.measure(capsules, z=1e6, horizon=periods * T, window=periods * T, t_start=settle * T)
    v, ed = np.asarray(res.mean_speed), np.asarray(res.e_d)
    ok = np.asarray(res.status) == lj.Status.OK
    cost = np.where(ok & (v > 0), ed / np.where(v > 0, v * periods * T, 1.0), np.inf)
    traj = lj.simulate(capsules, t_end=(settle + periods) * T, save_at=jnp.array([settle, settle + periods]) * T)
    body = np.abs(np.diff(np.asarray(traj.x)[..., 0], axis=-1)[..., 0])
    e_body = np.diff(np.asarray(traj.e_d), axis=-1)[..., 0]
    law = cast(lj.Coulomb, GROUNDS[OPT["friction"]])
    per_floor = np.where(body > 1e-9, e_body / np.where(body > 1e-9, float(law.mu_k) * (M + m) * body, 1.0), np.nan)
    return np.where(ok, v, np.nan), cost, per_floor


def _peak(cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    th = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    n = np.arange(1, cos.shape[-1] + 1)
    return np.abs(np.cos(np.outer(th, n)) @ cos.T + np.sin(np.outer(th, n)) @ sin.T).max(0)


def optimal_force(quick: bool) -> dict:
    """The cheapest internal force of `harmonics` harmonics of omega under the force bound that drives the
    capsule forward at v_min or faster: `lj.optimise` of the capsule (its steady gaits, exact gradients),
    checked by a direct simulation from rest (`lj.measure`, 100 periods of transient, 40 averaged), against
    a batched sweep of sinusoids A sin(omega t + phi) under the same bound, and against the floor of the
    cost of transport, mu_k (M + m) g (a body that never slides backward; backward slides cost more)."""
    H, f_max, v_min, omega = OPT["harmonics"], OPT["f_max"], OPT["v_min"], OPT["omega"]
    t0 = time.perf_counter()
    capsule = _force_capsules(np.zeros(1), np.zeros(1), omega)
    settings = lj.MechanismOptimiseSettings(
        amplitudes=4 if quick else 8, phases=4 if quick else 8, local=2 if quick else 4, max_iter=30 if quick else 40
    )
    opt = lj.optimise(capsule, v_min=v_min, a_max=f_max, omega=omega, harmonics=H, settings=settings)
    wall = time.perf_counter() - t0
    c, s = np.asarray(opt.cos)[0], np.asarray(opt.sin)[0]
    v_check, cost_check, _ = _speed_cost(c[None], s[None], settle=100, periods=40)
    # The baseline: sinusoids f_max u sin(omega t + phi), u in (0, 1], phi over a period (the phase sets where
    # the force starts, and on isotropic ground the start can pick the direction).
    U, PHI = (
        q.ravel() for q in np.meshgrid(np.linspace(0.02, 1.0, 50), np.linspace(0, 2 * math.pi, 24, endpoint=False))
    )
    c1, s1 = np.zeros((U.size, H)), np.zeros((U.size, H))
    c1[:, 0], s1[:, 0] = f_max * U * np.sin(PHI), f_max * U * np.cos(PHI)
    sv, scost, sfloor = _speed_cost(c1, s1)
    fast = int(np.nanargmax(sv))
    feasible = sv >= v_min
    cheapest = int(np.argmin(np.where(feasible, scost, np.inf)))
    law = cast(lj.Coulomb, GROUNDS[OPT["friction"]])
    floor = float(law.mu_k) * (M + m)
    moving = sv > MOVING  # forward faster than the map's threshold (a stuck capsule creeps at round-off)
    out = {**OPT, "optimise_wall_s": wall, "runtime_s": opt.runtime_s, "screened": opt.screened,
           "evaluations": opt.evaluations, "feasible": opt.feasible_exact, "stable": opt.stable_exact,
           "cos": c.tolist(), "sin": s.tolist(), "peak": float(_peak(c[None], s[None])[0]),
           "stroke_exact": float(np.max(opt.stroke_exact)), "mean_speed": opt.mean_speed_exact,
           "cost_of_transport": opt.cost_of_transport_exact, "spectral_radius": opt.spectral_radius_exact,
           "simulation_agreement": opt.simulation_agreement, "screen_sinusoid": opt.sinusoid,
           "mean_speed_check": float(v_check[0]), "cost_check": float(cost_check[0]), "cost_floor": floor,
           "sinusoid_fastest": float(sv[fast]), "sinusoid_fastest_amplitude": float(f_max * U[fast]),
           "sinusoid_fastest_phase": float(PHI[fast]), "sinusoid_feasible": int(feasible.sum()),
           "sinusoid_count": int(U.size), "sinusoid_moving": int(moving.sum()),
           "sinusoid_min_cost_moving": float(scost[moving].min()) if moving.any() else None,
           "sinusoid_min_dissipation_per_body_distance": float(np.nanmin(sfloor)),
           "sinusoid_cheapest_cost": float(scost[cheapest]) if feasible.any() else None,
           "sinusoid_cheapest_speed": float(sv[cheapest]) if feasible.any() else None}  # fmt: skip
    print(f"lj.optimise ({OPT['friction']}, omega={omega}, |f| <= {f_max}, v >= {v_min}, {H} harmonics): "
          f"{wall:.0f} s, {opt.screened} sinusoids screened, {opt.evaluations} orbit evaluations; optimum: "
          f"feasible {opt.feasible_exact}, speed {opt.mean_speed_exact:.6g}, cost of transport "
          f"{opt.cost_of_transport_exact:.10g} (floor mu_k (M + m) g = {floor:.6g}), peak force {out['peak']:.4g}, "
          f"cos {np.round(c, 4).tolist()}, sin {np.round(s, 4).tolist()}; direct simulation from rest "
          f"(lj.measure, 100 periods + 40): speed {v_check[0]:.6g}, cost {cost_check[0]:.10g}; sinusoids "
          f"A sin(omega t + phi) under the bound: the fastest {sv[fast]:.3g} (A {f_max * U[fast]:.3g}, "
          f"phi {PHI[fast]:.3g}), {out['sinusoid_feasible']} of {U.size} meet v_min, {int(moving.sum())} move forward "
          f"(> {MOVING}), the cheapest of those costs {out['sinusoid_min_cost_moving']}; every sinusoid dissipates "
          f"at least {np.nanmin(sfloor):.10g} times the floor per distance its body slides")  # fmt: skip
    return out


# -- the published result: prescribed harmonic internal motion on non-symmetric Coulomb friction ---------------

FANG_XU = dict(M=1.0, m=0.5, f_fwd=0.2, f_bwd=0.4, omega=2.0)
"""The check's parameters (g = 1): our choice, inside the model of Fang and Xu (2012)."""


def one_period(P: float, f_fwd: float) -> tuple[float, float]:
    """Closed form of the forward-only band f+ < P <= f- (REPRODUCTION.md): the displacement per period in
    units of g / omega^2 and the fraction of the period spent stuck; `(0, 1)` at rest (P <= f+)."""
    if P <= f_fwd:
        return 0.0, 1.0
    t1 = math.asin(f_fwd / P)  # the phase at which the body starts to slip
    h = lambda t: P * (math.cos(t1) - math.cos(t)) - f_fwd * (t - t1)  # omega v / g while it slips
    grid = np.linspace(t1 + 1e-9, t1 + 2 * math.pi, 4001)
    j = int(np.flatnonzero(np.array([h(t) for t in grid[1:]]) < 0)[0])
    t2 = cast(float, brentq(h, grid[j], grid[j + 1], xtol=1e-15))  # the phase at which it stops
    L = t2 - t1
    return P * (L * math.cos(t1) - (math.sin(t2) - math.sin(t1))) - f_fwd * L * L / 2, 1 - L / (2 * math.pi)


def reproduction(n: int) -> dict:
    """Mean speed and stuck fraction against P from the engine and the closed form, and the backward-slip
    boundary P = f- from the simulated velocities."""
    p = FANG_XU
    Mt, omega = p["M"] + p["m"], p["omega"]
    P = np.linspace(0.05, 0.6, n)
    P = np.unique(np.concatenate([P, [p["f_fwd"], p["f_bwd"]]]))
    force = P * Mt  # m b omega^2 = P (M + m) g: the inertial force -m s''(t) of s = b sin(omega t)
    law = lj.AnisotropicCoulomb(p["f_fwd"], p["f_bwd"], p["f_fwd"], p["f_bwd"])
    wave = lj.Sinusoid(a=jnp.asarray(force), omega=omega, lbar=0.0)
    body = lj.Mechanism(masses=[Mt], friction=law, links=[lj.ExternalForce(0, wave)])
    T = 2 * math.pi / omega
    res = lj.measure(body, z=1e6, horizon=20 * T, window=20 * T, t_start=5 * T, dynamics=lj.Exact(dt=0.005))
    traj = lj.simulate(body, t_end=6 * T, save_at=jnp.linspace(T, 6 * T, 2001), dynamics=lj.Exact(dt=0.005))
    speed, stuck = np.asarray(res.mean_speed), np.asarray(res.stick_fraction)[:, 0]
    closed = np.array([one_period(float(q), p["f_fwd"]) for q in P])
    exact_speed = closed[:, 0] / omega**2 / T
    band = P <= p["f_bwd"]
    rel = np.abs(speed[band] - exact_speed[band]) / np.maximum(np.abs(exact_speed[band]), 1e-300)
    rel = np.where(exact_speed[band] == 0, np.abs(speed[band]), rel)
    v_min = np.asarray(traj.v)[..., 0].min(axis=-1)
    backward = v_min < 0
    out = {**p, "P": P.tolist(), "mean_speed": speed.tolist(), "closed_form": exact_speed.tolist(),
           "stuck_fraction": stuck.tolist(), "closed_stuck": closed[:, 1].tolist(), "backward_slip": backward.tolist(),
           "max_rel_err_speed": float(rel.max()),
           "max_abs_err_stuck": float(np.abs(stuck[band] - closed[band, 1]).max()),
           "status_ok": bool((np.asarray(res.status) == lj.Status.OK).all())}  # fmt: skip
    print(f"Fang and Xu check: {len(P)} amplitudes, P from {P[0]:.3g} to {P[-1]:.3g}; mean speed vs closed form "
          f"(P <= f-): max relative error {out['max_rel_err_speed']:.2e}; stuck fraction max error "
          f"{out['max_abs_err_stuck']:.2e}; at rest exactly for P <= f+: "
          f"{bool((speed[P <= p['f_fwd']] == 0).all())}; backward slips exactly for P > f-: "
          f"{bool((backward == (P > p['f_bwd'])).all())}")  # fmt: skip
    return out


def plot(res: dict, rep: dict, path: Path) -> None:
    om, f0 = np.asarray(res["omega"]), np.asarray(res["F0"])
    names = list(res["grounds"])
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5), constrained_layout=True)
    cmap = ListedColormap(["0.75", "0.93", "tab:blue", "tab:red"])
    for row, name in enumerate(names):
        g = res["grounds"][name]
        speed, cot, regime = (np.asarray(g[q], float) for q in ("mean_speed", "cost_of_transport", "regime"))
        lim = np.nanmax(np.abs(speed))
        ax = axes[row, 0]
        pc = ax.pcolormesh(om, f0, speed.T, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="nearest")
        fig.colorbar(pc, ax=ax, label="mean speed")
        ax.set(xlabel="omega", ylabel="F0", title=f"{name}: mean speed")
        ax = axes[row, 1]
        pc = ax.pcolormesh(om, f0, np.log10(np.where(cot > 0, cot, np.nan)).T, cmap="viridis", shading="nearest")
        fig.colorbar(pc, ax=ax, label="log10 cost of transport")
        ax.set(xlabel="omega", ylabel="F0", title="cost of transport (e_d / distance), where moving")
        ax = axes[row, 2]
        ax.pcolormesh(om, f0, regime.T, cmap=cmap, vmin=-0.5, vmax=3.5, shading="nearest")
        handles = [Rectangle((0, 0), 1, 1, color=cmap(j)) for j in range(4)]
        ax.legend(handles, REGIMES, loc="upper right", fontsize=8)
        for w, ls in ((math.sqrt(K / m), ":"), (math.sqrt(K * (M + m) / (M * m)), "--")):
            ax.axvline(w, color="k", ls=ls, lw=0.8)
        ax.set(xlabel="omega (dotted: sqrt(k/m), dashed: sqrt(k(M+m)/(Mm)))", ylabel="F0", title="regime")
    fig.suptitle(f"capsule: M = {M}, m = {m} on a spring k = {K}, internal force F0 sin(omega t); "
                 f"averages over {res['horizon']:g} time units after {res['settle']:g}")  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)
    # The published check, a figure of its own.
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    P = np.asarray(rep["P"])
    band = P <= rep["f_bwd"]  # where the closed form holds
    a1.plot(P[band], np.asarray(rep["closed_form"])[band], "k-", lw=1, label="closed form (P <= f-)")
    a1.plot(P, rep["mean_speed"], "o", ms=3, label="lj.measure")
    a2.plot(P[band], np.asarray(rep["closed_stuck"])[band], "k-", lw=1, label="closed form (P <= f-)")
    a2.plot(P, rep["stuck_fraction"], "o", ms=3, label="lj.measure")
    for ax in (a1, a2):
        ax.axvline(rep["f_fwd"], color="tab:blue", ls="--", lw=0.8)
        ax.axvline(rep["f_bwd"], color="tab:red", ls="--", lw=0.8)
        ax.set_xlabel("P = m b omega^2 / ((M + m) g)   (dashed: f+, f-)")
        ax.legend()
    a1.set(ylabel="mean speed", title="internal mass s = b sin(omega t), f+ = 0.2, f- = 0.4")
    a1.set_ylim(min(-0.005, np.nanmin(rep["mean_speed"])), None)
    a2.set(ylabel="fraction of time stuck", title="stuck at rest for P <= f+; backward slips for P > f-")
    fig.savefig(path.with_name("capsule_fang_xu.png"), dpi=110)
    plt.close(fig)


def plot_waveform(best: dict, path: Path) -> None:
    """The optimal force waveform over one period."""
    th = np.linspace(0.0, 2 * math.pi, 400)
    n = np.arange(1, len(best["cos"]) + 1)
    f = np.cos(np.outer(th, n)) @ np.asarray(best["cos"]) + np.sin(np.outer(th, n)) @ np.asarray(best["sin"])
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    ax.plot(th / (2 * math.pi), f, "k-")
    ax.axhline(0, color="k", lw=0.5)
    for y in (-best["f_max"], best["f_max"]):
        ax.axhline(y, color="tab:red", ls="--", lw=0.8)
    ax.set(xlabel="t / T", ylabel="internal force f(t) (+ on the internal mass)",
           title=f"lj.optimise: cheapest force at speed >= {best['v_min']}, {best['friction']}, "
                 f"omega = {best['omega']}\nspeed {best['mean_speed_check']:.3g}, cost of transport "
                 f"{best['cost_check']:.4g} (floor {best['cost_floor']:.3g}); fastest sinusoid (any phase): "
                 f"{best['sinusoid_fastest']:.3g}")  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _rounded(x):
    """The results with 7 significant digits (a smaller file; the checks above use the full values)."""
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v) for v in x]
    if isinstance(x, float):
        return float(f"{x:.7g}") if math.isfinite(x) else None
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 22 x 16 map instead of 86 x 60")
    ap.add_argument("--out", default="experiments/output/capsule")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = capsule_map(*((22, 16) if args.quick else (86, 60)))
    rep = reproduction(12 if args.quick else 56)
    best = optimal_force(args.quick)
    (out / "capsule.json").write_text(json.dumps(_rounded({"map": res, "fang_xu": rep, "optimal_force": best})))
    plot(res, rep, out / "capsule.png")
    plot_waveform(best, out / "capsule_waveform.png")
    print(
        f"wrote {out / 'capsule.png'}, {out / 'capsule_fang_xu.png'}, {out / 'capsule_waveform.png'} and "
        f"{out / 'capsule.json'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
