"""The options shared by the subcommands (`cli._options`): one declaration, the same contract everywhere."""

import inspect
import math

import locomotion_jax as lj
import pytest
import typer.core
import typer.main
from locomotion_jax.cli import _main as _cli, _options as _cli_options
from typer.testing import CliRunner


def _options(command: str) -> dict:
    group = typer.main.get_command(_cli.app)
    assert isinstance(group, typer.core.TyperGroup)
    return {p.name: p for p in group.commands[command].params}


@pytest.mark.parametrize("command", ["simulate", "animate", "optimize"])
def test_model_options_take_defaults_and_ranges_from_params(command):
    options = _options(command)
    # optimize has no --a, and its --omega fixes the waveform's frequency (default: optimised).
    names = [n for n in lj.PARAM_NAMES if n in options and not (command == "optimize" and n == "omega")]
    assert len(names) == (7 if command == "optimize" else 9)
    for name in names:
        assert options[name].default == lj.DEFAULTS[name]
        assert lj.VALID_RANGES[name] in options[name].help


def test_expand_passes_a_group_as_one_dict():
    app = typer.Typer()

    @app.command()
    @_cli_options.expand(model=_cli_options.model_options(("k", "mu_s")))
    def show(*, model: _cli_options.Values, n: int = 1) -> None:
        typer.echo(f"{sorted(model.items())} {n}")

    @app.command()
    def other() -> None:
        pass

    res = CliRunner().invoke(app, ["show", "--mu-s", "0.9", "--n", "2"])
    assert res.exit_code == 0, res.output
    assert res.output.strip() == "[('k', 50.0), ('mu_s', 0.9)] 2"
    assert list(inspect.signature(show).parameters) == ["k", "mu_s", "n"]


def test_expand_needs_the_placeholder():
    with pytest.raises(TypeError, match="placeholder"):
        _cli_options.expand(model=_cli_options.model_options())(lambda *, other: None)


def test_to_params_omega_over_wn1():
    model = {n: lj.DEFAULTS[n] for n in lj.PARAM_NAMES}
    assert float(_cli_options.to_params({**model, "omega_over_wn1": None}).omega) == lj.DEFAULTS["omega"]
    # wn1 = sqrt(k (m1 + m2) / (m1 m2)) with m1 = 2 mhat, m2 = 2 (1 - mhat) (eqs. 6, 11), written
    # out here; unequal masses and another k, where a wrong formula could not hide behind wn1 = 10.
    k, mhat = 30.0, 0.3
    m1, m2 = 2 * mhat, 2 * (1 - mhat)
    wn1 = math.sqrt(k * (m1 + m2) / (m1 * m2))
    params = _cli_options.to_params({**model, "k": k, "mhat": mhat, "omega_over_wn1": 0.2})
    assert float(params.omega) == pytest.approx(0.2 * wn1, rel=1e-12)
    assert float(params.k) == k and float(params.mhat) == mhat
    with pytest.raises(ValueError, match="mu_s >= mu_k"):
        _cli_options.to_params({"mu_s": 0.1, "mu_k": 0.5})
