"""Several host-side local solvers in lockstep, their oracle calls batched into one.

A solver such as `scipy.optimize.minimize` asks for values at a point and waits for
them. [`run_lockstep`][] runs one solver per start in a thread; each request blocks
until every solver still running has posted one, then all are answered by a single
batched (vmapped) evaluation. The threads only wait: the work is the batched call,
made from the calling thread.
"""

import threading
from collections.abc import Callable, Sequence
from typing import Any


_EMPTY: Any = object()
"""An empty request or answer slot: any value, `None` included, is a valid request or answer."""


class _Exchange:
    def __init__(self, n: int):
        self.cv = threading.Condition()
        self.requests: list[Any] = [_EMPTY] * n
        self.answers: list[Any] = [_EMPTY] * n
        self.running = [True] * n

    def ask(self, i: int, x: Any) -> Any:
        with self.cv:
            self.requests[i] = x
            self.cv.notify_all()
            while self.answers[i] is _EMPTY:
                self.cv.wait()
            answer, self.answers[i] = self.answers[i], _EMPTY
        if isinstance(answer, _Abort):
            raise RuntimeError("the batched evaluation failed; this solver was stopped")
        return answer

    def finish(self, i: int) -> None:
        with self.cv:
            self.running[i] = False
            self.cv.notify_all()

    def pending(self) -> list[int] | None:
        """Wait until every running solver has asked; their indices (`None`: all finished)."""
        with self.cv:
            while any(r and q is _EMPTY for r, q in zip(self.running, self.requests)):
                self.cv.wait()
            idx = [i for i, r in enumerate(self.running) if r]
            return idx or None

    def answer(self, idx: list[int], answers: Sequence[Any]) -> None:
        if len(answers) != len(idx):
            raise ValueError(f"the batched evaluation returned {len(answers)} answers for {len(idx)} requests")
        with self.cv:
            for i, a in zip(idx, answers):
                self.requests[i] = _EMPTY
                self.answers[i] = a
            self.cv.notify_all()


def run_lockstep(
    solvers: Sequence[Callable[[Callable[[Any], Any]], Any]],
    evaluate: Callable[[list[int], list[Any]], Sequence[Any]],
) -> list[Any]:
    """Run `solvers[i](ask)` in threads; `ask(x)` returns `evaluate(idx, xs)` for its own `x`.

    `evaluate(idx, xs)` receives the indices of the solvers waiting and their points,
    and returns one answer each (any value, `None` included: the chain optimiser answers
    `None` where the orbit solve failed). Returns each solver's return value;
    an exception in a solver is raised here once all have stopped.
    """
    ex = _Exchange(len(solvers))
    results: list[Any] = [None] * len(solvers)
    errors: list[BaseException] = []

    def work(i: int) -> None:
        try:
            results[i] = solvers[i](lambda x: ex.ask(i, x))
        except BaseException as err:  # reported by the caller below
            errors.append(err)
        finally:
            ex.finish(i)

    threads = [threading.Thread(target=work, args=(i,), daemon=True) for i in range(len(solvers))]
    for t in threads:
        t.start()
    try:
        while (idx := ex.pending()) is not None:
            answers = evaluate(idx, [ex.requests[i] for i in idx])
            ex.answer(idx, answers)
    except BaseException:
        # Release the solvers (each gets an exception in its thread) before re-raising.
        ex.answer(list(range(len(solvers))), [_Abort()] * len(solvers))
        raise
    finally:
        for t in threads:
            t.join(timeout=60)
    if errors:
        raise errors[0]
    return results


class _Abort:
    """An answer that tells a waiting solver to stop (the batched evaluation failed)."""
