"""Every page that quotes the benchmark's targets table (`benchmarks/run.py` `QUOTED_IN`: the
README and the documentation's performance page) quotes what `--render` writes."""

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


def test_every_page_quotes_the_rendered_targets_table(run, tmp_path):
    data = json.loads((ROOT / "benchmarks" / "RESULTS.json").read_text())
    data["meta"]["load"] = [tuple(x) for x in data["meta"]["load"]]  # as `--render` reads it
    assert {p.relative_to(ROOT).as_posix() for p in run.QUOTED_IN} == {"README.md", "docs/performance.md"}
    for page in run.QUOTED_IN:
        copy = tmp_path / page.name
        shutil.copy(page, copy)
        run.quote_in_readme(data["results"], data["meta"], readme=copy)
        assert copy.read_text() == page.read_text(), f"{page} out of date: run benchmarks/run.py --render"
        start, end = run.README_MARKS
        assert page.read_text().count(start) == 1 and page.read_text().count(end) == 1
