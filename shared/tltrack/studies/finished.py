"""Finished sweeps kept whole, small enough to carry to another session or machine.

A study of hours runs one :func:`~tltrack.engine.montecarlo.run_sweep` per configuration (or per
group of them). Its checkpoint folder (:mod:`tltrack.engine.checkpoint`) keeps every finished
batch, about 120 kB each: a 1000-run study of 16 configurations leaves some 90 MB, too much to
carry in a repository. When a sweep is over, its results are also written to the same folder as
one JSON file (``sweep-<key>.json``, about 250 kB for 6 filters of 1200 steps and 1000 runs), and
a later call reads that file instead of the sweep's batches. Copying or committing the
``sweep-*.json`` files alone carries every finished sweep; the study then runs only the others.

The file is named by the batch file the whole sweep would have as one batch (the same digest of
configurations, filters, code and environment, see :mod:`tltrack.engine.checkpoint`), the batch
size and whether a run was timed: the two that change a result's last bit or its fields. It
holds plain JSON, no pickle, and Python's floats round-trip through it exactly, so a sweep read
back is bit for bit the sweep that ran. A file that cannot be read, or whose content does not fit
the sweep, is run again with a warning.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tltrack.config import Config
from tltrack.engine.checkpoint import Checkpoint
from tltrack.engine.montecarlo import FilterResult

Results = dict[str, FilterResult]
FORMAT = 1  #: the files' layout; another is run again


def path(
    folder: Path, cfgs: Sequence[Config], names: Sequence[str], batch_size: int, timed: bool
) -> Path:
    """The file of the sweep of ``cfgs`` and ``names`` in batches of ``batch_size``."""
    whole = Checkpoint(folder, cfgs, names).path(range(cfgs[0].runs))
    key = whole.stem.removeprefix("batch-")
    return Path(folder) / f"sweep-{key}-b{batch_size}{'-timed' if timed else ''}.json"


def load(file: Path, cfgs: Sequence[Config]) -> list[Results] | None:
    """The sweep's results, or None when it has not finished (or its file does not fit)."""
    if not file.exists():
        return None
    try:
        doc = json.loads(file.read_text(encoding="utf-8"))
        if doc["format"] != FORMAT or len(doc["results"]) != len(cfgs):
            raise ValueError(f"format {doc['format']}, {len(doc['results'])} configurations")
        out = [
            {name: FilterResult(**fields) for name, fields in part.items()}
            for part in doc["results"]
        ]
        runs = {len(r.run_rmse) for part in out for r in part.values()}
        if runs != {cfgs[0].runs}:
            raise ValueError(f"{sorted(runs)} runs, not {cfgs[0].runs}")
    except (OSError, ValueError, KeyError, TypeError) as err:
        warnings.warn(f"{file}: unreadable ({err}); running its sweep again", stacklevel=2)
        return None
    return out


def save(file: Path, results: Sequence[Results]) -> None:
    """Write the sweep's results whole (a temporary file, synced, then renamed); a failure warns
    and loses nothing but the file."""
    doc: dict[str, Any] = {
        "format": FORMAT,
        "results": [{n: dataclasses.asdict(r) for n, r in part.items()} for part in results],
    }
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=file.parent, prefix=".tmp-", suffix=".json")
        os.fchmod(fd, 0o644)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(doc, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, file)
    except OSError as err:
        if tmp:
            Path(tmp).unlink(missing_ok=True)
        warnings.warn(f"{file}: cannot save the finished sweep ({err})", stacklevel=2)
