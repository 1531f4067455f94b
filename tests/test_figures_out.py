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
