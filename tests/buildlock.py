"""One builder at a time in build/: the Docker image (tests/test_compose.py, reused by
tests/test_dask.py) and the wheel (tests/test_wheel.py) both run scripts/build_wheels.sh into
build/wheels, which removes and rewrites build/wheels/app (and deps/ when the pins change).

Under pytest-xdist several test processes may reach those fixtures at once; an exclusive
``flock`` on build/.build.lock makes the second wait for the first, and then reuse what it built
(the image's stamp says whether the image is current)."""

from __future__ import annotations

import contextlib
import fcntl
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / "build" / ".build.lock"


@contextlib.contextmanager
def held(what: str) -> Iterator[None]:
    """Hold the build lock for ``what``; says how long it waited for another test process."""
    LOCK.parent.mkdir(parents=True, exist_ok=True)
    with LOCK.open("a") as fh:
        t0 = time.monotonic()
        fcntl.flock(fh, fcntl.LOCK_EX)  # released when the file closes, even on a crash
        if (waited := time.monotonic() - t0) > 1:
            print(f"{what}: waited {waited:.0f} s for another test process's build")
        yield
