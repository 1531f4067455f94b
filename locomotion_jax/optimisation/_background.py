"""Compilation ahead of need: an optimiser's own programs compiled in a background thread while its
baseline runs in the calling thread.

XLA compiles a program on mostly one core, and an optimiser's baseline (a sweep, a screen) spends
much of its first call compiling its own programs: on a machine of two cores or more the two
overlap. Each step compiles by calling the program on placeholder inputs of the real call's
shapes, dtypes and static choices, so that the real call finds it in JAX's cache.
"""

import threading
from collections.abc import Callable
from typing import Any


class Background:
    """`steps` run in order in a daemon thread; `ready[i]` is set once step `i` has returned.

    A step that raises ends the thread and is left to the real call, which raises its error
    there; every event is set however the thread ends, so that no caller waits forever.
    """

    def __init__(self, *steps: Callable[[], Any]):
        self.ready = [threading.Event() for _ in steps]
        self.thread = threading.Thread(target=self._run, args=(steps,), daemon=True)
        self.thread.start()

    def _run(self, steps: tuple[Callable[[], Any], ...]) -> None:
        try:
            for step, ready in zip(steps, self.ready):
                step()
                ready.set()
        except Exception:  # the real call raises it
            pass
        finally:
            for ready in self.ready:
                ready.set()

    def wait(self, step: int | None = None) -> None:
        """Until step `step` has returned (`None`: until every step has)."""
        if step is None:
            self.thread.join()
        else:
            self.ready[step].wait()
