"""Each test's CPU, its child processes' included: an opt-in plugin, to find what make test spends.

    make test PYTEST=".venv/bin/pytest --cpu-profile"      # the option is tests/conftest.py's

Each test process appends a JSON line per test to ``build/cpu-profile/<pid>.jsonl``: the test's
id, the CPU of its own process, the CPU of the child processes it waited for (the routers,
services and CLI runs it started), and its wall time. At the end, the main process prints the
files and the tests that used the most. Not counted: the containers' CPU (the Docker daemon's
children) and a child that was never waited for. docs/contributing.md quotes what it found.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

OUT = Path(__file__).resolve().parents[1] / "build" / "cpu-profile"
SHOWN = 25


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def pytest_configure(config: pytest.Config) -> None:
    if not _is_worker(config):  # a fresh record for this run
        shutil.rmtree(OUT, ignore_errors=True)
    OUT.mkdir(parents=True, exist_ok=True)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    own, children, t0 = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN), time.monotonic()
    yield
    row = {
        "id": item.nodeid,
        "self_s": _cpu(resource.RUSAGE_SELF) - own,
        "children_s": _cpu(resource.RUSAGE_CHILDREN) - children,
        "wall_s": time.monotonic() - t0,
    }
    with open(OUT / f"{os.getpid()}.jsonl", "a") as f:
        f.write(json.dumps(row) + "\n")


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    if _is_worker(config):
        return
    rows = [json.loads(line) for p in sorted(OUT.glob("*.jsonl")) for line in p.open()]
    if not rows:
        return
    cpu = {r["id"]: r["self_s"] + r["children_s"] for r in rows}
    files: dict[str, float] = defaultdict(float)
    for test, s in cpu.items():
        files[test.split("::")[0]] += s
    write = terminalreporter.write_line
    write(f"CPU of {len(rows)} tests, their children's included: {sum(cpu.values()) / 60:.1f} min")
    for name, s in sorted(files.items(), key=lambda kv: -kv[1])[:SHOWN]:
        write(f"{s:8.1f} s  {name}")
    for test, s in sorted(cpu.items(), key=lambda kv: -kv[1])[:SHOWN]:
        write(f"{s:8.1f} s  {test}")
    write(f"one line per test: {OUT}/*.jsonl")
