"""Studies beyond the paper: faulty sources, several sources, and a communication budget.

All use the Monte-Carlo engine on `arasaratnam-haykin`, noise-free truth, I_p = 4, N = 3000.
Runs of the same index share the truth and the primary's measurements across configurations
(their random streams are named, not positional), so differences are *paired*: the Monte-Carlo
error of a difference A - B is twice the standard error of the per-run difference of
sqrt(mean over k of the squared position error).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tltrack import plots
from tltrack.config import Config, make_config
from tltrack.engine.montecarlo import FilterResult, run_experiment
from tltrack.engine.pcrlb import pcrlb
from tltrack.engine.scenario import PRIMARY, intensity, sensor, truth
from tltrack.models.motion import motion_model

FAULTS = ["none", "bias", "diverged", "stale"]
BUDGETS = [0.05, 0.1, 0.25, 0.5, 0.75, 1.0]

Progress = Callable[[int], None] | None


def base(runs: int, seed: int = 0) -> Config:
    return make_config(
        preset="arasaratnam-haykin",
        truth="noise-free",
        primary_intensity=4,
        particles=3000,
        runs=runs,
        seed=seed,
    )


def run_difference(a: FilterResult, b: FilterResult) -> NDArray[np.float64]:
    """Per run, the overall RMSE of a minus that of b: the paired comparison's samples."""
    return np.sqrt(a.run_mse) - np.sqrt(b.run_mse)


def paired(a: FilterResult, b: FilterResult) -> str:
    """``"+x.xx (e.ee)"``: the mean over runs of the per-run overall-RMSE difference a - b, and its
    Monte-Carlo error, twice the standard error (see the module docstring)."""
    d = run_difference(a, b)
    return f"{d.mean():+.3f} ({2.0 * d.std(ddof=1) / np.sqrt(len(d)):.3f})"


def _row(cells: list[Any]) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def robust(
    runs: int,
    out: Path,
    progress: Progress = None,
    seed: int = 0,
    *,
    workers: int | None = None,
    batch_size: int | None = None,
    executor: Executor | None = None,
) -> Path:
    """pf, tl-pf and robust-tl-pf against an honest, biased, diverged and stale source."""
    res = {
        f: run_experiment(
            base(runs, seed).with_(sources=[{"id": "s1", "fault": f}]),
            ["pf", "tl-pf", "robust-tl-pf"],
            progress=progress,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
        )
        for f in FAULTS
    }

    lines = [
        "# Robust transfer against faulty sources",
        "",
        f"`arasaratnam-haykin`, noise-free truth, I_p = 4, N = 3000, {runs} runs, seed {seed}. "
        "Differences are means over runs of the paired per-run overall RMSE difference; "
        "MC error = 2 x SE of that difference.",
        "",
        _row(
            [
                "source",
                "pf",
                "tl-pf",
                "robust-tl-pf",
                "robust - pf (MC err)",
                "robust gain / tl gain",
                "transfer rate (robust)",
                "lost pf / tl / robust",
            ]
        ),
        _row(["---"] * 8),
    ]
    for f, r in res.items():
        iso, tl, rob = r["pf"], r["tl-pf"], r["robust-tl-pf"]
        share = (
            run_difference(iso, rob).mean() / run_difference(iso, tl).mean()
            if f == "none"
            else None
        )
        lines.append(
            _row(
                [
                    f,
                    f"{iso.rmse_overall:.2f}",
                    f"{tl.rmse_overall:.2f}",
                    f"{rob.rmse_overall:.2f}",
                    paired(rob, iso),
                    "–" if share is None else f"{share:.1%}",
                    f"{rob.transfer_rate:.1%}",
                    f"{iso.lost_fraction:.0%} / {tl.lost_fraction:.0%} / {rob.lost_fraction:.0%}",
                ]
            )
        )
    return _write(out, "robust", lines, {f: _plain(r) for f, r in res.items()})


def sources(
    runs: int,
    out: Path,
    progress: Progress = None,
    seed: int = 0,
    *,
    workers: int | None = None,
    batch_size: int | None = None,
    executor: Executor | None = None,
) -> Path:
    """The primary's RMSE against the number of sources, honest or with one biased among them."""
    filters = ["pf", "tl-pf", "robust-tl-pf", "fusion-pf"]
    setups: dict[str, list[dict[str, Any]]] = {
        f"{n} honest": [{"id": f"s{i + 1}"} for i in range(n)] for n in (1, 2, 4)
    }
    setups |= {
        f"{n - 1} honest + 1 biased": [{"id": f"s{i + 1}"} for i in range(n - 1)]
        + [{"id": f"s{n}", "fault": "bias"}]
        for n in (2, 4)
    }
    res, bounds = {}, {}
    for label, srcs in setups.items():
        cfg = base(runs, seed).with_(sources=srcs)
        res[label] = run_experiment(
            cfg,
            filters,
            progress=progress,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
        )
        bounds[label] = float(np.mean(_bound_all(cfg)))
    one, two = res["1 honest"]["tl-pf"], res["2 honest"]["tl-pf"]
    mixed = res["1 honest + 1 biased"]["robust-tl-pf"]
    lines = [
        "# Several source operators",
        "",
        f"`arasaratnam-haykin`, noise-free truth, I_p = 4, N = 3000, {runs} runs; sources at "
        "the origin, I_s = 1; the biased one has a 10-sigma bearing bias.",
        "",
        _row(["sources", *filters, "PCRLB, all data (mean over k)"]),
        _row(["---"] * 6),
    ]
    for label, r in res.items():
        lines.append(
            _row([label, *(f"{r[f].rmse_overall:.2f}" for f in filters), f"{bounds[label]:.2f}"])
        )
    lines += [
        "",
        "Checks (difference, MC error):",
        "",
        f"- 2 honest vs 1 honest, tl-pf: {paired(two, one)}",
        f"- 1 honest + 1 biased, robust-tl-pf vs isolated pf: "
        f"{paired(mixed, res['1 honest + 1 biased']['pf'])}",
        f"- 1 honest + 1 biased, robust-tl-pf vs tl-pf with the honest source alone: "
        f"{paired(mixed, one)}",
    ]
    labels = list(res)
    plots.curves(
        range(len(labels)),
        {f: [res[lb][f].rmse_overall for lb in labels] for f in filters},
        out / "sources.png",
        xlabel="configuration: " + " | ".join(labels),
        ylabel="overall RMSE [m]",
        title="Primary RMSE against the sources it hears",
    )
    return _write(out, "sources", lines, {lb: _plain(r) for lb, r in res.items()})


def budget(
    runs: int,
    out: Path,
    progress: Progress = None,
    seed: int = 0,
    *,
    workers: int | None = None,
    batch_size: int | None = None,
    executor: Executor | None = None,
) -> Path:
    """RMSE against the share of steps with a transfer (the hybrid primary's budget)."""
    res = {
        b: run_experiment(
            base(runs, seed).with_(transfer_budget=b),
            ["pf", "robust-tl-pf"],
            progress=progress,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
        )
        for b in BUDGETS
    }
    rate = [res[b]["robust-tl-pf"].transfer_rate for b in BUDGETS]
    rmse = [res[b]["robust-tl-pf"].rmse_overall for b in BUDGETS]
    plots.curves(
        rate,
        {"robust-tl-pf": rmse, "pf": [res[b]["pf"].rmse_overall for b in BUDGETS]},
        out / "budget.png",
        xlabel="share of steps with a transfer",
        ylabel="overall RMSE [m]",
        title="RMSE against the transfer rate",
    )
    lines = [
        "# Communication budget",
        "",
        f"{runs} runs, N = 3000.",
        "",
        _row(["budget", "transfer rate", "RMSE robust-tl-pf", "RMSE pf"]),
        _row(["---"] * 4),
    ]
    lines += [
        _row([b, f"{r:.1%}", f"{m:.2f}", f"{res[b]['pf'].rmse_overall:.2f}"])
        for b, r, m in zip(BUDGETS, rate, rmse, strict=True)
    ]
    return _write(out, "budget", lines, {str(b): _plain(r) for b, r in res.items()})


def _bound_all(cfg: Config) -> np.ndarray:
    ids = [PRIMARY, *(s.id for s in cfg.sources)]
    pairs = [(sensor(cfg, i), sensor(cfg, i).R(intensity(cfg, i))) for i in ids]
    return pcrlb(motion_model(cfg), pairs, truth(cfg, 0)[None], np.diag(cfg.P0_diag))


def _plain(r: dict[str, FilterResult]) -> dict[str, Any]:
    return {
        n: {
            "rmse_overall": v.rmse_overall,
            "lost_fraction": v.lost_fraction,
            "transfer_rate": v.transfer_rate,
        }
        for n, v in r.items()
    }


def _write(out: Path, name: str, lines: list[str], data: dict[str, Any]) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(data, indent=1))
    path = out / f"{name}.md"
    path.write_text("\n".join(lines) + "\n")
    return path
