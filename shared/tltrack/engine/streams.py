"""Independent random streams named by (seed, run, purpose).

Every run and every filter draws from its own :class:`numpy.random.Generator`, spawned from
``SeedSequence(seed, spawn_key=(run, crc32(purpose)))``. So a run's numbers never depend on the
batch size, on the worker count, or on which other filters ran beside it; and a live service can
replay any single run of an experiment exactly by asking for the same stream.
"""

from __future__ import annotations

import zlib

import numpy as np


def stream(seed: int, run: int, purpose: str) -> np.random.Generator:
    """The generator for one (seed, run, purpose), e.g. purpose ``"pf"`` or ``"meas/primary"``."""
    key = zlib.crc32(purpose.encode())
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(run, key))))


def streams(seed: int, runs: range | list[int], purpose: str) -> list[np.random.Generator]:
    """One generator per run of a batch."""
    return [stream(seed, r, purpose) for r in runs]
