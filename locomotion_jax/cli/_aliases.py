"""The commands' old names, kept for one release: hidden, each prints a one-line deprecation note to
stderr and runs the new command (`chain` and `chain-simulate` measure and simulate a chain: the same
options, with `--masses`)."""

import functools
from typing import Any

import typer


ALIASES: dict[str, str] = {
    "chain": "measure",
    "chain-simulate": "simulate",
    "chain-gait": "gait",
    "chain-sweep": "sweep",
    "chain-optimize": "optimize",
}
"""Old name -> the command it runs."""


def _alias(old: str, new: str, callback: Any) -> Any:
    @functools.wraps(callback)  # the same signature, so the same options
    def run(*args: Any, **kwargs: Any) -> Any:
        typer.echo(f"Note: `{old}` is deprecated and will be removed; use `locomotion-jax {new}`.", err=True)
        return callback(*args, **kwargs)

    return run


def register(app: typer.Typer) -> None:
    """Add the hidden aliases of [`ALIASES`][] to `app` (after the commands they run)."""
    commands = {c.name: c for c in app.registered_commands}
    for old, new in ALIASES.items():
        command = commands[new]
        app.command(old, hidden=True, help=f"Deprecated: `{new}`.")(_alias(old, new, command.callback))
