"""The notebooks run top to bottom, at a small size, in a fresh kernel each (nbclient).

`LOCOMOTION_NB_SMALL=1` shrinks every grid, horizon and animation (see each
notebook's first code cell). A cell that raises fails its test with the cell and the
traceback (nbclient's `CellExecutionError`, from the client process's stderr).

The kernels are separate processes and JAX compiles on one thread, so the notebooks
run two at a time (the CI machine has two cores): about half the wall time of
running them in turn. `LOCOMOTION_NB_WORKERS` changes that. Each notebook's client
runs in a process of its own: with two clients in threads of one process (sharing
zmq and asyncio state) the suite twice stalled for about 10 minutes, client waiting
and kernel idle, before it went on.

The committed `.ipynb` files carry no outputs, and each is paired with a jupytext
percent-format `.py` (the reviewed source; see notebooks/README.md): the test checks
that the two hold the same cells.
"""

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jupytext
import nbformat
import pytest


NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
NAMES = ("01_model_tour", "02_parameter_maps", "03_optimal_actuation")
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
import nbformat
from nbclient import NotebookClient
src, out, path, timeout = sys.argv[1:]
nb = nbformat.read(src, as_version=4)
client = NotebookClient(nb, timeout=int(timeout), kernel_name="python3", resources={"metadata": {"path": path}})
t0 = time.perf_counter()
try:
    client.execute()
finally:
    nb.metadata["execution_seconds"] = time.perf_counter() - t0
    nbformat.write(nb, out)
"""


def _execute(name: str, out_dir: Path) -> tuple[nbformat.NotebookNode, float]:
    """Run one notebook in a fresh client process; raise with the kernel's traceback if a cell fails."""
    out = out_dir / f"{name}.ipynb"
    args = [sys.executable, "-c", _RUNNER, str(NOTEBOOKS / f"{name}.ipynb"), str(out), str(NOTEBOOKS),
            str(CELL_TIMEOUT)]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=NOTEBOOK_TIMEOUT)
    if proc.returncode:
        raise RuntimeError(f"{name} failed (exit {proc.returncode}):\n{proc.stderr[-6000:]}")
    nb = nbformat.read(out, as_version=4)
    return nb, nb.metadata["execution_seconds"]


@pytest.fixture(scope="module")
def executions(request, tmp_path_factory):
    """Start every selected notebook at once (two kernels at a time); each test waits for its own."""
    selected = [item.callspec.params["name"] for item in request.session.items
                if getattr(item, "originalname", None) == "test_notebook_runs"]
    env = {"LOCOMOTION_NB_SMALL": "1"}
    old = {k: os.environ.get(k) for k in (*env, "LOCOMOTION_NB_IMAGES")}
    os.environ.update(env)  # inherited by the kernels
    os.environ.pop("LOCOMOTION_NB_IMAGES", None)  # never write docs/images from a test
    pool = ThreadPoolExecutor(max_workers=int(os.environ.get("LOCOMOTION_NB_WORKERS", "2")))
    # The slowest first, so that the two workers finish together.
    out_dir = tmp_path_factory.mktemp("notebooks")
    futures = {name: pool.submit(_execute, name, out_dir) for name in sorted(selected, reverse=True)}
    try:
        yield futures
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs(name, executions):
    nb, seconds = executions[name].result()  # re-raises a failed cell's error, with its traceback
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors, f"{name}: {errors[0].ename}: {errors[0].evalue}"
    print(f"{name}: {seconds:.0f} s")
