"""The figures write only into their output directory: no copy of the report elsewhere."""

from pathlib import Path

from locomotion_jax.paper._figures import DEFAULT_OUT, write_reports


def test_report_is_written_only_into_out(tmp_path, monkeypatch):
    # The scripts' default, like the CLI's `figures --out` default, is relative to the working
    # directory (from the repository root: the committed reference figures).
    assert DEFAULT_OUT == Path("experiments/output")
    monkeypatch.chdir(tmp_path)
    DEFAULT_OUT.mkdir(parents=True)
    assert write_reports(DEFAULT_OUT) == [DEFAULT_OUT / "REPRODUCTION.md"]
    out = tmp_path / "elsewhere"
    assert write_reports(out) == [out / "REPRODUCTION.md"]
    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file())
    assert written == ["elsewhere/REPRODUCTION.md", "experiments/output/REPRODUCTION.md"]


def test_a_figure_run_writes_only_into_out(tmp_path, monkeypatch):
    """`run_figures` (the `figures` command) on one quick figure, from another working directory:
    every file it writes is under `out`, and the repository's tracked files are as before (untracked ones
    are left out: tests running beside it may write some)."""
    import subprocess

    from locomotion_jax.paper._figures import run_figures

    root = Path(__file__).resolve().parents[1]
    git = ["git", "status", "--porcelain", "--untracked-files=no"]
    in_git = (root / ".git").exists()  # a clone (an unpacked sdist has no history to compare)
    status = lambda: subprocess.run(git, cwd=root, capture_output=True, text=True).stdout if in_git else ""
    before = status()
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    paths = run_figures(["4b"], quick=True, out=out)
    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file())
    assert written and all(name.startswith("out/") for name in written), written
    assert {p.relative_to(tmp_path).as_posix() for p in paths} <= set(written)
    assert {"out/fig04b.png", "out/fig04b.nc", "out/REPRODUCTION.md"} <= set(written)
    assert status() == before
