"""The options shared by the subcommands (`cli._options`, `cli._mechanism`): one declaration, one contract."""

import inspect
import math

import locomotion_jax as lj
import pytest
import typer.core
import typer.main
from locomotion_jax.cli import _main as _cli, _options as _cli_options
from locomotion_jax.cli._mechanism import mechanism_options, to_params
from typer.testing import CliRunner


def _options(command: str) -> dict:
    group = typer.main.get_command(_cli.app)
    assert isinstance(group, typer.core.TyperGroup)
    return {p.name: p for p in group.commands[command].params}


@pytest.mark.parametrize("command", ["measure", "simulate", "gait", "sweep", "animate", "optimize"])
def test_mechanism_options_name_the_papers_defaults_and_ranges(command):
    options = _options(command)
    # optimize has no --a, and its --omega fixes the waveform's frequency (default: optimised).
    names = [n for n in lj.PARAM_NAMES if n in options and not (command == "optimize" and n == "omega")]
    assert len(names) == (7 if command == "optimize" else 9)
    for name in names:
        assert options[name].default is None  # the kind's default: the paper's, or a chain's
        assert f"paper: {lj.DEFAULTS[name]:g}" in options[name].help
        assert lj.VALID_RANGES[name] in options[name].help
    assert "masses" in options and "friction" in options


def test_expand_passes_a_group_as_one_dict():
    app = typer.Typer()

    @app.command()
    @_cli_options.expand(model=_cli_options.run_options(("dt", "z")))
    def show(*, model: _cli_options.Values, n: int = 1) -> None:
        typer.echo(f"{sorted(model.items())} {n}")

    @app.command()
    def other() -> None:
        pass

    res = CliRunner().invoke(app, ["show", "--z", "0.9", "--n", "2"])
    assert res.exit_code == 0, res.output
    assert res.output.strip() == "[('dt', 0.01), ('z', 0.9)] 2"
    assert list(inspect.signature(show).parameters) == ["dt", "z", "n"]


def test_expand_needs_the_placeholder():
    with pytest.raises(TypeError, match="placeholder"):
        _cli_options.expand(model=mechanism_options())(lambda *, other: None)


def test_to_params_omega_over_wn1():
    model = {n: repr(lj.DEFAULTS[n]) for n in lj.PARAM_NAMES}
    assert float(to_params({**model, "omega_over_wn1": None}).omega) == lj.DEFAULTS["omega"]
    # wn1 = sqrt(k (m1 + m2) / (m1 m2)) with m1 = 2 mhat, m2 = 2 (1 - mhat) (eqs. 6, 11), written
    # out here; unequal masses and another k, where a wrong formula could not hide behind wn1 = 10.
    k, mhat = 30.0, 0.3
    m1, m2 = 2 * mhat, 2 * (1 - mhat)
    wn1 = math.sqrt(k * (m1 + m2) / (m1 * m2))
    params = to_params({**model, "k": repr(k), "mhat": repr(mhat), "omega_over_wn1": "0.2"})
    assert float(params.omega) == pytest.approx(0.2 * wn1, rel=1e-12)
    assert float(params.k) == k and float(params.mhat) == mhat
    with pytest.raises(ValueError, match="mu_s >= mu_k"):
        to_params({"mu_s": "0.1", "mu_k": "0.5"})
    with pytest.raises(ValueError, match="--k must be a number"):
        to_params({"k": "50,60"})
