"""``tltrack reproduce``: every figure and table of the seed's "Simulation Results", beside the
numbers the paper prints, with the difference.

The paper prints values at a few points only (RMSE at chosen k, overall RMSE at I_p = 4 and 8,
Table 2); those are the reference column. Everything else is drawn from our runs.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tltrack.config import Config, make_config
from tltrack.engine import plots, results
from tltrack.engine.montecarlo import expand, run_sweep

KF_FILTERS = ["ukf", "tl-ukf", "ckf3", "tl-ckf3", "ckf5", "tl-ckf5"]
PF_FILTERS = ["pf", "tl-pf"]
#: the auxiliary particle filter that keeps the track (papers/rpf/README.md), beside the paper's SIR
RPF_FILTERS = ["rpf", "tl-rpf"]
#: what the lost-track jobs compare: both particle filters, the robust one, the UKF's share
LOSS_FILTERS = [*PF_FILTERS, *RPF_FILTERS, "robust-tl-rpf", "ukf", "tl-ukf"]
ALL_FILTERS = PF_FILTERS + RPF_FILTERS + KF_FILTERS
INTENSITIES = list(range(1, 9))
PARTICLES = [3000, 6000, 9000, 12000]

#: Table 2 of the seed: (RMSE isolated, ms isolated, RMSE TL, ms TL) at I_p = 4, Scenario 2.
TABLE2: dict[tuple[str, int | None], tuple[float, float, float, float]] = {
    ("ckf3", None): (18.0973, 0.154, 15.8815, 0.188),
    ("ukf", None): (17.9451, 0.165, 15.4299, 0.206),
    ("ckf5", None): (17.9178, 0.225, 15.2728, 0.297),
    ("pf", 3000): (16.9530, 0.867, 15.2341, 0.931),
    ("pf", 6000): (16.7473, 1.902, 14.3359, 2.020),
    ("pf", 9000): (16.6988, 2.957, 14.1443, 3.167),
    ("pf", 12000): (16.6630, 3.367, 14.0746, 3.569),
}

#: RMSE(k) values the text quotes: (scenario, filter, k) -> metres (N = 6000, I_p = 4).
RMSE_AT_K: dict[tuple[str, str, int], float] = {
    ("cv", "tl-pf", 52): 4.28,
    ("cv", "pf", 52): 7.37,
    ("cv", "tl-ukf", 52): 10.13,
    ("cv", "tl-ckf3", 52): 11.28,
    ("ct", "tl-pf", 10): 13.10,
    ("ct", "tl-ckf3", 10): 15.72,
    ("ct", "tl-ukf", 10): 14.35,
    ("ct", "tl-pf", 47): 7.79,
    ("ct", "tl-ukf", 47): 13.75,
    ("ct", "tl-pf", 48): 7.85,
    ("ct", "pf", 48): 9.73,
    ("ct", "tl-pf", 75): 14.38,
    ("ct", "pf", 75): 17.34,
}

#: Overall RMSE against I_p quoted in the text (N = 6000): (filter, I_p) -> metres.
RMSE_AT_IP: dict[tuple[str, int], float] = {
    ("pf", 4): 16.74,
    ("tl-pf", 4): 14.33,
    ("pf", 8): 23.06,
    ("tl-pf", 8): 17.45,
    ("tl-ckf5", 8): 17.45 + 1.24,
}

#: Delta RMSE against Delta I quoted in the text: (kind, Delta I) -> metres.
DELTA_AT_DI: dict[tuple[str, int], float] = {
    ("pf", 3): 2.41,
    ("ckf3", 3): 2.21,
    ("pf", 7): 5.61,
    ("ckf5", 7): 6.06,
}


KINDS = ["pf", "rpf", "ukf", "ckf3", "ckf5"]
S1 = "s1"  #: the label of Scenario 1's job
LOSS = "loss_"  #: the prefix of the lost-track jobs' labels


def s2_label(intensity: int, particles: int = 6000) -> str:
    """The label of Scenario 2's job at primary intensity I_p and N particles."""
    return f"s2_ip{intensity}" if particles == 6000 else f"s2_n{particles}"


@dataclass(frozen=True)
class Job:
    label: str
    cfg: Config
    filters: list[str]


def loss_jobs(base: Config) -> list[Job]:
    """PF and TL-PF under each preset and truth mode: how often, and why, tracks are lost."""
    return [
        Job(
            f"{LOSS}{p}_{t}",
            base.with_(scenario="ct", preset=p, truth=t, particles=6000, primary_intensity=4),
            LOSS_FILTERS,
        )
        for p in ("paper", "arasaratnam-haykin")
        for t in ("fixed", "random", "noise-free")
    ]


def table2_pf_jobs(base: Config) -> list[Job]:
    """Only Table 2's particle-filter rows (the 10,000-run target of the performance issue)."""
    ct = base.with_(scenario="ct", primary_intensity=4)
    return [Job(s2_label(4, n), ct.with_(particles=n), PF_FILTERS + RPF_FILTERS) for n in PARTICLES]


def jobs(base: Config) -> list[Job]:
    """Every Monte-Carlo experiment the section needs, each run once."""
    ct = base.with_(scenario="ct", particles=6000)
    out = [
        Job(
            S1,
            base.with_(scenario="cv", particles=6000, primary_intensity=4),
            PF_FILTERS + RPF_FILTERS + KF_FILTERS[:4],
        )
    ]
    out += [Job(s2_label(i), ct.with_(primary_intensity=i), ALL_FILTERS) for i in INTENSITIES]
    out += [
        Job(s2_label(4, n), ct.with_(particles=n, primary_intensity=4), PF_FILTERS + RPF_FILTERS)
        for n in PARTICLES
        if n != 6000
    ]
    return out


def sweeps(todo: list[Job]) -> list[list[Job]]:
    """Jobs grouped so that each group is one :func:`run_sweep`: same configuration but for the
    primary's noise intensity. The sources then run once for the whole I_p sweep, and a job
    whose configuration another job already has costs only its extra filters."""
    groups: dict[str, list[Job]] = {}
    for job in todo:
        key = job.cfg.model_dump_json(exclude={"primary_intensity"})
        groups.setdefault(key, []).append(job)
    return list(groups.values())


def run_all(
    todo: list[Job],
    out: Path,
    *,
    workers: int | None = None,
    progress: Callable[[str, int], None] | None = None,
    batch_size: int | None = None,
    executor: Executor | None = None,
    checkpoint: Path | None = None,
) -> dict[str, dict[str, Any]]:
    """Run every job (``progress(label, runs_done)``, with 0 runs when its sweep starts),
    saving each one's results.json; the batches go to ``executor`` (a Dask cluster's) when given,
    else to a local pool, and are kept in ``checkpoint`` when given
    (:mod:`tltrack.engine.checkpoint`).

    A job's ``wall_s`` is that of its sweep (``sweep`` lists the jobs that shared it).
    """
    docs = {}
    for group in sweeps(todo):
        t0 = time.perf_counter()
        cfgs = list({j.cfg.primary_intensity: j.cfg for j in group}.values())
        names = list(dict.fromkeys(n for j in group for n in j.filters))

        labels = [j.label for j in group]

        def advance(n: int, labels: list[str] = labels) -> None:
            for label in labels:
                if progress:
                    progress(label, n)

        advance(0)  # the jobs' sweep starts: their progress, waiting until now, starts too
        swept = run_sweep(
            cfgs,
            names,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
            progress=advance,
            checkpoint=checkpoint,
        )
        wall = time.perf_counter() - t0
        by_intensity = {c.primary_intensity: r for c, r in zip(cfgs, swept, strict=True)}
        for job in group:
            wanted = {s.name for s in expand(job.filters, job.cfg)}
            res = by_intensity[job.cfg.primary_intensity]
            doc = results.assemble(
                job.cfg, {n: r for n, r in res.items() if n.split("/")[0] in wanted}
            )
            doc["wall_s"] = wall
            doc["sweep"] = labels
            results.write(doc, out / job.label)
            docs[job.label] = doc
    return docs


def wall_minutes(docs: dict[str, dict[str, Any]]) -> float:
    """Wall time of all jobs, each shared sweep counted once."""
    walls = {tuple(d.get("sweep", [label])): d.get("wall_s", 0.0) for label, d in docs.items()}
    return sum(walls.values()) / 60


def _fmt(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def _row(cells: Iterable[Any]) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def table2_pf_report(docs: dict[str, dict[str, Any]], out: Path) -> Path:
    """Table 2's particle-filter rows only, beside the paper's, with the wall time: the paper's
    SIR (``pf``) and the auxiliary filter that keeps the track (``rpf``), on the same runs."""
    lines = [
        "# Table 2, particle-filter rows",
        "",
        _row(
            [
                "N",
                "filter",
                "RMSE iso (paper / ours)",
                "RMSE TL (paper / ours)",
                "lost iso / TL",
                "ms iso / TL",
                "runs",
                "wall [min]",
            ]
        ),
        _row(["---"] * 8),
    ]
    for n in PARTICLES:
        d = docs[s2_label(4, n)]
        r_iso, _, r_tl, _ = TABLE2["pf", n]
        for kind in ("pf", "rpf"):
            iso, tl = d["filters"][kind], d["filters"][f"tl-{kind}"]
            lines.append(
                _row(
                    [
                        n,
                        kind,
                        f"{r_iso} / {iso['rmse_overall']:.2f}",
                        f"{r_tl} / {tl['rmse_overall']:.2f}",
                        f"{iso['lost_fraction']:.2%} / {tl['lost_fraction']:.2%}",
                        f"{_fmt(iso['ms_per_step'], 3)} / {_fmt(tl['ms_per_step'], 3)}",
                        d["config"]["runs"],
                        f"{d['wall_s'] / 60:.1f}",
                    ]
                )
            )
    lines += ["", f"Total wall time: {wall_minutes(docs):.1f} min."]
    path = out / "table2_pf.md"
    path.write_text("\n".join(lines) + "\n")
    return path


Results = dict[str, dict[str, Any]]  #: job label -> filter name -> its results


def table2_section(f: Results) -> list[str]:
    """Table 2 (Scenario 2, I_p = 4): each filter's RMSE and step time beside the paper's."""
    lines = [
        "## Table 2 (Scenario 2, I_p = 4)",
        "",
        _row(
            [
                "filter",
                "points",
                "RMSE iso (paper)",
                "RMSE iso (ours)",
                "diff",
                "RMSE TL (paper)",
                "RMSE TL (ours)",
                "diff",
                "ms iso (paper / ours)",
                "ms TL (paper / ours)",
                "lost iso / TL",
            ]
        ),
        _row(["---"] * 11),
    ]
    rows = [
        (ours, n, paper)
        for (kind, n), paper in TABLE2.items()
        for ours in ([kind, "rpf"] if kind == "pf" else [kind])  # rpf beside the paper's PF
    ]
    for kind, n, (r_iso, t_iso, r_tl, t_tl) in rows:
        res = f[s2_label(4, n or 6000)]
        iso, tl = res[kind], res[f"tl-{kind}"]
        points = n or {"ckf3": 10, "ukf": 11, "ckf5": 51}[kind]
        lines.append(
            _row(
                [
                    kind.upper(),
                    points,
                    r_iso,
                    _fmt(iso["rmse_overall"]),
                    _fmt(iso["rmse_overall"] - r_iso),
                    r_tl,
                    _fmt(tl["rmse_overall"]),
                    _fmt(tl["rmse_overall"] - r_tl),
                    f"{t_iso} / {_fmt(iso['ms_per_step'], 3)}",
                    f"{t_tl} / {_fmt(tl['ms_per_step'], 3)}",
                    f"{iso['lost_fraction']:.1%} / {tl['lost_fraction']:.1%}",
                ]
            )
        )
    return lines


def rmse_at_k_section(f: Results) -> list[str]:
    """RMSE(k) at the steps the text quotes, beside the quoted values."""
    lines = [
        "## RMSE(k) at the steps the text quotes (N = 6000, I_p = 4)",
        "",
        _row(["scenario", "filter", "k", "paper", "ours", "diff"]),
        _row(["---"] * 6),
    ]
    for (scen, name, k), ref in RMSE_AT_K.items():
        ours = f[S1 if scen == "cv" else s2_label(4)][name]["rmse_per_step"][k - 1]
        lines.append(_row([scen, name, k, ref, _fmt(ours), _fmt(ours - ref)]))
    return lines


def rmse_against_ip_section(f: Results) -> list[str]:
    """Every filter's overall RMSE at each primary intensity I_p."""
    lines = [
        "## Overall RMSE against I_p (N = 6000)",
        "",
        _row(["I_p", *ALL_FILTERS]),
        _row(["---"] * (1 + len(ALL_FILTERS))),
    ]
    for i in INTENSITIES:
        row = [f"{i}"]
        for name in ALL_FILTERS:
            ours = f[s2_label(i)][name]["rmse_overall"]
            ref_ip = RMSE_AT_IP.get((name, i))
            row.append(_fmt(ours) + ("" if ref_ip is None else f" (paper {ref_ip:.2f})"))
        lines.append(_row(row))
    return lines


def transfer_gains(f: Results) -> dict[str, list[float]]:
    """Delta RMSE = RMSE iso - RMSE TL of each filter kind, at each I_p."""
    return {
        kind: [
            f[s2_label(i)][kind]["rmse_overall"] - f[s2_label(i)][f"tl-{kind}"]["rmse_overall"]
            for i in INTENSITIES
        ]
        for kind in KINDS
    }


def gain_section(gains: dict[str, list[float]]) -> list[str]:
    """The gain of transfer against the intensity gap Delta I, beside the quoted values."""
    lines = [
        "## Delta RMSE = RMSE iso - RMSE TL against Delta I = I_p - I_s",
        "",
        _row(["Delta I", *KINDS]),
        _row(["---"] * (1 + len(KINDS))),
    ]
    for j, i in enumerate(INTENSITIES):
        row = [f"{i - 1}"]
        for kind in KINDS:
            ref_d = DELTA_AT_DI.get((kind, i - 1))
            row.append(_fmt(gains[kind][j]) + ("" if ref_d is None else f" (paper {ref_d:.2f})"))
        lines.append(_row(row))
    return lines


def lost_by_job_section(f: Results) -> list[str]:
    """The share of lost runs of every filter in every job."""
    names = ALL_FILTERS
    lines = [
        "## Share of runs that lost track (error > threshold in each of the last 10 steps)",
        "",
        _row(["job", *names]),
        _row(["---"] * (1 + len(names))),
    ]
    for label, res in f.items():
        cells = (f"{res[n]['lost_fraction']:.1%}" if n in res else "–" for n in names)
        lines.append(_row([label, *cells]))
    return lines


def lost_by_truth_section(docs: dict[str, dict[str, Any]]) -> list[str]:
    """Lost runs (and their MC error, 2 x the binomial SE) under each preset and truth mode."""
    lines = [
        "## Lost tracks under each preset and truth mode (N = 6000, I_p = 4)",
        "",
        "A run is lost when its final position error exceeds the threshold (100 m). Each cell is "
        "the share of lost runs, with its MC error (2 x its binomial standard error) in brackets.",
        "",
        _row(["preset", "truth", "runs", *LOST_COLUMNS]),
        _row(["---"] * (3 + len(LOST_COLUMNS))),
    ]
    for label, d in docs.items():
        if label.startswith(LOSS):
            res, c = d["filters"], d["config"]
            lines.append(
                _row(
                    [
                        c["preset"],
                        c["truth"],
                        c["runs"],
                        *(_lost(res[n], c["runs"]) if n in res else "–" for n in LOST_COLUMNS),
                    ]
                )
            )
    lines += [
        "",
        _row(["preset", "truth", *(f"RMSE {n}" for n in LOST_RMSE)]),
        _row(["---"] * (2 + len(LOST_RMSE))),
    ]
    for label, d in docs.items():
        if label.startswith(LOSS):
            res, c = d["filters"], d["config"]
            rmse = (_fmt(res[n]["rmse_overall"]) if n in res else "–" for n in LOST_RMSE)
            lines.append(_row([c["preset"], c["truth"], *rmse]))
    return lines


LOST_COLUMNS = [
    "source-pf",
    "pf",
    "tl-pf",
    "source-rpf",
    "rpf",
    "tl-rpf",
    "robust-tl-rpf",
    "ukf",
    "tl-ukf",
]
LOST_RMSE = ["pf", "tl-pf", "rpf", "tl-rpf", "robust-tl-rpf", "ukf", "tl-ukf"]


def _lost(r: dict[str, Any], runs: int) -> str:
    p = r["lost_fraction"]
    return f"{p:.2%} ({2 * (p * (1 - p) / runs) ** 0.5:.2%})"


def losses_report(docs: dict[str, dict[str, Any]], out: Path) -> Path:
    """The lost-track table alone (``tltrack reproduce --losses-only``)."""
    lines = lost_by_truth_section(docs)
    lines += ["", f"Total wall time: {wall_minutes(docs):.1f} min."]
    path = out / "losses.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def figures(docs: dict[str, dict[str, Any]], gains: dict[str, list[float]], out: Path) -> list[str]:
    """The paper's figures, drawn from our runs with its quoted values as references."""
    f = {label: d["filters"] for label, d in docs.items()}
    plots.rmse_vs_time(docs[S1], out / "fig_s1_rmse.png", "Scenario 1: RMSE against time")
    plots.rmse_vs_time(docs[s2_label(4)], out / "fig_s2_rmse.png", "Scenario 2: RMSE against time")
    plots.curves(
        INTENSITIES,
        {n: [f[s2_label(i)][n]["rmse_overall"] for i in INTENSITIES] for n in ALL_FILTERS},
        out / "fig_rmse_vs_ip.png",
        xlabel="primary noise intensity I_p",
        ylabel="overall RMSE [m]",
        title="Scenario 2: overall RMSE against I_p",
        reference={
            n: [RMSE_AT_IP.get((n, i), float("nan")) for i in INTENSITIES]
            for n in ("pf", "tl-pf", "tl-ckf5")
        },
    )
    plots.curves(
        [i - 1 for i in INTENSITIES],
        gains,
        out / "fig_delta_rmse.png",
        xlabel="Delta I_w = |I_p - I_s|",
        ylabel="Delta RMSE [m]",
        title="Scenario 2: RMSE gain of transfer against Delta I",
        reference={
            k: [DELTA_AT_DI.get((k, i - 1), float("nan")) for i in INTENSITIES] for k in KINDS
        },
    )
    plots.curves(
        PARTICLES,
        {
            n: [f[s2_label(4, p)][n]["rmse_overall"] for p in PARTICLES]
            for n in PF_FILTERS + RPF_FILTERS
        },
        out / "fig_rmse_time_vs_n.png",
        xlabel="particles N_s",
        ylabel="overall RMSE [m]",
        title="Scenario 2: RMSE against N_s (ms per step in report.md)",
        reference={
            "pf": [TABLE2["pf", p][0] for p in PARTICLES],
            "tl-pf": [TABLE2["pf", p][2] for p in PARTICLES],
        },
    )
    return [
        "Figures: ![s1](fig_s1_rmse.png) ![s2](fig_s2_rmse.png) ![ip](fig_rmse_vs_ip.png) "
        "![delta](fig_delta_rmse.png) ![n](fig_rmse_time_vs_n.png)",
    ]


def report(docs: dict[str, dict[str, Any]], out: Path) -> Path:
    """Figures plus ``report.md``: each printed number beside ours and the difference."""
    f = {label: d["filters"] for label, d in docs.items()}
    cfg = docs[s2_label(4)]["config"]
    gains = transfer_gains(f)
    sections = [
        [
            "# Reproduction of the seed's Simulation Results",
            "",
            f"{cfg['runs']} Monte-Carlo runs per point (the paper: 10,000); preset "
            f"`{cfg['preset']}`, truth `{cfg['truth']}`, seed {cfg['seed']}. "
            "Difference = ours - paper.",
        ],
        table2_section(f),
        rmse_at_k_section(f),
        rmse_against_ip_section(f),
        gain_section(gains),
        lost_by_job_section(f),
        lost_by_truth_section(docs),
        [
            f"Wall time of all jobs: {wall_minutes(docs):.1f} min (the sources of each I_p "
            "sweep, and a job repeated under another label, computed once)."
        ],
        figures(docs, gains, out),
    ]
    path = out / "report.md"
    path.write_text("\n\n".join("\n".join(s) for s in sections) + "\n")
    (out / "summary.json").write_text(json.dumps(f))
    return path


def base_config(preset: str, truth: str, runs: int, seed: int) -> Config:
    return make_config(preset=preset, truth=truth, runs=runs, seed=seed)
