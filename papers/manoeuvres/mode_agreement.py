"""Would the source's mode probabilities help the primary? How far the primary's are from them.

    .venv/bin/python papers/manoeuvres/mode_agreement.py [--runs 20] [--truth FILE]

The transfer carries the source's predicted-observation density alone, never its mode
probabilities (docs/howto/manoeuvring-targets.md). This runs the turn sequence (by default) with
the aircraft class's three modes, `ukf`/`tl-ukf` (IMM) and `rpf`/`tl-rpf` (a mode per particle),
and measures at every step the total variation distance between each primary's predicted mode
probabilities, Pi^T mu_k, and the source's, c_{k+1|k}: 0 when they agree, 1 when they put their
weight on different modes. If the TL primary's are already as close to the source's as
isolated's are, or closer, the transfer has carried what the mode probabilities would.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tltrack.config import load_config
from tltrack.engine.driver import Driver, StepRecord
from tltrack.engine.scenario import Run, simulate
from tltrack.engine.setup import Setup

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument(
        "--truth", type=Path, default=ROOT / "examples" / "tracks" / "sim-turn-sequence.csv"
    )
    args = parser.parse_args()
    cfg = load_config(
        None,
        preset="arasaratnam-haykin",
        truth_file=args.truth,
        target_class="aircraft",
        runs=args.runs,
    )
    setup, runs = Setup(cfg), list(range(args.runs))
    sims = [simulate(setup, r) for r in runs]
    print(f"{args.truth.name}: K = {cfg.K}, {args.runs} runs, N = {cfg.particles}")
    modes, errors = _run(setup, sims, adopt=False)
    print("filter | TV to its source's modes (mean, 90th pct) | RMSE [m]")
    for kind in ("ukf", "rpf"):
        source = np.array(modes[f"source-{kind}"])  # (K, M, B)
        for name in (kind, f"tl-{kind}"):
            tv = 0.5 * np.abs(np.array(modes[name]) - source).sum(axis=1)  # (K, B)
            print(
                f"{name} | {tv.mean():.3f}, {np.quantile(tv, 0.9):.3f} | {_rmse(errors[name]):.1f}"
            )
    _, adopted = _run(setup, sims, adopt=True)
    print("with the source's mode probabilities in place of its own (IMM):")
    for name in ("ukf", "tl-ukf"):
        diff = _run_rmse(adopted[name]) - _run_rmse(errors[name])  # paired, per run
        print(
            f"{name} | RMSE {_rmse(errors[name]):.1f} -> {_rmse(adopted[name]):.1f} m; per run "
            f"{diff.mean():+.2f} m (2 SE {2 * diff.std(ddof=1) / np.sqrt(diff.size):.2f})"
        )


def _rmse(errors: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.array(errors) ** 2)))


def _run_rmse(errors: list[np.ndarray]) -> np.ndarray:
    return np.sqrt(np.mean(np.array(errors) ** 2, axis=0))


def _run(
    setup: Setup, sims: list[Run], *, adopt: bool
) -> tuple[dict[str, list[np.ndarray]], dict[str, list[np.ndarray]]]:
    """Every filter's predicted mode probabilities for k + 1 (M, B) and position errors (B,) at
    each step. With ``adopt``, each IMM primary's mu_k is replaced after its step by the source's
    (Pi^T mu = the source's c_{k+1|k}, the transfer's timing): what sending them would give."""
    Pi = np.asarray(setup.cfg.mode_transition)
    modes: dict[str, list[np.ndarray]] = {}
    errors: dict[str, list[np.ndarray]] = {}
    truth = np.stack([s.truth[:, [0, 2]] for s in sims], axis=1)  # (ticks + 1, B, 2): positions

    def collect(r: StepRecord) -> None:
        p = r.filter.mode_probabilities  # type: ignore[attr-defined]
        # a source has predicted already (its transfer is for k + 1); a primary holds mu_k
        modes.setdefault(r.name, []).append(p.copy() if r.role == "source" else Pi.T @ p)
        d = r.estimate.mean[:, [0, 2]] - truth[r.k]
        errors.setdefault(r.name, []).append(np.hypot(d[:, 0], d[:, 1]))
        if adopt and r.name in ("ukf", "tl-ukf"):
            mu = np.clip(np.linalg.solve(Pi.T, modes["source-ukf"][-1]), 0.0, None)
            r.filter.mu = mu / mu.sum(axis=0)  # type: ignore[attr-defined]

    x0 = np.stack([s.x0_hat for s in sims], axis=1)
    driver = Driver([setup], ["ukf", "tl-ukf", "rpf", "tl-rpf"], x0, [s.run for s in sims],
                    collectors=[[collect]])  # fmt: skip
    for k in range(1, setup.cfg.K + 1):
        z = {
            i: setup.sensors[i].observe(np.stack([s.z[i][k - 1] for s in sims], 1))
            for i in setup.sensor_ids
        }
        driver.step(k, [z])
    return modes, errors


if __name__ == "__main__":
    main()
