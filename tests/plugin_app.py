"""A typer app with one plug-in subcommand, for testing it apart from the main CLI (and its global options)."""

from collections.abc import Callable

import typer


def plugin_app(register: Callable[[typer.Typer], None]) -> typer.Typer:
    """An app with the command that `register` adds (e.g. `cli._animate.register`)."""
    app = typer.Typer()
    register(app)

    @app.command("noop")  # a second command keeps typer in multi-command mode, as in cli/_main.py
    def noop() -> None:
        pass

    return app
