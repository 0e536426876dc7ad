"""Finished sweeps kept whole, small enough to carry to another session or machine.

A study of hours runs one :func:`~tltrack.engine.montecarlo.run_sweep` per configuration (or per
group of them). Its checkpoint folder (:mod:`tltrack.engine.checkpoint`) keeps every finished
batch, about 120 kB each: a 1000-run study of 16 configurations leaves some 90 MB, too much to
carry in a repository. When a sweep is over, its results are also written to the same folder as
one JSON file (``sweep-<key>.json``, about 250 kB for 6 filters of 1200 steps and 1000 runs), and
a later call reads that file instead of the sweep's batches. Copying or committing the
``sweep-*.json`` files alone carries every finished sweep; the study then runs only the others.

The file is named by the key the whole sweep would have as one batch
(:meth:`~tltrack.engine.checkpoint.Checkpoint.key`: the same digest of configurations, filters,
code and environment as its batch files), the batch size and whether a run was timed: the two
that change a result's last bit or its fields. It holds plain JSON, no pickle, and Python's
floats round-trip through it exactly, so a sweep read back on the machine that ran it is bit for
bit the sweep that ran. A file that cannot be read, or whose content does not fit the sweep, is
run again with a warning.

A file made on another machine (another CPU, or other versions of the numerical libraries) has
another name, but it also records the sweep's digest without the environment. When no file of
this machine's name is there, one of the same sweep made elsewhere is read back, with a warning
(:func:`~tltrack.engine.checkpoint.made_elsewhere`): its runs are the same code's with the same
seeds, equal in distribution, but not bit for bit what this machine would compute (the
manoeuvres study's first 8 sweeps, made on two CPUs, differ by at most 1.3e-10 m of run RMSE:
``papers/manoeuvres/other_machine.py``). Delete it to run the sweep here instead.

A sweep that has not finished carries over by its prefix file instead
(:mod:`tltrack.engine.checkpoint`): the merged statistics of its first batches.
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter

from tltrack.config import Config
from tltrack.engine.checkpoint import Checkpoint, environment, made_elsewhere, write_whole
from tltrack.engine.montecarlo import FilterResult

Results = dict[str, FilterResult]
#: a filter's results from a file: each field of its type (ValidationError, a ValueError)
_RESULT = TypeAdapter(FilterResult)
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
        self.file = Path(folder) / f"sweep-{checkpoint.key(runs)}{tail}.json"
        #: the digest of the file's name without the environment, to be found from elsewhere
        self.key = checkpoint.key(runs, machine=False, also=tail)
        self.cfgs = cfgs

    def load(self) -> list[Results] | None:
        """The sweep's results, or None when it has not finished (or its file does not fit)."""
        if self.file.exists():
            return self._results(self.file)
        found = made_elsewhere(self.file.parent, "sweep-*.json", self.key)
        return None if found is None else self._results(*found)

    def _results(self, file: Path, doc: Any = None) -> list[Results] | None:
        """The results in ``doc`` (by default ``file``'s JSON), checked against the sweep."""
        try:
            if doc is None:
                doc = json.loads(file.read_text(encoding="utf-8"))
            if doc["format"] != FORMAT or len(doc["results"]) != len(self.cfgs):
                raise ValueError(f"format {doc['format']}, {len(doc['results'])} configurations")
            out = [
                {name: _RESULT.validate_python(fields) for name, fields in part.items()}
                for part in doc["results"]
            ]
            runs = {len(r.run_rmse) for part in out for r in part.values()}
            if runs != {self.cfgs[0].runs}:
                raise ValueError(f"{sorted(runs)} runs, not {self.cfgs[0].runs}")
        except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
            why = "nested too deeply" if isinstance(err, RecursionError) else err
            warnings.warn(f"{file}: unreadable ({why}); running its sweep again", stacklevel=3)
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
        try:
            write_whole(self.file, lambda f: f.write(json.dumps(doc)), binary=False)
        except OSError as err:
            warnings.warn(f"{self.file}: cannot save the finished sweep ({err})", stacklevel=2)
