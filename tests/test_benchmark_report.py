"""The committed benchmark report is what `benchmarks/run.py` renders from its saved
results, and the README quotes it (numbers generated, never hand-typed)."""

import importlib.util
import json
import shutil
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run():
    spec = importlib.util.spec_from_file_location("bench_run", ROOT / "benchmarks" / "run.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def saved():
    data = json.loads((ROOT / "benchmarks" / "RESULTS.json").read_text())
    data["meta"]["load"] = [tuple(x) for x in data["meta"]["load"]]  # as `--render` reads it
    return data["results"], data["meta"]


def test_results_md_is_rendered_from_results_json(run, saved):
    assert run.report(*saved) == (ROOT / "benchmarks" / "RESULTS.md").read_text()


def test_readme_quotes_the_targets_table(run, saved, tmp_path):
    copy = tmp_path / "README.md"
    shutil.copy(ROOT / "README.md", copy)
    run.quote_in_readme(*saved, readme=copy)
    assert copy.read_text() == (ROOT / "README.md").read_text(), "README out of date: run benchmarks/run.py --render"
    start, end = run.README_MARKS
    quoted = copy.read_text().split(start)[1].split(end)[0]
    rows = [ln for ln in quoted.splitlines() if ln.startswith("| ") and ("met" in ln or "reported" in ln)]
    assert len(rows) >= 8 and all(ln.rstrip().endswith(("| **met** |", "| reported |")) for ln in rows)
