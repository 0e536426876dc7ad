"""One image build at a time: tests/test_compose.py's ``image`` fixture, which tests/test_dask.py
reuses, runs scripts/build_image.sh (its wheels into build/wheels, then docker build).

Under pytest-xdist both test processes may reach that fixture at once; an exclusive ``flock`` on
build/.build.lock makes the second wait for the first's build, and then reuse it (the image's
stamp says whether the image is current). tests/test_wheel.py builds into its own folder."""

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
