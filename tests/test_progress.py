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
