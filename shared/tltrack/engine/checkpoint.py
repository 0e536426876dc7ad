"""Batches that outlive their process: a sweep of hours resumes where it stopped.

:func:`tltrack.engine.montecarlo.run_sweep` cuts the runs into batches and merges their
statistics in batch order. Given a folder, it also writes each finished batch's statistics there,
one file per batch, and on the next call reads back every batch it finds instead of running it
again. The merged result is then bit for bit that of one uninterrupted call: a batch's statistics
depend on its runs alone (every random number comes from a per-(seed, run, purpose) stream), and
the merge's order is the batches' order either way.

A batch's file is named by a digest of all that determines its statistics on this machine:

- the configurations, all but ``runs`` (so a 1000-run sweep reuses the batches of a 200-run one
  made with the same batch size), and the bytes of a recorded truth's file, which name it instead
  of its path (the same file copied to another folder or name keeps the batches);
- the filters and the batch's runs;
- the code that computes them: the syntax trees of the packages ``models``, ``filters``,
  ``config`` and ``engine`` and of ``declare.py``, without their docstrings (a comment or a
  docstring edited keeps the batches), but for the modules that compute none of a batch's numbers
  (:data:`BESIDE`: this one, the Dask pool's, its workers' preload and the plots), and the source
  of any plugin kind that is registered;
- the environment that can change the last bit (see :doc:`/howto/dask`): the versions of Python,
  NumPy, SciPy, numba and llvmlite, the CPU that numba compiles for and its features, and
  ``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES``, ``NPY_DISABLE_CPU_FEATURES``, ``OPENBLAS_CORETYPE``.

Any other change names other files: a stale batch is never read, it is run again. Files are
written whole or not at all (:func:`~tltrack.engine.checkpoint.write_whole`: a temporary file,
synced, then renamed), so a process killed mid-write leaves nothing half-read; a file that cannot
be read is run again, with a warning. A folder that cannot be written is refused before any batch
runs; a save that fails later (a full disk) warns once and the sweep goes on without its
checkpoint.

The files it writes in the folder:

- ``batch-<key>.pkl``, one per finished batch, ``key`` the digest of its runs
  (:meth:`~tltrack.engine.checkpoint.Checkpoint.key`). They are pickles: resume only from a folder
  that you wrote.
- ``prefix-<key>-b<batch size>.json``, one per sweep and batch size, ``key`` the digest of the
  sweep without its run count: the merged statistics of its first full batches, up to the first
  one not yet finished, rewritten as that prefix grows. A longer sweep goes on from a shorter
  one's (1000 runs from 200), since their first batches are the same. Plain JSON (Python's
  floats round-trip through it exactly), small enough to commit: with it alone a sweep resumes
  after its prefix, bit for bit, when the batch files are gone (another session). It also
  records the sweep's digest without the environment and the environment it was made in: a
  prefix of the same sweep made elsewhere (another CPU, other library versions) is read, with a
  warning, when it holds more batches than this machine's (a sweep carried across machines
  leaves one file per machine), and the prefixes that continue it keep saying so.

:mod:`tltrack.studies.finished` keeps a whole finished sweep in the same folder, named alike.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import hashlib
import inspect
import json
import os
import pickle
import platform
import tempfile
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

from tltrack.config import Config

#: the package's folder
PACKAGE = Path(__file__).resolve().parents[1]
#: the packages whose code decides a batch's numbers
NUMERICAL = ("models", "filters", "config", "engine")
#: the declarations that they build on (parameters, registries)
DECLARE = "declare.py"
#: modules of those packages that store, distribute or draw results and compute none of a
#: batch's numbers: an edit to them keeps every file (a table of many sessions outlives edits)
BESIDE = ("engine/checkpoint.py", "engine/cluster.py", "engine/dask_preload.py", "engine/plots.py")
#: environment variables that change which machine code numba and NumPy run
CPU_VARIABLES = (
    "NUMBA_CPU_NAME",
    "NUMBA_CPU_FEATURES",
    "NPY_DISABLE_CPU_FEATURES",
    "OPENBLAS_CORETYPE",
)
#: the layout of a prefix file; another is ignored
PREFIX_FORMAT = 1


def _tree(source: bytes) -> str:
    """A module's syntax tree without its docstrings."""
    tree = ast.parse(source)
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
    return ast.dump(tree)


@functools.cache
def code_digest(root: Path = PACKAGE) -> str:
    """A digest of the numerical packages' code (:data:`NUMERICAL`, :data:`DECLARE`) under
    ``root``, but for the modules :data:`BESIDE` them."""
    paths = [root / DECLARE] + [p for pkg in NUMERICAL for p in sorted((root / pkg).rglob("*.py"))]
    # an editor's lock file (.#x.py) is no source; nor is a declare.py that is not there
    paths = [p for p in paths if not p.name.startswith(".") and p.is_file()]
    paths = [p for p in paths if p.relative_to(root).as_posix() not in BESIDE]
    h = hashlib.sha256()
    for path in paths:
        h.update(path.relative_to(root).as_posix().encode())
        h.update(_tree(path.read_bytes()).encode())
    if not paths:
        raise RuntimeError(f"no source under {root} to digest: a checkpoint needs tltrack's .py")
    return h.hexdigest()


def plugin_digest() -> str:
    """A digest of the source of every registered kind defined outside tltrack (plugins)."""
    from tltrack.filters.kinds import FILTERS
    from tltrack.models.kinds import MOTIONS, SENSORS

    h = hashlib.sha256()
    for registry in (SENSORS, MOTIONS, FILTERS):
        for name in [*registry.names(), *registry.imported.values()]:
            cls = registry.get(name)
            module = getattr(cls, "__module__", "")
            if module.split(".")[0] == "tltrack":
                continue
            h.update(f"{name}={module}:{getattr(cls, '__qualname__', '')}".encode())
            with contextlib.suppress(OSError, TypeError):  # no source: its name alone
                h.update(Path(inspect.getsourcefile(cls) or "").read_bytes())
    return h.hexdigest()


@functools.cache
def environment() -> dict[str, Any]:
    """What besides the code can change a batch's last bit on this machine: numba compiles for
    the host's CPU unless ``NUMBA_CPU_NAME`` says otherwise, NumPy picks its loops by the CPU's
    features."""
    import llvmlite
    import llvmlite.binding as ll
    import numba
    import numpy
    import scipy

    return {
        "python": platform.python_version(),
        "versions": [m.__version__ for m in (numpy, scipy, numba, llvmlite)],
        "cpu": ll.get_host_cpu_name(),
        "features": ll.get_host_cpu_features().flatten(),
        "variables": {v: os.environ.get(v) for v in CPU_VARIABLES},
    }


def _truth_digest(cfg: Config) -> str | None:
    """The digest of a recorded truth's file, which the configuration names only by its path."""
    return hashlib.sha256(Path(cfg.truth_file).read_bytes()).hexdigest() if cfg.truth_file else None


def write_whole(path: Path, write: Callable[[IO[Any]], object], *, binary: bool) -> None:
    """Write ``path`` whole or not at all: ``write`` fills a temporary file in the same folder
    (mode 644, binary or UTF-8 text), which is flushed, synced and renamed over ``path``. On any
    error the temporary file is removed and the error raised: ``path`` is the old file or the new
    one, never half of it."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    try:
        with os.fdopen(fd, "wb" if binary else "w", encoding=None if binary else "utf-8") as f:
            os.fchmod(f.fileno(), 0o644)
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _differences(theirs: Any) -> str:
    """How the environment ``theirs`` (as :func:`environment` recorded it elsewhere) differs
    from this one: "cpu, versions differ, features unknown; CPU znver3, here rocketlake"."""
    theirs = theirs if isinstance(theirs, dict) else {}
    mine = environment()
    differ = ", ".join(k for k in mine if k in theirs and theirs[k] != mine[k])
    unknown = "".join(f", {k} unknown" for k in mine if k not in theirs)
    return f"{differ} differ{unknown}; CPU {theirs.get('cpu', 'unknown')}, here {mine['cpu']}"


def _same_sweep(
    folder: Path, pattern: str, key: str, besides: Path | None = None
) -> list[tuple[Path, Any]]:
    """Every file of ``folder.glob(pattern)`` (by name) but ``besides`` (read already) whose JSON
    records ``made.key == key`` (a digest without the environment, :meth:`Checkpoint.key`), with
    its document. Files that cannot be read are skipped here: their own sweep warns of them."""
    found = []
    for other in sorted(Path(folder).glob(pattern)):
        if other == besides:
            continue
        try:
            doc = json.loads(other.read_text(encoding="utf-8"))
            made = doc["made"]
        except (OSError, ValueError, KeyError, TypeError, RecursionError):
            continue  # not this sweep's, or warned of when its own sweep reads it
        if isinstance(made, dict) and made.get("key") == key:
            found.append((other, doc))
    return found


def _warn_elsewhere(path: Path, made: Any, what: str, stacklevel: int = 4) -> None:
    """A file of this sweep made in another environment is read: say what differs. Its numbers
    are the same code's with the same seeds, equal in distribution, but not bit for bit what this
    machine computes."""
    warnings.warn(
        f"{path.name}: {what}, made in another environment "
        f"({_differences(made.get('environment'))}): read back, the same code and seeds but "
        "not bit for bit what this machine computes",
        stacklevel=stacklevel,
    )


def made_elsewhere(
    folder: Path, pattern: str, key: str, what: str = "this sweep"
) -> tuple[Path, Any] | None:
    """The first file of ``folder.glob(pattern)`` (by name) of this sweep (:func:`_same_sweep`)
    and its document, read with a warning (it was made in another environment, else it would
    have this machine's name); or None."""
    found = _same_sweep(folder, pattern, key)
    if not found:
        return None
    _warn_elsewhere(found[0][0], found[0][1]["made"], what)
    return found[0]


def full_batches(batches: Sequence[Sequence[int]]) -> int:
    """How many of ``batches`` (runs in order, cut into batches of the first one's size) are
    full: all but a short last one."""
    return len(batches) - (len(batches[-1]) < len(batches[0]))


def writable(folder: Path) -> None:
    """Make ``folder`` and write a file in it, or raise :class:`OSError`: a checkpoint that
    cannot be kept is refused before any batch runs, not hours later."""
    folder.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=folder, prefix=".tmp-")
    os.close(fd)
    os.unlink(name)


class Checkpoint:
    """One sweep's batches in ``folder``: :meth:`load` the ones done, :meth:`save` each new one;
    :meth:`load_prefix` and :meth:`save_prefix` the merged statistics of its first batches."""

    def __init__(self, folder: Path, cfgs: Sequence[Config], names: Sequence[str]) -> None:
        self.folder = Path(folder)
        writable(self.folder)
        what = {
            # a recorded truth by its bytes, not its path: the path digested as None, as it is
            # for a sweep without a truth file (whose names this keeps)
            "configs": [
                {**c.model_dump(mode="json", exclude={"runs"}), "truth_file": None} for c in cfgs
            ],
            "truth_files": [_truth_digest(c) for c in cfgs],
            "filters": list(names),
            "code": code_digest(),
            "plugins": plugin_digest(),
            "environment": environment(),
        }
        self._sweep = json.dumps(what, sort_keys=True)
        del what["environment"]
        self._anywhere = json.dumps(what, sort_keys=True)
        self._saving = True
        self._saving_prefix = True  # not over a longer sweep's prefix
        #: the environments, other than this one, that made batches of the prefix read
        self._elsewhere: list[Any] = []

    def key(self, runs: Sequence[int], machine: bool = True, also: str = "") -> str:
        """The 24 hex digits that name ``runs`` of this sweep: with ``machine``, on this machine
        (its environment is in the digest: a batch file's name), else on any (what a file made
        elsewhere records to be found). ``also``, when given, is digested after the runs."""
        what = f"{self._sweep if machine else self._anywhere}|{list(runs)}"
        if also:
            what += f"|{also}"
        return hashlib.sha256(what.encode()).hexdigest()[:24]

    def path(self, runs: Sequence[int]) -> Path:
        """The file of the batch of ``runs``."""
        return self.folder / f"batch-{self.key(runs)}.pkl"

    def load(self, runs: Sequence[int]) -> Any | None:
        """The batch's statistics, or None when it has not run (or its file cannot be read)."""
        path = self.path(runs)
        if not path.exists():
            return None
        try:
            with path.open("rb") as f:
                sweep, saved_runs, stats = pickle.load(f)
        except Exception as err:  # cut short by a crash, or not ours: run the batch again
            warnings.warn(f"{path}: unreadable ({err}); running its batch again", stacklevel=2)
            return None
        if sweep != self._sweep or saved_runs != list(runs):  # a digest collision, in theory
            return None
        return stats

    def save(self, runs: Sequence[int], stats: Any) -> None:
        """Write the batch's statistics whole (:func:`write_whole`). A failure (a full disk)
        warns once and stops saving; the sweep's numbers are unaffected."""
        what = (self._sweep, list(runs), stats)
        self._write(self.path(runs), lambda f: pickle.dump(what, f, pickle.HIGHEST_PROTOCOL), True)

    def prefix_path(self, batch_size: int) -> Path:
        """The prefix file of this sweep's first batches of ``batch_size`` runs. The run count is
        not in its name: a 1000-run sweep goes on from a 200-run one's prefix."""
        key = self.key([], also=f"prefix-b{batch_size}")
        return self.folder / f"prefix-{key}-b{batch_size}.json"

    def _prefix_key(self, batch_size: int) -> str:
        """The digest of the prefix without the environment, to be found from elsewhere."""
        return self.key([], machine=False, also=f"prefix-b{batch_size}")

    def load_prefix(
        self, batches: Sequence[Sequence[int]], decode: Callable[[Any, int], Any]
    ) -> tuple[int, Any] | None:
        """How many of ``batches`` the prefix read holds, and their merged statistics, which
        ``decode(plain, runs)`` makes of its plain JSON (raising ``ValueError``, ``KeyError`` or
        ``TypeError`` when they are not those of ``runs`` runs); None when there is none.

        A sweep carried across machines leaves one prefix file per machine, so the one that holds
        the most batches is read: this machine's file, or one of the same sweep made elsewhere,
        with a warning that says what differs. A file that cannot be read or does not fit the
        sweep warns and is ignored: the batches are read from their files, or run again. A prefix
        of more runs than this sweep's full batches (a longer sweep's) is neither used nor
        overwritten."""
        if not batches:
            return None
        bs, full = len(batches[0]), full_batches(batches)
        own, key = self.prefix_path(bs), self._prefix_key(bs)
        candidates: list[tuple[Path, Any]] = []
        if own.exists():
            try:
                candidates.append((own, json.loads(own.read_text(encoding="utf-8"))))
            except (OSError, ValueError, RecursionError) as err:
                self._unreadable(own, err)
        candidates += _same_sweep(self.folder, f"prefix-*-b{bs}.json", key, besides=own)
        usable: list[tuple[int, Path, Any]] = []  # (batches, file, document)
        for path, doc in candidates:
            try:
                if doc["format"] != PREFIX_FORMAT:
                    raise ValueError(f"format {doc['format']}")
                if doc["made"]["key"] != key:
                    raise ValueError("another sweep's")
                done = doc["batches"]
                if not isinstance(done, int) or done < 1:
                    raise ValueError(f"{done!r} batches")
                if not isinstance(doc["made"].get("environment"), dict):
                    raise ValueError("no environment it was made in")
            except (ValueError, KeyError, TypeError) as err:
                self._unreadable(path, err)
                continue
            if done <= full:
                usable.append((done, path, doc))
                continue
            if path == own:
                self._saving_prefix = False
            warnings.warn(
                f"{path.name}: the first {done * bs} runs of a longer sweep, more than this "
                f"one's {full * bs} in full batches; neither used nor overwritten",
                stacklevel=2,
            )
        if not usable:
            return None
        done, path, doc = max(usable, key=lambda u: u[0])  # the first of the longest: own first
        made = doc["made"]
        try:
            stats = decode(doc["stats"], done * bs)
            elsewhere = list(made.get("elsewhere", []))
        except (ValueError, KeyError, TypeError, IndexError, AttributeError) as err:
            self._unreadable(path, err)
            return None
        if path != own:
            _warn_elsewhere(path, made, "this sweep's first batches", stacklevel=3)
        if made["environment"] != environment():  # read from another machine's file
            elsewhere.append(made["environment"])
        # a sweep carried back to a machine it ran on before: only the others' batches differ
        others = [e for e in elsewhere if e != environment()]
        if others and path == own:
            warnings.warn(
                f"{path.name}: this sweep's first batches were made in another environment "
                f"({_differences(others[0])}): read back, the same code and seeds but not bit "
                "for bit what this machine computes",
                stacklevel=2,
            )
        self._elsewhere = elsewhere
        return done, stats

    def _unreadable(self, path: Path, err: Exception) -> None:
        warnings.warn(
            f"{path}: unreadable ({err}); ignored, its batches are read from their files or run "
            "again",
            stacklevel=3,
        )

    def save_prefix(self, batches: Sequence[Sequence[int]], done: int, stats: Any) -> None:
        """Write the merged statistics of the first ``done`` of ``batches``, as plain JSON
        ``stats``, whole (:func:`write_whole`); a failure warns once and stops saving. A prefix
        ending in a short last batch is not written: it would fit no longer sweep."""
        if not self._saving_prefix or done > full_batches(batches):
            return
        bs = len(batches[0])
        made: dict[str, Any] = {"key": self._prefix_key(bs), "environment": environment()}
        if self._elsewhere:  # the prefix read was made elsewhere: this one is partly so
            made["elsewhere"] = self._elsewhere
        doc = {"format": PREFIX_FORMAT, "made": made, "batches": done, "stats": stats}
        self._write(self.prefix_path(bs), lambda f: f.write(json.dumps(doc)), False)

    def _write(self, path: Path, write: Callable[[IO[Any]], object], binary: bool) -> None:
        """:func:`write_whole`, or after a failure a warning, once, and no more saving."""
        if not self._saving:
            return
        try:
            write_whole(path, write, binary=binary)
        except (OSError, ValueError, TypeError, AttributeError, pickle.PicklingError) as err:
            self._saving = False
            warnings.warn(
                f"checkpoint {self.folder}: cannot save ({err}); going on without it", stacklevel=3
            )
