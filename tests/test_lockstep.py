"""`run_lockstep`: host-side solvers in threads, their requests answered in batches."""

import threading

import pytest
from locomotion_jax.optimisation._lockstep import run_lockstep


def _within(seconds: float, fn):
    """`fn()` in a thread; fails (instead of hanging the suite) if it does not return in time."""
    box: dict = {}

    def run():
        try:
            box["value"] = fn()
        except BaseException as err:
            box["error"] = err

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), "run_lockstep did not return: a solver or the caller is stuck waiting"
    if "error" in box:
        raise box["error"]
    return box["value"]


def _counter(n_asks: int):
    """A solver that asks `n_asks` times and returns what it was answered."""

    def solve(ask):
        return [ask((n_asks, j)) for j in range(n_asks)]

    return solve


def test_batches_every_waiting_solver_and_answers_none():
    # Solvers of different lengths: each batch holds every solver still running; `None` is
    # an answer like any other (the chain optimiser's answer for a failed orbit solve).
    batches = []

    def evaluate(idx, xs):
        batches.append(list(idx))
        return [None if i == 1 else (i, x) for i, x in zip(idx, xs)]

    out = _within(20, lambda: run_lockstep([_counter(3), _counter(1), _counter(2)], evaluate))
    assert out[0] == [(0, (3, 0)), (0, (3, 1)), (0, (3, 2))]
    assert out[1] == [None]
    assert out[2] == [(2, (2, 0)), (2, (2, 1))]
    assert batches == [[0, 1, 2], [0, 2], [0]]


def test_a_failed_evaluation_stops_every_solver_and_is_raised():
    def evaluate(idx, xs):
        raise FloatingPointError("oracle failed")

    with pytest.raises(FloatingPointError, match="oracle failed"):
        _within(20, lambda: run_lockstep([_counter(2), _counter(2)], evaluate))


def test_a_short_answer_list_is_an_error_not_a_hang():
    with pytest.raises(ValueError, match="1 answers for 2 requests"):
        _within(20, lambda: run_lockstep([_counter(1), _counter(1)], lambda idx, xs: [0]))


def test_a_solver_error_is_raised_after_the_others_finish():
    def broken(ask):
        ask(0)
        raise KeyError("solver bug")

    with pytest.raises(KeyError, match="solver bug"):
        _within(20, lambda: run_lockstep([broken, _counter(3)], lambda idx, xs: list(xs)))
