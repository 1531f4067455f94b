"""The notebooks run top to bottom, at a small size, in a fresh kernel each (nbclient).

`LOCOMOTION_NB_SMALL=1` shrinks every grid, horizon and animation (see each
notebook's first code cell). A cell that raises fails its test with the cell and the
traceback (nbclient's `CellExecutionError`, from the client process's stderr).

Each test runs its notebook in a client process of its own (nbclient in a
subprocess: a stuck client is killed by `NOTEBOOK_TIMEOUT`, and no zmq or asyncio
state is shared); `pytest -n 2` spreads them over both cores.

The client waits for kernel messages in polls of at most a second. In CI runs it
sometimes missed the zmq wake-up for a reply (after the `ipywidgets` panel of
`01_model_tour`; jupyter/nbclient#312) and found it only when its 600 s wait ran
out; a poll that times out checks the socket again, so a missed wake-up costs
under a second.

The committed `.ipynb` files carry no outputs, and each is paired with a jupytext
percent-format `.py` (the reviewed source; see notebooks/README.md): the test checks
that the two hold the same cells.
"""

import os
import subprocess
import sys
from pathlib import Path

import jupytext
import nbformat
import pytest
from locomotion_jax._cache import WRITE_EVERY_ENTRY


NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
NAMES = ("01_model_tour", "02_parameter_maps", "03_optimal_actuation", "04_gradients_and_fitting", "05_steady_gaits")
CELL_TIMEOUT = 600  # seconds per cell: a hung kernel fails instead of blocking CI
NOTEBOOK_TIMEOUT = 900  # seconds per notebook, client start included


def test_every_notebook_is_tested():
    assert sorted(p.stem for p in NOTEBOOKS.glob("*.ipynb")) == sorted(NAMES)
    assert sorted(p.stem for p in NOTEBOOKS.glob("[0-9]*.py")) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_committed_notebook_is_stripped_and_paired(name):
    nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, f"{name}.ipynb has outputs: strip them"
    assert "widgets" not in nb.metadata, f"{name}.ipynb carries widget state: strip it"
    text = jupytext.read(NOTEBOOKS / f"{name}.py")
    assert [(c.cell_type, c.source) for c in text.cells] == [(c.cell_type, c.source) for c in nb.cells], (
        f"{name}.ipynb and {name}.py differ: run `jupytext --sync notebooks/{name}.py`"
    )


_RUNNER = """
import sys, time
from queue import Empty
import nbformat
from nbclient import NotebookClient

POLL = 1.0  # longest single wait on a channel, seconds


def short_polls(channel):
    # A poll that times out re-checks the socket: a missed zmq wake-up then costs one
    # poll, not the whole timeout. Same contract as get_msg: Empty once `timeout` is up.
    get = channel.get_msg

    async def get_msg(timeout=None):
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = POLL if deadline is None else min(POLL, max(0.0, deadline - time.monotonic()))
            try:
                return await get(timeout=left)
            except Empty:
                if deadline is not None and time.monotonic() >= deadline:
                    raise

    channel.get_msg = get_msg


def on_start(notebook):
    short_polls(client.kc.shell_channel)
    short_polls(client.kc.iopub_channel)


src, out, path, timeout = sys.argv[1:]
nb = nbformat.read(src, as_version=4)
client = NotebookClient(nb, timeout=int(timeout), kernel_name="python3", resources={"metadata": {"path": path}},
                        on_notebook_start=on_start)
t0 = time.perf_counter()
try:
    client.execute()
finally:
    nb.metadata["execution_seconds"] = time.perf_counter() - t0
    nbformat.write(nb, out)
"""


def _share_test_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernel reads and writes the tests' compilation cache (`conftest._shared_compilation_cache`:
    the directory in `LJ_TEST_CACHE_DIR`) through JAX's own environment variables: a program a
    notebook shares with a test, or with another notebook, is compiled once per run."""
    path = os.environ.get("LJ_TEST_CACHE_DIR")
    if not path or path == "off":
        return
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", path)
    for name, value in WRITE_EVERY_ENTRY.items():  # as `lj.enable_compilation_cache`
        monkeypatch.setenv(name.upper(), str(value))


def _execute(name: str, out_dir: Path, source: Path | None = None) -> tuple[nbformat.NotebookNode, float]:
    """Run one notebook (`source`, default the committed one) in a fresh client process;
    raise with the kernel's traceback if a cell fails."""
    out = out_dir / f"{name}.ipynb"
    args = [
        sys.executable,
        "-c",
        _RUNNER,
        str(source or NOTEBOOKS / f"{name}.ipynb"),
        str(out),
        str(NOTEBOOKS),
        str(CELL_TIMEOUT),
    ]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=NOTEBOOK_TIMEOUT)
    if proc.returncode:
        raise RuntimeError(f"{name} failed (exit {proc.returncode}):\n{proc.stderr[-6000:]}")
    nb = nbformat.read(out, as_version=4)
    return nb, nb.metadata["execution_seconds"]


# Every notebook runs in the default suite (what CI runs), at the small size.
@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs(name, tmp_path, monkeypatch):
    monkeypatch.setenv("LOCOMOTION_NB_SMALL", "1")  # inherited by the client and its kernel
    monkeypatch.delenv("LOCOMOTION_NB_IMAGES", raising=False)  # never write docs/images from a test
    _share_test_cache(monkeypatch)
    nb, seconds = _execute(name, tmp_path)  # raises with a failed cell's traceback
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors, f"{name}: {errors[0].ename}: {errors[0].evalue}"
    print(f"{name}: {seconds:.0f} s")


def test_model_tour_runs_without_ipywidgets(tmp_path, monkeypatch):
    # The main install (`pip install -e .`) has no ipywidgets: a module of that name
    # that fails to import stands in for it, first on the kernel's path.
    hide = tmp_path / "hide"
    hide.mkdir()
    (hide / "ipywidgets.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'ipywidgets'\", name='ipywidgets')\n"
    )
    path = [str(hide), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(path))
    monkeypatch.setenv("LOCOMOTION_NB_SMALL", "1")
    monkeypatch.delenv("LOCOMOTION_NB_IMAGES", raising=False)
    _share_test_cache(monkeypatch)
    # Only what the panel needs (the whole notebook runs in `test_notebook_runs`): the setup
    # cell, the two example configurations, the plotting helpers, and the panel's cells.
    nb = nbformat.read(NOTEBOOKS / "01_model_tour.ipynb", as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    first = next(i for i, c in enumerate(code) if "T_EXPLORE = " in c.source)
    cases = next(c for c in code if "base = lj.Params()" in c.source)
    helpers = next(c for c in code if "def plot_case" in c.source)
    nb.cells = [code[0], cases, nbformat.v4.new_code_cell("T_END = 40.0"), helpers, *code[first:]]
    trimmed = tmp_path / "trimmed.ipynb"
    nbformat.write(nb, trimmed)
    nb, _ = _execute("01_model_tour", tmp_path, trimmed)
    printed = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    assert "No sliders: ipywidgets is not installed" in printed
    assert "explore ready: OK" in printed
