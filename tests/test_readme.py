"""The README as a landing page: its links resolve, its test command is the one CI runs, and
its example prints what the README says it prints."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _block(lang: str, after: str) -> str:
    """The first fenced block of `lang` after the heading or text `after`."""
    match = re.search(rf"```{lang}\n(.*?)```", README[README.index(after) :], re.S)
    assert match is not None, f"no {lang} block after {after!r}"
    return match.group(1)


def test_readme_is_short_and_its_links_resolve():
    assert len(README.splitlines()) <= 250
    links = re.findall(r"\]\(([^)\s]+)\)", README)
    local = [link.split("#")[0] for link in links if not re.match(r"[a-z]+:", link)]
    assert len(local) >= 10
    missing = [link for link in local if not (ROOT / link).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_readme_test_command_is_the_one_ci_runs():
    commands = _block("bash", "## Two commands")
    ci = (ROOT / ".ci" / "run").read_text()
    test_command = ci.split("# The README's test command:\n")[1].strip()
    assert commands.rstrip().endswith(test_command)
    assert "locomotion-jax figures --out out/figures" in commands
    assert "/out/" in (ROOT / ".gitignore").read_text().split()  # the figures' folder is not tracked


@pytest.mark.slow  # the exact engine, a steady gait and an optimisation (5 to 12 minutes on 2 cores)
def test_readme_example_prints_what_the_readme_says(tmp_path):
    code = _block("python", "## A robot, its measurement")
    expected = _block("text", "## A robot, its measurement")
    env = dict(os.environ, LOCOMOTION_JAX_CACHE_DIR=str(tmp_path / "cache"))
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1800
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout == expected
