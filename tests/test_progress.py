"""`verbose=True` shows progress from the first second: a line before each compile-heavy stage."""

from pathlib import Path

import locomotion_jax as lj
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
