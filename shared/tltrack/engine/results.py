"""The ``results.json`` of an experiment: config, provenance, per-filter metrics and the PCRLB."""

from __future__ import annotations

import json
import platform
import subprocess
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

import tltrack
from tltrack.config import Config
from tltrack.config.truth_file import recorded_track
from tltrack.engine.montecarlo import FilterResult
from tltrack.engine.scenario import truth
from tltrack.engine.setup import PRIMARY, Setup

SCHEMA_VERSION = 1


def provenance() -> dict[str, Any]:
    """Enough to tell which code, libraries and machine produced a result."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            cwd=Path(__file__).parent,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return {
        "package_version": tltrack.__version__,
        "git_commit": commit or "unknown",
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "machine": f"{platform.machine()} {platform.processor() or platform.node()}".strip(),
        "cpu_count": __import__("os").cpu_count(),
    }


#: what the bound is when the filters carry motion modes (results' ``pcrlb_note``)
PCRLB_MODES_NOTE = (
    "the PCRLB is the scenario's single model's along the truth: the bound of a target that "
    "switches between modes (a jump-Markov model) is out of scope, and the filters' modes do "
    "not enter it"
)


#: why there is no bound when the operators keep their own clocks
PCRLB_CLOCKS_NOTE = (
    "no PCRLB: its recursion steps every sensor on one period (tltrack.engine.pcrlb), and the "
    "operators here keep their own periods, phases or clocks"
)


def position_bounds(cfg: Config) -> dict[str, list[float]]:
    """PCRLB of the primary alone, and with every source's raw data, averaged over the truths;
    none when the operators keep their own clocks (:data:`PCRLB_CLOCKS_NOTE`)."""
    if not cfg.timeline.synchronous:
        return {}
    setup = Setup(cfg)
    runs = 1 if cfg.truth != "random" else cfg.runs
    truths = np.stack([truth(setup, r) for r in range(runs)])
    return {
        "primary": setup.pcrlb([PRIMARY], truths).tolist(),
        "with_source": setup.pcrlb(setup.sensor_ids, truths).tolist(),
    }


def assemble(cfg: Config, results: dict[str, FilterResult]) -> dict[str, Any]:
    """The results document. Each filter's ``run_rmse`` lists every run's overall RMSE, in run
    order, so that anyone can compute paired differences between filters from it."""
    filters = {name: asdict(r) for name, r in results.items()}
    doc = {
        "schema_version": SCHEMA_VERSION,
        "provenance": provenance(),
        "config": cfg.model_dump(mode="json"),
        "filters": filters,
        "pcrlb": position_bounds(cfg),
    }
    if cfg.truth == "file":
        doc["truth"] = truth_file_record(cfg)
    if cfg.motion_modes is not None:
        doc["pcrlb_note"] = PCRLB_MODES_NOTE
    if not cfg.timeline.synchronous:
        doc["pcrlb_note"] = PCRLB_CLOCKS_NOTE
    return doc


def truth_file_record(cfg: Config) -> dict[str, Any]:
    """What a recorded truth was: the file's name and SHA-256, its frame's origin, K."""
    track = recorded_track(cfg)
    return {
        "mode": "file",
        "file": track.name,
        "sha256": track.sha256,
        "origin": track.origin,
        "K": cfg.K,
        "Ts": cfg.Ts,
    }


def write(doc: dict[str, Any], out_dir: Path) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "results.json"
    path.write_text(json.dumps(doc, indent=1, allow_nan=True))
    return path


def read(path: Path) -> dict[str, Any]:
    """A results document, refused (``ValueError``) unless it has what its figures are drawn from:
    the config, and each filter's RMSE per step and overall."""
    try:
        doc = json.loads(Path(path).read_text())
    except RecursionError:
        raise ValueError(f"{path}: nested too deeply") from None
    if not isinstance(doc, dict) or doc.get("schema_version") != SCHEMA_VERSION:
        version = doc.get("schema_version") if isinstance(doc, dict) else None
        raise ValueError(f"{path}: unsupported results schema {version!r}")
    filters = doc.get("filters")
    if not isinstance(doc.get("config"), dict) or not isinstance(filters, dict) or not filters:
        raise ValueError(f"{path}: no config, or no filters' results")
    for name, r in filters.items():
        per_step = r.get("rmse_per_step") if isinstance(r, dict) else None
        if not isinstance(per_step, list) or not isinstance(r.get("rmse_overall"), int | float):
            raise ValueError(f"{path}: filters.{name} lacks rmse_per_step or rmse_overall")
    return doc
