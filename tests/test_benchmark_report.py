"""The committed benchmark report is what `benchmarks/run.py` renders from its saved
results, and the page that quotes its targets table (`run.py` `QUOTED_IN`: the documentation's
performance page) quotes what `--render` writes (numbers generated, never hand-typed); the README
quotes none of it."""

import importlib.util
import json
import shutil
import subprocess
import sys
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


def test_readme_quotes_no_benchmark_number(run):
    readme = (ROOT / "README.md").read_text()
    start, end = run.TABLE_MARKS
    assert start not in readme and end not in readme
    assert "docs/performance.md" in readme and "benchmarks/RESULTS.md" in readme


def test_every_page_quotes_the_rendered_targets_table(run, tmp_path):
    data = json.loads((ROOT / "benchmarks" / "RESULTS.json").read_text())
    data["meta"]["load"] = [tuple(x) for x in data["meta"]["load"]]  # as `--render` reads it
    assert {p.relative_to(ROOT).as_posix() for p in run.QUOTED_IN} == {"docs/performance.md"}
    for page in run.QUOTED_IN:
        copy = tmp_path / page.name
        shutil.copy(page, copy)
        run.quote_in(data["results"], data["meta"], copy)
        assert copy.read_text() == page.read_text(), f"{page} out of date: run benchmarks/run.py --render"
        start, end = run.TABLE_MARKS
        assert page.read_text().count(start) == 1 and page.read_text().count(end) == 1


def test_zarr_map_case_runs_at_a_small_size(run):
    # The benchmark's Zarr map case (2048 x 2048 in the full run) at 16 x 16, in a process of
    # its own as the benchmark spawns it: the map is complete, every configuration has a
    # regime, and the store on disk holds the map.
    r = run.spawn(dict(kind="zarr_map", N=16, **run.ZARR_MAP), timeout=600)
    assert "error" not in r, r.get("error")
    assert r["n_configs"] == 256 and sum(r["regimes"].values()) == 256
    assert r["regimes"]["UNDETERMINED"] == 256 - r["n_ok"]  # only runs that stopped early lack a regime
    assert r["regimes"]["SSL"] > 0 and r["regimes"]["SL"] > 0  # the map crosses the boundary
    assert r["store_mb"] > 0 and r["n_files"] > 1 and r["wall"] > 0 and r["rss"] > 0


def _script(name: str, *args: str) -> str:
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / name), *args], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def test_chain_scaling_runs_at_a_small_size():
    # The script calls the engine's compiled program directly, so a change of its arguments shows here.
    out = _script("chain_scaling.py", "--sizes", "2", "--batch", "16", "--layouts", "array")
    assert any(line.startswith("| 2 | array | ") for line in out.splitlines()), out


def test_padding_benchmark_finds_padded_and_unpadded_runs_equal():
    out = _script("padding.py", "--small", "--sizes", "17", "--repeats", "1")
    row = [line for line in out.splitlines() if line.startswith("| 17 | 32 | ")]
    assert len(row) == 1 and row[0].rstrip().endswith("| 0.0e+00 |"), out


def test_loop_cost_reads_the_engine_hot_loop():
    # As chain_scaling.py, this script compiles the engine's program itself (and replaces its queue).
    out = json.loads(_script("loop_cost.py", "--B", "16", "--rep", "1").splitlines()[-1])
    assert out["engine"] == "n-body" and out["hot_loop"]["flops"] > 0 and out["iterations"]["sum"] > 0
