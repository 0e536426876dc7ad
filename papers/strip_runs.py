"""Take the per-run arrays (``run_rmse``) out of results files, so that the summaries can be
committed: each FILE (or every ``*.json`` under a DIR, but for a checkpoint folder's, which the
engine reads back whole) that holds a ``run_rmse`` keeps everything else, and the untouched
original goes to ``<name>.full.json`` beside it, which git ignores (papers/.gitignore).
``scripts/long_runs.sh`` runs it after every job.

    .venv/bin/python papers/strip_runs.py papers/rpf/results/presets [FILE_OR_DIR ...]

The committed files' arrays are in the history: ``git show 68d1365:papers/<study>/results/...``
(papers/README.md, "Per-run arrays").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

KEY = "run_rmse"


def without_runs(doc: Any) -> tuple[Any, bool]:
    """``doc`` with every ``run_rmse`` removed, and whether there was one."""
    if isinstance(doc, dict):
        found = KEY in doc
        out = {}
        for k, v in doc.items():
            if k == KEY:
                continue
            out[k], sub = without_runs(v)
            found = found or sub
        return out, found
    if isinstance(doc, list):
        items = [without_runs(v) for v in doc]
        return [v for v, _ in items], any(f for _, f in items)
    return doc, False


def strip(path: Path) -> bool:
    text = path.read_text()
    doc, found = without_runs(json.loads(text))
    if not found:
        return False
    path.with_name(path.stem + ".full.json").write_text(text)
    path.write_text(json.dumps(doc, indent=1, allow_nan=True))
    return True


def main(args: list[str]) -> None:
    if not args or args[0] in ("-h", "--help"):
        print(__doc__)
        return
    for arg in map(Path, args):
        files = sorted(arg.rglob("*.json")) if arg.is_dir() else [arg]
        # a checkpoint's sweep files are read back by the engine, run_rmse and all
        for f in (f for f in files if "checkpoint" not in f.parts):
            if not f.name.endswith(".full.json") and strip(f):
                print(f"stripped {f} (original: {f.stem}.full.json)")


if __name__ == "__main__":
    main(sys.argv[1:])
