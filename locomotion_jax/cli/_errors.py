"""Expected failures of a command end with one line `Error: ...` on stderr and exit code 2, never a traceback.

Expected are a `ValueError` from the library or the command (bad arguments; its message names
the option or the parameter), a `NotImplementedError` (a combination the library refuses by name,
e.g. `--contact hop` with a carried body) and an `OSError` (an output path that cannot be created
or written, an input that cannot be read), which [`os_error_message`][] attributes to the path
option it concerns.
"""

import functools
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import typer


F = TypeVar("F", bound=Callable[..., Any])


def _concerns(option: Path, path: Path) -> bool:
    """Whether the failing `path` is the option's path, a folder above it, or a file inside it."""
    option, path = option.absolute(), path.absolute()
    return path == option or path in option.parents or option in path.parents


def os_error_message(err: OSError, options: Mapping[str, Any]) -> str:
    """`--out PATH: cannot use it (File exists: /etc/passwd)`: the path option (among a command's
    `options`, by Python name) whose path the error concerns, and the system's reason."""
    reason = err.strerror or str(err)
    failing = None if err.filename is None else Path(str(err.filename))
    detail = reason if failing is None else f"{reason}: {failing}"
    for name, value in options.items():
        if isinstance(value, Path) and failing is not None and _concerns(value, failing):
            return f"--{name.replace('_', '-')} {value}: cannot use it ({detail})."
    return f"{detail}."


def friendly(fn: F) -> F:
    """Decorator of a command: a `ValueError`, a `NotImplementedError` or an `OSError` ends with `Error: ...`
    and exit code 2.

    Apply it below `@app.command()` and above `_options.expand`, so that it sees every option by name.
    """

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ValueError, NotImplementedError) as err:
            message = str(err)
        except OSError as err:
            message = os_error_message(err, kwargs)
        typer.echo(f"Error: {message}", err=True)
        raise typer.Exit(2)

    return wrapper  # type: ignore[return-value]
