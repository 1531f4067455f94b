"""Progress lines of the gait solvers' `verbose=True`: on stderr, flushed, with the seconds since the call began.

Each long call prints a line before each stage that compiles or runs (so the first line
comes before any compiling), and one when it is done.
"""

import sys
import time
from collections.abc import Callable


def reporter(verbose: bool, name: str | None = None) -> Callable[[str], None]:
    """A function that prints `"[name t s] message"` (without a `name`: the message alone) to stderr
    when `verbose`, else does nothing."""
    if not verbose:
        return lambda message: None
    if name is None:
        return lambda message: print(message, file=sys.stderr, flush=True)
    t0 = time.perf_counter()

    def say(message: str) -> None:
        print(f"[{name} {time.perf_counter() - t0:.1f} s] {message}", file=sys.stderr, flush=True)

    return say
