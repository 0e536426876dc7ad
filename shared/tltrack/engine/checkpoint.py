"""Batches that outlive their process: a sweep of hours resumes where it stopped.

:func:`tltrack.engine.montecarlo.run_sweep` cuts the runs into batches and merges their
statistics in batch order. Given a folder, it also writes each finished batch's statistics there,
one file per batch, and on the next call reads back every batch it finds instead of running it
again. The merged result is then bit for bit that of one uninterrupted call: a batch's statistics
depend on its runs alone (every random number comes from a per-(seed, run, purpose) stream), and
the merge's order is the batches' order either way.

A batch's file is named by a digest of all that determines its statistics: the configurations
(all but ``runs``, so a 1000-run sweep reuses the batches of a 200-run one made with the same batch
size), the filters, the batch's runs, and the code of the packages that compute them (models,
filters, config, engine; their comments and docstrings aside). Any other change names other
files: a stale batch is never read, it is run again. Files are written whole or not at all (a
temporary file, then a rename), so a process killed mid-write leaves nothing half-read; one that
cannot be read is run again, with a warning. They are pickles: resume only from a folder that you
wrote.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import os
import pickle
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tltrack.config import Config

#: the packages whose source decides a batch's numbers
NUMERICAL = ("models", "filters", "config", "engine")


@functools.cache
def code_digest() -> str:
    """A digest of the numerical packages' code (:data:`NUMERICAL`): their syntax trees without
    docstrings, so that a comment or a docstring changed keeps a checkpoint, and code does not."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for pkg in NUMERICAL:
        for path in sorted((root / pkg).rglob("*.py")):
            tree = ast.parse(path.read_bytes())
            for node in ast.walk(tree):
                body = getattr(node, "body", None)
                if (
                    isinstance(body, list)
                    and body
                    and isinstance(body[0], ast.Expr)
                    and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)
                ):
                    node.body = body[1:] or [ast.Pass()]  # type: ignore[attr-defined]
            h.update(path.relative_to(root).as_posix().encode())
            h.update(ast.dump(tree).encode())
    return h.hexdigest()


class Checkpoint:
    """One sweep's batches in ``folder``: :meth:`load` the ones done, :meth:`save` each new one."""

    def __init__(self, folder: Path, cfgs: Sequence[Config], names: Sequence[str]) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        what = {
            "configs": [c.model_dump(mode="json", exclude={"runs"}) for c in cfgs],
            "filters": list(names),
            "code": code_digest(),
        }
        self._sweep = json.dumps(what, sort_keys=True)

    def path(self, runs: Sequence[int]) -> Path:
        """The file of the batch of ``runs``."""
        key = hashlib.sha256(f"{self._sweep}|{list(runs)}".encode()).hexdigest()[:24]
        return self.folder / f"batch-{key}.pkl"

    def load(self, runs: Sequence[int]) -> Any | None:
        """The batch's statistics, or None when it has not run (or its file cannot be read)."""
        path = self.path(runs)
        if not path.exists():
            return None
        try:
            with path.open("rb") as f:
                sweep, saved_runs, stats = pickle.load(f)
        except Exception as err:  # truncated, or not ours: run the batch again
            warnings.warn(f"{path}: unreadable ({err}); running its batch again", stacklevel=2)
            return None
        if sweep != self._sweep or saved_runs != list(runs):  # a digest collision, in theory
            return None
        return stats

    def save(self, runs: Sequence[int], stats: Any) -> None:
        """Write the batch's statistics whole: to a temporary file, then renamed."""
        path = self.path(runs)
        fd, tmp = tempfile.mkstemp(dir=self.folder, prefix=".tmp-", suffix=".pkl")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump((self._sweep, list(runs), stats), f, pickle.HIGHEST_PROTOCOL)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
