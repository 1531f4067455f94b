"""MkDocs hook: add files that live outside `docs/` to the site, unchanged.

- `notebooks/*.ipynb` as `notebooks/*.ipynb` (rendered by mkdocs-jupyter, which must see
  them: hence the priority);
- the committed reproduction report `experiments/output/REPRODUCTION.md` as
  `reproduction/report.md`, with the figures of `experiments/output/` under `reproduction/`,
  so that its relative links (`fig05.png`) hold as they are;
- `experiments/REPRODUCTION.md` (other papers' results) as `reproduction/REPRODUCTION.md`, where the
  link of `experiments/README.md` (included in `reproduction/index.md`) finds it.
"""

from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files


ROOT = Path(__file__).resolve().parent.parent

NOTEBOOKS = "notebooks/*.ipynb"
"""Notebooks, at the same path in the site as in the repository."""

MOVED = {
    "reproduction/report.md": "experiments/output/REPRODUCTION.md",
    "reproduction/REPRODUCTION.md": "experiments/REPRODUCTION.md",  # other papers' results (capsule robots)
}
"""Site path: source file (relative to the repository root)."""

MOVED_FOLDERS = {"reproduction": ("experiments/output", "**/*.png")}
"""Site folder: (source folder, glob)."""


@event_priority(100)  # before mkdocs-jupyter (priority 0) turns notebooks into pages
def on_files(files: Files, config) -> Files:
    for path in sorted(ROOT.glob(NOTEBOOKS)):
        # A real source folder (the repository root), not `File.generated`: mkdocs-jupyter
        # reads the notebook through `abs_src_path`, which a generated file does not have.
        uri = path.relative_to(ROOT).as_posix()
        urls = config.use_directory_urls
        files.append(File(uri, src_dir=str(ROOT), dest_dir=config.site_dir, use_directory_urls=urls))
    moved = dict(MOVED)
    for dest, (src, pattern) in MOVED_FOLDERS.items():
        for path in sorted((ROOT / src).glob(pattern)):
            moved[f"{dest}/{path.relative_to(ROOT / src).as_posix()}"] = path.relative_to(ROOT).as_posix()
    for uri, src in moved.items():
        files.append(File.generated(config, uri, abs_src_path=str(ROOT / src)))
    return files
