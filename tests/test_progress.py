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
