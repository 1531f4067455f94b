"""Options that several `locomotion-jax` subcommands share: the model parameters and the run settings.

Typer reads a command's options from its signature, one parameter each, so a shared option
would be declared again in every command. Instead a command declares one placeholder
parameter for a group of options, e.g. `model: Values`, and `@expand(model=model_options())`
puts the group's options in its place and calls the command with their values in one dict.
Names, defaults and valid ranges come from `_params`, so the help shows the ranges that
`Params` enforces.
"""

import functools
import inspect
from collections.abc import Callable, Iterable, Mapping
from typing import Annotated, Any, TypeVar

import typer

from ..model._params import DEFAULTS, Params, VALID_RANGES


Values = dict[str, Any]
"""What a command receives for a group: option name (the Python name, e.g. `mu_s`) -> value."""

Group = tuple[inspect.Parameter, ...]
"""A group of options, as the signature parameters that typer reads."""

F = TypeVar("F", bound=Callable[..., Any])

MODEL_NAMES: tuple[str, ...] = ("omega", "omega_over_wn1", "a", "d", "mhat", "mu_s", "mu_k", "k", "c", "lbar")
"""The model options in the order the commands list them (actuation first); `omega_over_wn1`
gives omega as a multiple of wn1 instead."""

DESCRIPTIONS: dict[str, str] = {
    "k": "Spring stiffness",
    "c": "Linear damping",
    "d": "Vertical offset of the spring",
    "lbar": "Mean rest length (eq. 13)",
    "a": "Actuation amplitude (eq. 13)",
    "omega": "Actuation frequency (eq. 13)",
    "mu_s": "Static friction coefficient",
    "mu_k": "Kinetic friction coefficient",
    "mhat": "Mass ratio m1 / (m1 + m2)",
    "omega_over_wn1": "Omega as a multiple of wn1 (instead of --omega)",
}


def option(name: str, annotation: Any, default: Any, help: str) -> inspect.Parameter:
    """One typer option `--NAME` (underscores become dashes), as a signature parameter."""
    return inspect.Parameter(
        name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=Annotated[annotation, typer.Option(help=help)]
    )


def _model_help(name: str, form: str = "") -> str:
    """E.g. 'Spring stiffness; k > 0.', with `form` (the accepted text) after the description."""
    valid = f"; {VALID_RANGES[name]}" if name in VALID_RANGES else ""
    return f"{DESCRIPTIONS[name]}{form}{valid}."


def model_options(names: Iterable[str] = MODEL_NAMES) -> Group:
    """The model parameters `names` as float options, defaulting to the paper's values (`omega_over_wn1`: none)."""
    return tuple(
        option(n, float | None, None, _model_help(n))
        if n == "omega_over_wn1"
        else option(n, float, DEFAULTS[n], _model_help(n))
        for n in names
    )


def axis_options(names: Iterable[str] = MODEL_NAMES) -> Group:
    """The model parameters `names` as text options of `sweep`: a range, a list or one value (none by default)."""
    return tuple(option(n, str | None, None, _model_help(n, ": start:stop:count, v1,v2,... or a value")) for n in names)


_RUN = {
    p.name: p
    for p in (
        option("contact", str, "strict", "'strict' (stop at lift-off) or 'paper' (n_i = |N_i|, flagged)."),
        option("start", str, "paper", "'paper' (eq. 14) or 'relaxed' (spring at rest length)."),
        option("dt", float, 0.01, "RK4 step of the exact hybrid integrator."),
        option("z", float, 5.0, "Distance to travel for tau_z, e_z (paper: 5)."),
        option("horizon", float, 2000.0, "Time allowed after t_start."),
        option("window", float, 25.0, "Regime window Delta tau (paper: 25)."),
    )
}

RUN_NAMES: tuple[str, ...] = tuple(_RUN)
"""The settings of a simulation or measurement on the exact model."""


def run_options(names: Iterable[str] = RUN_NAMES) -> Group:
    """The run settings `names` (contact reading, initial condition, step; z, horizon, window of a measurement)."""
    return tuple(_RUN[n] for n in names)


def to_params(model: Mapping[str, Any]) -> Params:
    """The `Params` of the model options; `omega_over_wn1`, when given, sets omega to that multiple of wn1.

    **Raises:** `ValueError` naming the parameter and its valid range for an invalid value.
    """
    params = Params(**{n: v for n, v in model.items() if n != "omega_over_wn1"})
    ratio = model.get("omega_over_wn1")
    return params if ratio is None else params.replace(omega=ratio * float(params.wn1))


def expand(**groups: Group) -> Callable[[F], F]:
    """Decorator: replace each placeholder parameter `NAME` of a command by the options `groups[NAME]`.

    The command is then called with the values of those options as one dict (`Values`) named `NAME`.
    Apply it below `@app.command()`, so that typer reads the expanded signature.
    """

    def decorate(fn: F) -> F:
        signature = inspect.signature(fn)
        missing = set(groups) - set(signature.parameters)
        if missing:
            raise TypeError(f"{fn.__name__} has no placeholder parameter(s) {sorted(missing)}.")
        params: list[inspect.Parameter] = []
        for p in signature.parameters.values():
            if p.name in groups:  # the placeholder's kind keeps the order of kinds valid
                params.extend(q.replace(kind=p.kind) for q in groups[p.name])
            else:
                params.append(p)

        @functools.wraps(fn)
        def wrapper(**kwargs: Any) -> Any:
            for name, group in groups.items():
                kwargs[name] = {q.name: kwargs.pop(q.name) for q in group}
            return fn(**kwargs)

        # typer reads the options from these two, not from `fn`.
        wrapper.__signature__ = signature.replace(parameters=params)  # type: ignore[attr-defined]
        wrapper.__annotations__ = {p.name: p.annotation for p in params} | {"return": signature.return_annotation}
        return wrapper  # type: ignore[return-value]

    return decorate
