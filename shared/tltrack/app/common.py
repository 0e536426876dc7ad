"""What the ``tltrack`` commands share: the app, the console, progress bars, the engine's pool,
and the configuration built from a file and the options."""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from concurrent.futures import Executor
from contextlib import contextmanager
from datetime import timedelta
from pathlib import Path
from typing import Annotated, Any

import typer
from pydantic import ValidationError
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from tltrack.config import Config, ConfigError, DetectionSpec, describe_validation_error

app = typer.Typer(
    help="Bayesian transfer learning between tracking operators (TL-PF): experiments, "
    "the paper's figures, and the live dual tracker.",
    no_args_is_help=True,
    rich_markup_mode="markdown",
)
console = Console(stderr=True)


@app.callback()
def _plain_warnings() -> None:
    """A warning reads as one line to the user, not as Python's file, line and source."""
    warnings.formatwarning = _one_line


def _one_line(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    line: str | None = None,
) -> str:
    return f"warning: {message}\n"


def refused(err: ValueError) -> typer.Exit:
    """Print why a value was refused, a pydantic error one field a line, and the exit (status 2)
    to raise: ``raise refused(err) from None``."""
    said = describe_validation_error(err) if isinstance(err, ValidationError) else str(err)
    say_error(said)
    return typer.Exit(2)


def say_error(text: str) -> None:
    """Print ``text`` as an error, as written: rich would take a bracketed part of it (a
    pattern's ``[a-z0-9-]``, a list, a path) for markup and drop it."""
    console.print(f"[red]error:[/red] {escape(text)}")


def say_warning(text: str, label: str = "warning") -> None:
    """Print ``text`` after a yellow ``label``, as written (:func:`say_error`)."""
    console.print(f"[yellow]{label}:[/yellow] {escape(text)}")


#: how often a long job writes its progress when stderr is not a terminal [s]
LOG_EVERY_S = 60.0
#: runs counted this soon after a task starts were read back from a checkpoint, not run [s]
READ_BACK_S = 1.0


class LoggedProgress(Progress):
    """Rich's bar on a terminal; in a log file, a line per task every :data:`LOG_EVERY_S` seconds.

    Rich redraws a bar only on a terminal, so a run of hours sent to a file (``nohup``,
    ``scripts/long_runs.sh``, CI) would say nothing until its end. Its lines give the count, the
    time so far and the time left at the mean rate so far (a batch's runs finish together, so a
    recent rate would jump). Runs counted within :data:`READ_BACK_S` of a task's start were read
    back from a checkpoint, not run: they are left out of the rate. A task added with
    ``start=False`` (one that waits for others) starts at its first advance, of 0 runs or more:
    its wait is not in its rate either.
    """

    def __init__(self, what: str, *columns: Any, **kwargs: Any) -> None:
        super().__init__(*columns, **kwargs)
        self.what = what
        #: per task: when its last line was written, and the (count, time) its rate starts from
        self._logged_at: dict[TaskID, float] = {}
        self._base: dict[TaskID, tuple[float, float]] = {}

    def advance(self, task_id: TaskID, advance: float = 1) -> None:
        if self._tasks[task_id].start_time is None:
            self.start_task(task_id)
        super().advance(task_id, advance)
        self._log(task_id)

    def update(self, task_id: TaskID, **changes: Any) -> None:
        super().update(task_id, **changes)
        self._log(task_id)

    def _log(self, task_id: TaskID) -> None:
        if self.disable or self.console.is_terminal:
            return
        now = self.get_time()  # the clock of the tasks' start times
        task = self._tasks[task_id]
        started = task.start_time if task.start_time is not None else now
        if now - started < READ_BACK_S:  # read back from a checkpoint: not in the rate
            self._base[task_id] = (task.completed, now)
        self._base.setdefault(task_id, (0, started))
        self._logged_at.setdefault(task_id, started)
        if now - self._logged_at[task_id] < LOG_EVERY_S or task.finished:
            return
        self._logged_at[task_id] = now
        name = task.description or self.what
        line = f"{name}: {task.completed:.0f}"
        if task.total:
            line += f"/{task.total:.0f} ({task.completed / task.total:.0%})"
        line += f" after {timedelta(seconds=round(now - started))}"
        done, since = self._base[task_id]
        if task.total and task.completed > done:
            rate = (task.completed - done) / (now - since)
            line += f", about {timedelta(seconds=round((task.total - task.completed) / rate))} left"
        self.console.print(line, markup=False, highlight=False)


def progress_bar(total: int, what: str) -> Progress:
    """A progress bar on stderr, for long Monte-Carlo work (a line a minute in a log file)."""
    return LoggedProgress(
        what,
        TextColumn(f"[bold]{what}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
        disable=not console.is_terminal and total < 2,
    )


#: ``--scheduler``, shared by the commands that run the Monte-Carlo engine.
Scheduler = Annotated[
    str | None,
    typer.Option(
        envvar="TLTRACK_SCHEDULER",
        help="run the batches on the Dask cluster of this scheduler (tcp://HOST:PORT) instead of "
        "the local process pool",
    ),
]
#: ``--workers`` and ``--batch-size``, likewise.
Workers = Annotated[
    int | None,
    typer.Option(min=1, help="worker processes of the local pool (default: all cores)"),
]
BatchSize = Annotated[int | None, typer.Option(min=1, help="runs per vectorised batch")]
#: ``--checkpoint``: finished batches kept in a folder, so that a stopped run resumes.
CheckpointDir = Annotated[
    Path | None,
    typer.Option(
        "--checkpoint",
        help="keep each finished batch in this folder; the same command run again after a stop "
        "resumes from it (only a folder you wrote: its files are pickles). A study also keeps "
        "each finished sweep there as sweep-*.json, which can be copied elsewhere alone",
    ),
]


def checked_folder(
    folder: Path, option: str = "--out", given: Path | None = None, writes: Sequence[str] = ()
) -> Path:
    """An output folder, made and tried with a file at once, or refused (exit 2) naming the path
    ``given``, or the file of ``writes`` that is a folder there: a run of hours must not end in a
    traceback that loses its results."""
    from tltrack.engine.checkpoint import writable

    try:
        writable(folder)
    except OSError as err:
        shown = given or folder
        where = f" ({err.filename})" if err.filename and err.filename != str(shown) else ""
        say_error(f"{option} {shown}: {err.strerror or err}{where}")
        raise typer.Exit(2) from None
    for name in writes:
        if (folder / name).is_dir():
            say_error(f"{option} {folder}: {folder / name} is a folder, where it writes a file")
            raise typer.Exit(2)
    return folder


def checked_file(path: Path, option: str = "--out") -> Path:
    """An output file's path, refused at once (exit 2) when it is a folder or its folder cannot
    be written."""
    if path.is_dir():
        say_error(f"{option} {path}: a folder, not a file")
        raise typer.Exit(2)
    checked_folder(path.parent, option, given=path)
    return path


def checked_checkpoint(folder: Path | None) -> Path | None:
    """``--checkpoint``'s folder, refused at once (exit 2) when it cannot be written."""
    return None if folder is None else checked_folder(folder, "--checkpoint")


@contextmanager
def engine_pool(scheduler: str | None, workers: int | None) -> Iterator[Executor | None]:
    """The Dask cluster's executor for ``--scheduler``, or None for the local pool; exits with
    the reason when the two options clash or the cluster cannot be used."""
    from tltrack.engine import cluster

    address = cluster.address(scheduler)
    if reason := cluster.refuse_workers(address, workers):
        say_error(reason)
        raise typer.Exit(2)
    try:
        with cluster.pool(address, say=console.print) as ex:
            if ex is not None:
                console.print(f"batches go to the Dask cluster at {address}")
            yield ex
    except cluster.SchedulerError as err:
        say_error(str(err))
        raise typer.Exit(1) from None


def build_config(config: Path | None, **overrides: Any) -> Config:
    """Preset/file first, then any option given on the command line; exits with the field named."""
    from tltrack.config import load_config

    source_intensity = overrides.pop("source_intensity", None)
    sources = overrides.pop("sources", None)
    fault = overrides.pop("source_fault", None)
    source_filter = overrides.pop("source_filter", None)
    detection = {k: overrides.pop(k, None) for k in ("pd", "clutter_rate")}
    source_detection = {k: overrides.pop(f"source_{k}", None) for k in ("pd", "clutter_rate")}
    try:
        if sources is not None and source_intensity is not None:
            raise ConfigError("--sources: give either --sources or --source-intensity, not both")
        if sources is not None:
            overrides["sources"] = _parse_sources(sources)
        cfg = load_config(config, **overrides)  # completed from a truth file, if any
        if source_intensity is not None:
            cfg = cfg.with_source_intensity(source_intensity)
        if fault is not None:
            first = {**cfg.sources[0].model_dump(), "fault": fault}
            cfg = cfg.with_(sources=[first, *cfg.sources[1:]])
        if source_filter is not None:
            cfg = cfg.with_(
                sources=[{**s.model_dump(), "filter": source_filter} for s in cfg.sources],
                trusted_changes=True,
            )
        cfg = _with_detection(cfg, detection, source_detection)
    except ValueError as err:  # a ConfigError, or a truth file refused
        say_error(f"invalid configuration: {err}")
        raise typer.Exit(2) from None
    return cfg


def filter_names(filters: str, cfg: Config) -> list[str]:
    """``--filters`` as names, each known and each able to run with the config's sensors; exits
    with the reason otherwise."""
    from tltrack.engine.montecarlo import check_filters
    from tltrack.engine.registry import parse

    names = [n.strip() for n in filters.split(",") if n.strip()]
    twice = sorted({n for n in names if names.count(n) > 1})
    problem = "name at least one filter" if not names else twice and f"{twice} named twice"
    if problem:
        say_error(f"--filters: {problem}")
        raise typer.Exit(2)
    try:
        for n in names:
            parse(n, trusted=True)
        check_filters(cfg, names)
    except ValueError as err:
        say_error(f"--filters: {err}")
        raise typer.Exit(2) from None
    return names


def _with_detection(
    cfg: Config, primary: dict[str, float | None], sources: dict[str, float | None]
) -> Config:
    """``--pd``/``--clutter-rate`` into the primary's detection process, ``--source-pd``/
    ``--source-clutter-rate`` into every source's, over what the config file gave."""

    def merged(given: DetectionSpec | None, flags: dict[str, float | None]) -> dict[str, Any]:
        return {
            **(given.model_dump() if given else {}),
            **{k: v for k, v in flags.items() if v is not None},
        }

    if any(v is not None for v in primary.values()):
        cfg = cfg.with_(primary_detection=merged(cfg.primary_detection, primary))
    if any(v is not None for v in sources.values()):
        cfg = cfg.with_(
            sources=[
                {**s.model_dump(), "detection": merged(s.detection, sources)} for s in cfg.sources
            ]
        )
    return cfg


def _parse_sources(text: str) -> list[dict[str, Any]]:
    """``"1,2,8"`` -> sources s1, s2, s3 at the origin with those noise intensities."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(f"--sources: {text!r} is not a comma-separated list of numbers") from None
    return [{"id": f"s{i + 1}", "intensity": v} for i, v in enumerate(values)]
