"""Options that several `locomotion-jax` subcommands share: the run settings, and how a group plugs in.

Typer reads a command's options from its signature, one parameter each, so a shared option
would be declared again in every command. Instead a command declares one placeholder
parameter for a group of options, e.g. `mech: Values`, and `@expand(mech=mechanism_options())`
puts the group's options in its place and calls the command with their values in one dict.
The mechanism's options are in `_mechanism.py`.
"""

import functools
import inspect
from collections.abc import Callable, Iterable
from typing import Annotated, Any, TypeVar

import typer


Values = dict[str, Any]
"""What a command receives for a group: option name (the Python name, e.g. `mu_s`) -> value."""

Group = tuple[inspect.Parameter, ...]
"""A group of options, as the signature parameters that typer reads."""

F = TypeVar("F", bound=Callable[..., Any])


def option(name: str, annotation: Any, default: Any, help: str) -> inspect.Parameter:
    """One typer option `--NAME` (underscores become dashes), as a signature parameter."""
    return inspect.Parameter(
        name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=Annotated[annotation, typer.Option(help=help)]
    )


_RUN = {
    p.name: p
    for p in (
        option(
            "contact",
            str,
            "strict",
            "Contact reading: 'strict' (stop at lift-off), 'paper' (n_i = |N_i|, "
            "flagged), 'hop' (flight and landing, SPEC section 10), or another the engine knows (passed to it "
            "as given).",
        ),
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
