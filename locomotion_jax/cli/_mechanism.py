"""The mechanism of a command: the paper's model (default), a chain (`--masses`) or a mechanism file.

Every command that runs a mechanism declares one group of options, [`mechanism_options`][], and reads
it once with [`build`][] into a [`Built`][]: the mechanism to pass to the library's front ends, and
what the command prints about it. The options that the paper's model and a chain share (`--a`,
`--omega`, `--k`, `--d`, `--lbar`, `--c`, `--mu-s`, `--mu-k`) take text: one number for the paper's
model; for a chain one number or a comma-separated list (per spring or per mass, one value broadcast).
Unset, each takes its kind's default. A positional FILE replaces all of them (they are refused beside
it: a silent mix of the two would be ambiguous).
"""

import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from ..model._params import DEFAULTS, Params, VALID_RANGES
from ._options import Group, option, Values


PAPER_ONLY: tuple[str, ...] = ("omega_over_wn1", "mhat")
CHAIN_ONLY: tuple[str, ...] = ("masses", "phi", "actuator", "friction", "mu_s_bwd", "mu_k_bwd", "v_s")
NAMES: tuple[str, ...] = ("omega", "omega_over_wn1", "a", "d", "mhat", "mu_s", "mu_k", "k", "c", "lbar", *CHAIN_ONLY)
"""The mechanism options in the order the commands list them (the paper's model's first)."""

CHAIN_DEFAULTS: dict[str, str] = {"a": "0.05", "omega": "2", "phi": "0", "k": "50", "d": "0", "lbar": "3",
                                  "c": "0.01", "mu_s": "0.7", "mu_k": "0.5"}  # fmt: skip
"""A chain's values of the options not given (d = 0: flat springs, as a worm on the ground)."""

_WHAT: dict[str, str] = {
    "omega": "Actuation frequency (eq. 13; a chain's travelling wave)",
    "omega_over_wn1": "The paper's model: omega as a multiple of wn1 (instead of --omega)",
    "a": "Actuation amplitude (eq. 13; a chain's travelling wave)",
    "d": "Vertical offset of the spring (a chain: per spring)",
    "mhat": "The paper's model: mass ratio m1 / (m1 + m2)",
    "mu_s": "Static friction coefficient (a chain: per mass; forward where anisotropic)",
    "mu_k": "Kinetic friction coefficient (a chain: per mass; forward where anisotropic)",
    "k": "Spring stiffness (a chain: per spring)",
    "c": "Linear damping (a chain: per mass)",
    "lbar": "Mean rest length (eq. 13; a chain: per spring)",
}


def _help(name: str, sweep: bool) -> str:
    form = "start:stop:count, v1,v2,... or a value" if sweep else "a number"
    paper = f"paper: {DEFAULTS[name]:g}" if name in DEFAULTS else "paper: none"
    chain = f", chain: {CHAIN_DEFAULTS[name]}" if name in CHAIN_DEFAULTS else ""
    valid = f"; {VALID_RANGES[name]}" if name in VALID_RANGES else ""
    return f"{_WHAT[name]}: {form} (default {paper}{chain}){valid}."


def mechanism_options(names: tuple[str, ...] = NAMES, sweep: bool = False) -> Group:
    """The options of `names` (a subset of [`NAMES`][], in that order); `sweep`: the help names ranges."""
    chain: dict[str, Any] = {
        "masses": (str | None, None, "A chain: its masses m_i, comma-separated (N >= 2)."),
        "phi": (str | None, None, "A chain: phase lag of the wave a sin(omega t - j phi) on spring j (default 0)."),
        "actuator": (Literal["length", "force"], "length", "A chain: the signal is a rest length or a force."),
        "friction": (Literal["coulomb", "anisotropic", "stribeck"], "coulomb", "A chain: every mass's friction law."),
        "mu_s_bwd": (str | None, None, "A chain: backward static coefficient (default: forward)."),
        "mu_k_bwd": (str | None, None, "A chain: backward kinetic coefficient (default: forward)."),
        "v_s": (float, 0.3, "A chain: Stribeck speed (--friction stribeck)."),
    }
    group = tuple(option(n, *chain[n]) if n in chain else option(n, str | None, None, _help(n, sweep)) for n in names)
    return tuple(_recording(p) for p in group) if sweep else group


ORDER = "locomotion_jax.axis_order"
"""The key of the click context's `meta` under which `sweep` finds its options in the order given."""


def _recording(p: inspect.Parameter) -> inspect.Parameter:
    """The option `p` with a callback that records its name when given: click processes the options
    in the order of the command line, so a sweep's dimensions can follow it."""
    from ._files import context

    def record(value: Any) -> Any:
        ctx = context()
        if value is not None and ctx is not None:
            ctx.meta.setdefault(ORDER, []).append(p.name)
        return value

    base, info = p.annotation.__origin__, p.annotation.__metadata__[0]
    return p.replace(annotation=Annotated[base, typer.Option(help=info.help, callback=record)])


def floats(name: str, text: str) -> list[float]:
    """`--NAME`'s text as a list of numbers (comma-separated)."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--{name} must be a number or a comma-separated list of numbers, got {text!r}.") from None
    if not values:
        raise ValueError(f"--{name} is empty.")
    return values


def number(name: str, text: str) -> float:
    """`--NAME`'s text as one number (an option of the paper's model)."""
    opt = "--" + name.replace("_", "-")
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{opt} must be a number (the paper's model takes one value), got {text!r}.") from None


def _one(values: list[float]) -> float | list[float]:
    return values[0] if len(values) == 1 else values


def _list(mech: Values, name: str) -> float | list[float]:
    text = mech.get(name)
    return _one(floats(name.replace("_", "-"), CHAIN_DEFAULTS[name] if text is None else text))


def friction_law(mech: Values) -> Any:
    """A chain's friction law of the options (`ValueError` for inconsistent ones)."""
    import locomotion_jax as lj

    fwd = {n: _list(mech, n) for n in ("mu_s", "mu_k")}
    bwd = {n: fwd[n[:4]] if mech[n] is None else _one(floats(n.replace("_", "-"), mech[n]))
           for n in ("mu_s_bwd", "mu_k_bwd")}  # fmt: skip
    kind = mech["friction"]
    if kind == "coulomb":
        if mech["mu_s_bwd"] is not None or mech["mu_k_bwd"] is not None:
            raise ValueError("--mu-s-bwd/--mu-k-bwd need --friction anisotropic or stribeck.")
        return lj.Coulomb(fwd["mu_s"], fwd["mu_k"])
    if kind == "anisotropic":
        return lj.AnisotropicCoulomb(fwd["mu_s"], bwd["mu_s_bwd"], fwd["mu_k"], bwd["mu_k_bwd"])
    v_s = mech["v_s"]
    if not (math.isfinite(v_s) and v_s > 0):
        raise ValueError(f"--v-s must be a finite number > 0, got {v_s!r}.")
    return lj.Stribeck(fwd["mu_s"], fwd["mu_k"], v_s, mu_s_bwd=bwd["mu_s_bwd"], mu_k_bwd=bwd["mu_k_bwd"])


def to_chain(mech: Values, waveforms: Any = None, check: bool = True) -> Any:
    """The [`Chain`][] of the options with `waveforms`. **Raises:** `ValueError` naming the bad option."""
    import locomotion_jax as lj

    k, d, lbar, c = (_list(mech, n) for n in ("k", "d", "lbar", "c"))
    actuator = lj.InternalForce() if mech["actuator"] == "force" else lj.RestLength()
    return lj.Chain(masses=floats("masses", mech["masses"]), k=k, d=d, lbar=lbar, c=c, waveforms=waveforms,
                    friction=friction_law(mech), actuator=actuator, check=check)  # fmt: skip


def wave_text(mech: Values, name: str) -> str:
    """The text of a chain's wave option `name` (a, omega, phi): as given, else the chain's default."""
    text = mech.get(name)
    return CHAIN_DEFAULTS[name] if text is None else text


def to_params(mech: Values) -> Params:
    """The paper's model of the options (`omega_over_wn1`, when given, sets omega to that multiple of wn1).

    **Raises:** `ValueError` naming the option, or the parameter and its valid range.
    """
    values: dict[str, Any] = {n: number(n, mech[n]) for n in DEFAULTS if mech.get(n) is not None}
    params = Params(**values)
    ratio = mech.get("omega_over_wn1")
    return params if ratio is None else params.replace(omega=number("omega_over_wn1", ratio) * float(params.wn1))


@dataclass
class Built:
    """A command's mechanism: `mechanism` for the library, `extra` its keyword arguments (a paper
    file's `waveform`), `head` the report's first line, `record` what `--json` says of it."""

    kind: str  # "paper", "chain" or "mechanism" (of bodies and links)
    mechanism: Any
    head: str
    record: dict[str, Any]
    file: Path | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def omega(self) -> float:
        """The actuation frequency (of a paper file's waveform where it has one)."""
        import numpy as np

        source = self.extra.get("waveform", self.mechanism)
        return float(np.max(np.asarray(source.omega)))


KIND_NAMES: dict[str, str] = {"paper": "the paper's model", "chain": "a chain",
                              "mechanism": 'a mechanism of bodies and links (kind = "mechanism")'}  # fmt: skip


def kind_of_options(mech: Values) -> str:
    """`"chain"` when `--masses` is given, else `"paper"`; `ValueError` for an option of the other kind."""
    from ._files import given

    kind = "paper" if mech.get("masses") is None else "chain"
    other = [n for n in given(mech) if n in (CHAIN_ONLY if kind == "paper" else PAPER_ONLY)]
    if other:
        options = ", ".join("--" + n.replace("_", "-") for n in other)
        need = "describe a chain: give --masses" if kind == "paper" else "describe the paper's model, not a chain"
        raise ValueError(f"{options}: these options {need}.")
    return kind


def build(mech: Values, file: Path | None, *, wave: bool = True) -> Built:
    """The mechanism of the FILE, else of the options `mech`; `wave`: a chain gets its travelling wave
    (a, omega, phi) from the options (without it, the command supplies the actuation)."""
    import locomotion_jax as lj

    if file is not None:
        from ._files import label, load, refuse_options

        refuse_options(file, mech)
        loaded, waveform = load(file)
        record: dict[str, Any] = {"mechanism": str(file), "kind": loaded.kind}
        if loaded.kind == "paper":
            record["params"] = {n: float(v) for n, v in loaded.as_dict().items()}
        extra = {} if waveform is None else {"waveform": waveform}
        return Built(loaded.kind, loaded, label(file, loaded, waveform), record, file, extra)
    if kind_of_options(mech) == "paper":
        params = to_params(mech)
        values = {n: float(getattr(params, n)) for n in DEFAULTS}
        head = "parameters: " + ", ".join(f"{n}={v:g}" for n, v in values.items())
        return Built("paper", params, head, {"kind": "paper", "params": values})
    w = {n: number(n, wave_text(mech, n)) for n in ("a", "omega", "phi")} if wave else {}
    chain = to_chain(mech, lj.TravellingWave(w["a"], w["omega"], w["phi"]) if wave else None)
    described = {n: _list(mech, n) for n in ("k", "d", "lbar", "c", "mu_s", "mu_k")}
    described.update({n: _one(floats(n.replace("_", "-"), mech[n])) for n in ("mu_s_bwd", "mu_k_bwd") if mech[n]})
    record = {"kind": "chain", "n_masses": chain.n_masses, "masses": floats("masses", mech["masses"]), **described,
              "friction": mech["friction"], "actuator": mech["actuator"], **w}  # fmt: skip
    head = f"chain of {chain.n_masses} masses, {mech['friction']} friction, {mech['actuator']} actuator"
    head += "".join(f"; {n}={v:g}" if n == "a" else f", {n}={v:g}" for n, v in w.items())
    return Built("chain", chain, head, record)
