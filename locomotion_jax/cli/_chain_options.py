"""Options that the chain commands share: the mechanism (masses, springs, friction, actuator) and the wave.

Per-mass and per-spring values are comma-separated lists (one value is broadcast), read by
[`to_chain`][]. The groups plug into a command through `_options.expand`, e.g.
`@expand(mech=mechanism_options(), wave=wave_options())`.
"""

import math
from typing import Any, Literal

from ..model._chain import Chain
from ._options import Group, option, Values


def floats(name: str, text: str) -> list[float]:
    """A comma-separated list of numbers (`--NAME`'s text)."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--{name} must be a number or a comma-separated list of numbers, got {text!r}.") from None
    if not values:
        raise ValueError(f"--{name} is empty.")
    return values


def one(values: list[float]) -> float | list[float]:
    return values[0] if len(values) == 1 else values


def mechanism_options(masses_required: bool = True) -> Group:
    """Masses, springs, damping, actuator and friction law of a chain (`--masses` optional where a
    mechanism file may replace the options)."""
    masses = "Masses m_i, comma-separated (N >= 2; the total sets the scale)."
    return (
        option("masses", str, ..., masses) if masses_required else option("masses", str | None, None, masses),
        option("k", str, "50", "Stiffness per spring (one value or N-1)."),
        option("d", str, "0", "Vertical offset per spring (default 0: flat springs, as a worm on the ground)."),
        option("lbar", str, "3", "Mean rest length per spring."),
        option("c", str, "0.01", "Damping per mass."),
        option("actuator", Literal["length", "force"], "length", "The signal is a rest length or an internal force."),
        option("friction", Literal["coulomb", "anisotropic", "stribeck"], "coulomb", "Friction law of every mass."),
        option("mu_s", str, "0.7", "Static coefficient (forward where anisotropic), per mass."),
        option("mu_k", str, "0.5", "Kinetic coefficient (forward where anisotropic), per mass."),
        option("mu_s_bwd", str | None, None, "Backward static coefficient (default: forward)."),
        option("mu_k_bwd", str | None, None, "Backward kinetic coefficient (default: forward)."),
        option("v_s", float, 0.3, "Stribeck speed (friction=stribeck)."),
    )


def wave_options() -> Group:
    """The travelling wave $s_j = a \\sin(\\omega t - j\\varphi)$."""
    return (
        option("a", float, 0.05, "Amplitude of the travelling wave s_j = a sin(omega t - j phi)."),
        option("omega", float, 2.0, "Frequency of the wave."),
        option("phi", float, 0.0, "Phase lag between neighbouring springs (> 0: towards +x)."),
    )


def friction_law(mech: Values) -> Any:
    """The friction law of the options (`ValueError` for inconsistent ones)."""
    import locomotion_jax as lj

    law = {"mu_s": floats("mu-s", mech["mu_s"]), "mu_k": floats("mu-k", mech["mu_k"])}
    bwd = {
        "mu_s_bwd": law["mu_s"] if mech["mu_s_bwd"] is None else floats("mu-s-bwd", mech["mu_s_bwd"]),
        "mu_k_bwd": law["mu_k"] if mech["mu_k_bwd"] is None else floats("mu-k-bwd", mech["mu_k_bwd"]),
    }
    kind = mech["friction"]
    if kind == "coulomb":
        if mech["mu_s_bwd"] is not None or mech["mu_k_bwd"] is not None:
            raise ValueError("--mu-s-bwd/--mu-k-bwd need --friction anisotropic or stribeck.")
        return lj.Coulomb(one(law["mu_s"]), one(law["mu_k"]))
    if kind == "anisotropic":
        return lj.AnisotropicCoulomb(one(law["mu_s"]), one(bwd["mu_s_bwd"]), one(law["mu_k"]), one(bwd["mu_k_bwd"]))
    v_s = mech["v_s"]
    if not (math.isfinite(v_s) and v_s > 0):
        raise ValueError(f"--v-s must be a finite number > 0, got {v_s!r}.")
    return lj.Stribeck(one(law["mu_s"]), one(law["mu_k"]), v_s, mu_s_bwd=one(bwd["mu_s_bwd"]),
                       mu_k_bwd=one(bwd["mu_k_bwd"]))  # fmt: skip


def to_chain(mech: Values, waveforms: Any = None, **overrides: Any) -> Chain:
    """The [`Chain`][] of the mechanism options with `waveforms` (`overrides`: arrays that replace
    options, e.g. batched values of a sweep). **Raises:** `ValueError` naming the bad option."""
    import locomotion_jax as lj

    fields: dict[str, Any] = {n: one(floats(n, mech[n])) for n in ("k", "d", "lbar", "c")}
    fields.update(overrides)
    return lj.Chain(
        masses=floats("masses", mech["masses"]), waveforms=waveforms, friction=friction_law(mech),
        actuator=lj.InternalForce() if mech["actuator"] == "force" else lj.RestLength(), **fields,
    )  # fmt: skip


def describe(mech: Values) -> dict[str, Any]:
    """The mechanism options as JSON-ready values (lists of numbers where given as lists)."""
    out: dict[str, Any] = {"n_masses": len(floats("masses", mech["masses"]))}
    for n in ("masses", "k", "d", "lbar", "c", "mu_s", "mu_k", "mu_s_bwd", "mu_k_bwd"):
        if mech[n] is not None:
            out[n] = one(floats(n.replace("_", "-"), mech[n]))
    out.update(friction=mech["friction"], actuator=mech["actuator"])
    return out
