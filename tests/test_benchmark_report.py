"""The committed benchmark report is what `benchmarks/run.py` renders from its saved
results, and the README quotes it (issue 5: numbers generated, never hand-typed)."""

import importlib.util
import json
import shutil
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]


def _run_module():
    spec = importlib.util.spec_from_file_location("bench_run", ROOT / "benchmarks" / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _saved():
    saved = json.loads((ROOT / "benchmarks" / "RESULTS.json").read_text())
    saved["meta"]["load"] = [tuple(x) for x in saved["meta"]["load"]]  # as `--render` reads it
    return saved["results"], saved["meta"]


def test_results_md_is_rendered_from_results_json():
    run = _run_module()
    res, meta = _saved()
    assert run.report(res, meta) == (ROOT / "benchmarks" / "RESULTS.md").read_text()


def test_readme_quotes_the_targets_table(tmp_path):
    run = _run_module()
    res, meta = _saved()
    copy = tmp_path / "README.md"
    shutil.copy(ROOT / "README.md", copy)
    run.quote_in_readme(res, meta, readme=copy)
    assert copy.read_text() == (ROOT / "README.md").read_text(), "README out of date: run benchmarks/run.py --render"
    start, end = run.README_MARKS
    quoted = copy.read_text().split(start)[1].split(end)[0]
    rows = [ln for ln in quoted.splitlines() if ln.startswith("| ") and ("met" in ln or "reported" in ln)]
    assert len(rows) >= 8 and all(ln.rstrip().endswith(("| **met** |", "| reported |")) for ln in rows)
