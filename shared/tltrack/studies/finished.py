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
back on the machine that ran it is bit for bit the sweep that ran. A file that cannot be read, or
whose content does not fit the sweep, is run again with a warning.

A file made on another machine (another CPU, or other versions of the numerical libraries) has
another name, but it also records the sweep's digest without the environment. When no file of
this machine's name is there, one of the same sweep made elsewhere is read back, with a warning:
its runs are the same code's with the same seeds, equal in distribution, but not bit for bit what
this machine would compute (the manoeuvres study's first 8 sweeps, made on two CPUs, differ by
at most 1.3e-10 m of run RMSE: ``papers/manoeuvres/other_machine.py``). Delete it to run the
sweep here instead.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tltrack.config import Config
from tltrack.engine.checkpoint import Checkpoint, environment
from tltrack.engine.montecarlo import FilterResult

Results = dict[str, FilterResult]
FORMAT = 1  #: the files' layout; another is run again


class Finished:
    """The file of the sweep of ``cfgs`` and ``names`` in batches of ``batch_size`` in ``folder``:
    :meth:`load` it when the sweep has finished here or elsewhere, :meth:`save` it when it has."""

    def __init__(
        self,
        folder: Path,
        cfgs: Sequence[Config],
        names: Sequence[str],
        batch_size: int,
        timed: bool,
    ) -> None:
        checkpoint = Checkpoint(folder, cfgs, names)
        runs = range(cfgs[0].runs)
        tail = f"-b{batch_size}{'-timed' if timed else ''}"
        key = checkpoint.path(runs).stem.removeprefix("batch-")
        self.file = Path(folder) / f"sweep-{key}{tail}.json"
        # the digest of the file's name without the environment: the batches' own, read whole
        # so that no field is missed (Checkpoint should say it; its code is in every digest)
        sweep = json.loads(checkpoint._sweep)
        del sweep["environment"]
        what = f"{json.dumps(sweep, sort_keys=True)}|{list(runs)}|{tail}"
        self.key = hashlib.sha256(what.encode()).hexdigest()[:24]
        self.cfgs = cfgs

    def load(self) -> list[Results] | None:
        """The sweep's results, or None when it has not finished (or its file does not fit)."""
        if self.file.exists():
            return self._results(self.file)
        for other in sorted(self.file.parent.glob("sweep-*.json")):
            try:
                doc = json.loads(other.read_text(encoding="utf-8"))
                made = doc["made"]
            except (OSError, ValueError, KeyError, TypeError):
                continue  # not this sweep's, or warned of when its own sweep reads it
            if not isinstance(made, dict) or made.get("key") != self.key:
                continue
            theirs, mine = made.get("environment", {}), environment()
            differ = ", ".join(k for k in mine if k in theirs and theirs[k] != mine[k])
            unknown = "".join(f", {k} unknown" for k in mine if k not in theirs)
            cpu = f"CPU {theirs.get('cpu', 'unknown')}, here {mine['cpu']}"
            warnings.warn(
                f"{other.name}: this sweep, made in another environment ({differ} differ"
                f"{unknown}; {cpu}): read back, the same code and seeds but not bit for bit what "
                "this machine computes",
                stacklevel=2,
            )
            return self._results(other, doc)
        return None

    def _results(self, file: Path, doc: Any = None) -> list[Results] | None:
        """The results in ``doc`` (by default ``file``'s JSON), checked against the sweep."""
        try:
            if doc is None:
                doc = json.loads(file.read_text(encoding="utf-8"))
            if doc["format"] != FORMAT or len(doc["results"]) != len(self.cfgs):
                raise ValueError(f"format {doc['format']}, {len(doc['results'])} configurations")
            out = [
                {name: FilterResult(**fields) for name, fields in part.items()}
                for part in doc["results"]
            ]
            runs = {len(r.run_rmse) for part in out for r in part.values()}
            if runs != {self.cfgs[0].runs}:
                raise ValueError(f"{sorted(runs)} runs, not {self.cfgs[0].runs}")
        except (OSError, ValueError, KeyError, TypeError) as err:
            warnings.warn(f"{file}: unreadable ({err}); running its sweep again", stacklevel=3)
            return None
        return out

    def save(self, results: Sequence[Results]) -> None:
        """Write the sweep's results whole (a temporary file, synced, then renamed); a failure
        warns and loses nothing but the file."""
        doc: dict[str, Any] = {
            "format": FORMAT,
            "made": {"key": self.key, "environment": environment()},
            "results": [{n: dataclasses.asdict(r) for n, r in part.items()} for part in results],
        }
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(dir=self.file.parent, prefix=".tmp-", suffix=".json")
            os.fchmod(fd, 0o644)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(doc, f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.file)
        except OSError as err:
            if tmp:
                Path(tmp).unlink(missing_ok=True)
            warnings.warn(f"{self.file}: cannot save the finished sweep ({err})", stacklevel=2)
