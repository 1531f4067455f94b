"""The mutation check (`tests/mutations.py`) stays applicable as code moves: every deliberate bug
still edits text that occurs exactly once in its file, and names tests that exist. Running the
mutations themselves takes minutes each and is done by hand (docs/development.md)."""

import re
from pathlib import Path

import mutations
import pytest


ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("m", mutations.MUTATIONS, ids=lambda m: m.name)
def test_mutation_applies_and_names_existing_tests(m, tmp_path):
    (tmp_path / Path(m.path).parent).mkdir(parents=True)
    (tmp_path / m.path).write_text((ROOT / m.path).read_text())
    mutations._apply(tmp_path, m)
    assert (tmp_path / m.path).read_text() != (ROOT / m.path).read_text()
    for test in m.tests:
        path, _, name = test.partition("::")
        source = (ROOT / path).read_text()
        if name:
            function = name.split("[")[0]
            assert re.search(rf"^def {re.escape(function)}\(", source, re.M), f"{m.name}: no test {test}"


def test_mutation_names_are_unique():
    names = [m.name for m in mutations.MUTATIONS]
    assert len(names) == len(set(names))
