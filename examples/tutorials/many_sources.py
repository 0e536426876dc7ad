"""Many sources: one primary, three source operators, each transfer a likelihood of its own.

Each source runs its own filter on its own sensor and sends its own transfer; the primary
multiplies every transfer that arrived in time into its weights. The three sources here are those
of the compose profile ``three-sources`` (``deploy/three-sources.toml``): ``s1`` as in the paper,
``s2`` a noisier one beside it, ``s3`` a third sensor 2 km east.

    python examples/tutorials/many_sources.py
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tltrack.config import load_config
from tltrack.engine.montecarlo import run_experiment

THREE = Path(__file__).resolve().parents[2] / "deploy" / "three-sources.toml"


def main(runs: int = 20, particles: int = 1000) -> dict[str, Any]:
    """TL with the first source only, and with all three: {label: {filter: result}}."""
    three = load_config(THREE, particles=particles, runs=runs, seed=1)
    one = three.with_(sources=[three.sources[0].model_dump()])
    out = {}
    for label, cfg in (("one source", one), ("three sources", three)):
        ids = ", ".join(f"{s.id} (I_w {s.intensity:g})" for s in cfg.sources)
        res = run_experiment(cfg, ["rpf", "tl-rpf"], workers=1)
        out[label] = res
        print(f"{label}: {ids}")
        for name, r in res.items():
            print(f"  {name:20s} RMSE {r.rmse_overall:7.2f} m")
    return out


if __name__ == "__main__":
    main()
