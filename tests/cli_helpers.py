"""What the CLI tests share: typer's `CliRunner` and `invoke` (one command line, in process).

Their modules also take the `isolate_xla_flags` fixture of `conftest.py`
(`pytestmark = pytest.mark.usefixtures("isolate_xla_flags")`)."""

from locomotion_jax.cli import _main as _cli
from typer.testing import CliRunner, Result


runner = CliRunner()


def invoke(*args: str) -> Result:
    """Run `locomotion-jax ARGS...` in this process."""
    return runner.invoke(_cli.app, list(args))
