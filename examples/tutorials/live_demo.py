"""Your first live demo: the dual tracker as separate processes over Zenoh, one episode.

``tltrack demo`` starts a router per operator (the referee's, the primary's, the source's), the
scorer, each operator's sensor and tracker, and sensor_sim (the world clock and the truth), runs
one episode and prints the scorer's summary. This script runs a short one and reads the summary
it writes as JSON:

    python examples/tutorials/live_demo.py --out /tmp/live
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any


def main(out: Path, steps: int = 40, particles: int = 1000) -> dict[str, Any]:
    """Run one episode of ``steps`` steps into ``out``; return the scorer's summary."""
    summary_file = out / "summary.json"
    command = [
        sys.executable, "-m", "tltrack", "demo",
        "--steps", str(steps),
        "--particles", str(particles),
        "--pace", "0",  # as fast as the trackers go; --realtime paces at one step per Ts
        "--json", str(summary_file),
        "--out", str(out),
    ]  # fmt: skip
    subprocess.run(command, check=True)
    summary: dict[str, Any] = json.loads(summary_file.read_text())

    print(f"topology {summary['topology']}, access control {summary['access_control']}")
    for name, f in summary["filters"].items():
        rmse = f["rmse_overall"]
        print(
            f"{name:18s} RMSE {rmse:7.2f} m  steps {f['steps']:3d}  "
            f"with a transfer {f['steps_with_transfer']:3d}  p50 {f['latency_ms']['p50']:.2f} ms"
        )
    return summary


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, default=Path("out/live-demo"))
    parser.add_argument("--steps", type=int, default=40)
    args = parser.parse_args()
    main(args.out, args.steps)
