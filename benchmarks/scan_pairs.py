"""What a dense scan's likelihood must cost: the particle-detection pairs of the clutter bench.

    .venv/bin/python benchmarks/scan_pairs.py [--particles 6000] [--steps 100]

``tltrack bench --clutter`` (:mod:`tltrack.perf.clutter`) times ``rpf`` and ``pf`` on scans of
1000 detections against their clean step. This script runs it once more while keeping the inputs
of every call of the grid kernel (:func:`tltrack.filters.kernels.scan.scan_loglik`), then counts,
for each call, the pairs (particle, detection) whose residual is inside the particle's box (the
kernel's ``half``, 6 noise standard deviations): the Gaussian terms that the expected-likelihood
weight sums, and that no exact evaluation can skip. It times each call again on its own (the
fastest of 3) and prints the medians: detections, pairs in the boxes, ms per call, ns per pair
(the median time over the median count), and a call's time against the bench's clean ``rpf``
step. ``rpf`` makes two such calls a step (its look-ahead and its update), ``pf`` one. (The
bench's cluttered steps are not shown: keeping the inputs slows them; ``tltrack bench
--clutter`` times them.) Counting holds an (n_z, N, M) array, about 100 MB at N = 6000.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
from tltrack.filters.kernels import scan as kernel
from tltrack.models.angles import wrap_angle
from tltrack.perf.clutter import run_clutter_bench


def pairs_in_boxes(Zx: np.ndarray, Z: np.ndarray, angular: np.ndarray, half: np.ndarray) -> int:
    """How many (particle, detection) residuals are within ``half`` in every component."""
    v = Z[:, None, :] - Zx[:, :, None]  # (n_z, N, M)
    v[angular] = wrap_angle(v[angular])
    return int(np.all(np.abs(v) <= half[:, None, None], axis=0).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--steps", type=int, default=100)
    a = ap.parse_args()
    calls: list[list[np.ndarray]] = []
    real = kernel.scan_loglik

    def kept(*args: Any) -> None:
        calls.append([np.array(x, copy=True) for x in args])
        real(*args)

    kernel.scan_loglik = kept  # the filters call it as tltrack.filters.association.kernel's
    try:
        bench = run_clutter_bench(a.particles, repeats=1, steps=a.steps, stonesoup_steps=0)
    finally:
        kernel.scan_loglik = real
    # the bench's two passes (warm-up, timed) are alike, call for call: keep the timed one's
    assert len(calls) % 2 == 0, len(calls)
    calls = calls[len(calls) // 2 :]
    detections, pairs, ms = [], [], []
    for Zx, Z, angular, Ri, half, floor, weight, out in calls:
        detections.append(Z.shape[1])
        pairs.append(pairs_in_boxes(Zx, Z, angular, half))
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            real(Zx, Z, angular, Ri, half, floor, weight, out)
            best = min(best, time.perf_counter() - t0)
        ms.append(best * 1e3)
    clean = bench["median_ms"]["rpf"]
    med = {k: float(np.median(v)) for k, v in (("d", detections), ("p", pairs), ("ms", ms))}
    print(f"kernel calls (the timed repeat's): {len(calls)}")
    print(f"detections per scan: {med['d']:.0f}; pairs in the boxes per call: {med['p']:.0f}")
    print(f"kernel: {med['ms']:.3f} ms a call, {med['ms'] * 1e6 / med['p']:.2f} ns a pair")
    print(f"a call against the clean rpf step ({clean:.3f} ms): {med['ms'] / clean:.2f}")


if __name__ == "__main__":
    main()
