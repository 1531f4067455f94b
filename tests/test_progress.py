"""`verbose=True` shows progress from the first second: a line before each compile-heavy stage."""

from pathlib import Path

import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax.optimisation import _chain


class Stop(Exception):
    pass


def test_chain_optimisation_says_what_it_compiles_before_compiling(monkeypatch, capsys):
    def screen(*args, **kwargs):
        assert "screening 8 travelling waves" in capsys.readouterr().err  # printed before the long work
        raise Stop

    monkeypatch.setattr(_chain.screen, "screen", screen)
    worm = lj.load_mechanism(Path(__file__).resolve().parents[1] / "examples" / "worm.toml")
    settings = lj.ChainOptimiseSettings(amplitudes=2, frequencies=2, phases=2, verbose=True)
    with pytest.raises(Stop):
        lj.optimise(worm, 0.1, 0.1, settings=settings)


def test_sweep_bar_shows_before_the_first_chunk(monkeypatch, capsys):
    from locomotion_jax.maps import _sweep

    def dispatch(*args, **kwargs):
        assert "compiling (first call only)" in capsys.readouterr().err  # the bar, before the long work
        raise Stop

    monkeypatch.setattr(_sweep.sharding, "dispatch_chunk", dispatch)
    with pytest.raises(Stop):
        lj.sweep({"omega": [1.0, 2.0]}, z=0.5, horizon=5.0, window=2.0, order="natural")


@pytest.mark.parametrize("args", [["gait", "--omega", "2"], ["chain-gait", "--masses", "1,1,1"]], ids=lambda a: a[0])
def test_gait_commands_say_they_compile_before_solving(monkeypatch, args):
    from locomotion_jax.cli import _main as _cli
    from typer.testing import CliRunner

    def steady_gait(*a, **k):
        raise ValueError("stood in")

    monkeypatch.setattr(lj, "steady_gait", steady_gait)
    res = CliRunner().invoke(_cli.app, args)
    assert res.exit_code == 2
    assert res.output.index("solving the steady gait") < res.output.index("Error: stood in"), res.output


def test_steady_gait_says_what_it_does_before_compiling(monkeypatch, capsys):
    from locomotion_jax.gaits import _shooting

    def transient(*args, **kwargs):
        assert "compiling (first call only)" in capsys.readouterr().err  # printed before the long work
        raise Stop

    monkeypatch.setattr(_shooting, "_transient_batch", transient)
    with pytest.raises(Stop):
        lj.steady_gait(lj.Params(omega=2.0), verbose=True)


def test_chain_steady_gait_says_what_it_does_before_compiling(monkeypatch, capsys):
    from locomotion_jax.gaits import _shooting

    def solver(*args, **kwargs):
        assert "compiling (first call only)" in capsys.readouterr().err
        raise Stop

    monkeypatch.setattr(_shooting, "steady_gaits", solver)
    with pytest.raises(Stop):
        lj.steady_gait(lj.Chain(masses=[1.0] * 3, waveforms=lj.TravellingWave(0.06, 2.0, 1.0)), verbose=True)


@pytest.mark.parametrize("call", ["continuation", "basins"])
def test_continuation_and_basins_say_what_they_do_before_compiling(monkeypatch, capsys, call):
    from locomotion_jax.gaits import _shooting

    def transient(*args, **kwargs):
        err = capsys.readouterr().err
        assert f"[{call} " in err or call == "basins", err  # the caller's own first line (continuation)
        assert "[steady_gait " in err and "compiling (first call only)" in err, err
        raise Stop

    monkeypatch.setattr(_shooting, "_transient_batch", transient)
    with pytest.raises(Stop):
        if call == "continuation":
            lj.continuation(lj.Params(omega=4.0), "omega", 6.0, verbose=True)
        else:
            lj.basins(lj.Params(omega=4.9), np.array([[2.95, 0.0, 0.0], [2.9, 0.1, -0.1]]), verbose=True)


def test_steady_gait_verbose_prints_each_stage_and_the_result(capsys):
    g = lj.steady_gait(lj.Params(omega=2.0), periods=1, verbose=True)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("[steady_gait ")]
    assert [("compiling" in lines[0]), ("transient" in lines[1]), ("gait period 1" in lines[2])] == [True] * 3, err
    assert lines[-1].endswith(f"done: {int(g.converged)} of 1 converged") and bool(g.converged), err
    lj.steady_gait(lj.Params(omega=2.0), periods=1)  # quiet by default
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("method", ["exact", "smoothed"])
def test_optimise_says_it_sweeps_the_baseline_before_compiling(monkeypatch, capsys, method):
    from locomotion_jax.optimisation import _pareto

    def sweep(*args, **kwargs):
        assert "the sinusoid baseline: sweeping the sinusoids" in capsys.readouterr().err
        raise Stop

    monkeypatch.setattr(_pareto, "sinusoid_sweep", sweep)
    settings = lj.ExactOptimiseSettings(shape="fourier", verbose=True) if method == "exact" else None
    if settings is None:
        settings = lj.OptimiseSettings(verbose=True)
    with pytest.raises(Stop):
        lj.optimise(lj.Params(), 0.01, 0.05, method=method, harmonics=4, settings=settings)
