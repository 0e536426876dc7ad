"""The ``tltrack`` command line. Option names are a contract: other tools call them."""

from __future__ import annotations

import json
from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from tltrack.config import Config, ConfigError
from tltrack.live.topology import Kind as TopologyKind

app = typer.Typer(
    help="Bayesian transfer learning between tracking operators (TL-PF): experiments, "
    "the paper's figures, and the live dual tracker.",
    no_args_is_help=True,
    rich_markup_mode="markdown",
)
console = Console(stderr=True)


def progress_bar(total: int, what: str) -> Progress:
    """A progress bar on stderr, for long Monte-Carlo work."""
    p = Progress(
        TextColumn(f"[bold]{what}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=False,
        disable=not console.is_terminal and total < 2,
    )
    return p


#: ``--scheduler``, shared by the commands that run the Monte-Carlo engine.
Scheduler = Annotated[
    str | None,
    typer.Option(
        envvar="TLTRACK_SCHEDULER",
        help="run the batches on the Dask cluster of this scheduler (tcp://HOST:PORT) instead of "
        "the local process pool",
    ),
]
#: ``--workers`` and ``--batch-size``, likewise.
Workers = Annotated[
    int | None, typer.Option(help="worker processes of the local pool (default: all cores)")
]
BatchSize = Annotated[int | None, typer.Option(help="runs per vectorised batch")]


@contextmanager
def engine_pool(scheduler: str | None, workers: int | None) -> Iterator[Executor | None]:
    """The Dask cluster's executor for ``--scheduler``, or None for the local pool; exits with
    the reason when the two options clash or the cluster cannot be used."""
    from tltrack.engine import cluster

    address = cluster.address(scheduler)
    if reason := cluster.refuse_workers(address, workers):
        console.print(f"[red]error:[/red] {reason}")
        raise typer.Exit(2)
    try:
        with cluster.pool(address, say=console.print) as ex:
            if ex is not None:
                console.print(f"batches go to the Dask cluster at {address}")
            yield ex
    except cluster.SchedulerError as err:
        console.print(f"[red]error:[/red] {err}")
        raise typer.Exit(1) from None


def build_config(config: Path | None, **overrides: Any) -> Config:
    """Preset/file first, then any option given on the command line; exits with the field named."""
    from tltrack.config import load_config

    source_intensity = overrides.pop("source_intensity", None)
    sources = overrides.pop("sources", None)
    fault = overrides.pop("source_fault", None)
    source_filter = overrides.pop("source_filter", None)
    try:
        if sources is not None and source_intensity is not None:
            raise ConfigError("--sources: give either --sources or --source-intensity, not both")
        if sources is not None:
            overrides["sources"] = _parse_sources(sources)
        cfg = load_config(config, **overrides)  # completed from a truth file, if any
        if source_intensity is not None:
            cfg = cfg.with_source_intensity(source_intensity)
        if fault is not None:
            first = {**cfg.sources[0].model_dump(), "fault": fault}
            cfg = cfg.with_(sources=[first, *cfg.sources[1:]])
        if source_filter is not None:
            cfg = cfg.with_(
                sources=[{**s.model_dump(), "filter": source_filter} for s in cfg.sources],
                trusted_changes=True,
            )
    except ValueError as err:  # a ConfigError, or a truth file refused
        console.print(f"[red]error:[/red] invalid configuration: {err}")
        raise typer.Exit(2) from None
    return cfg


def _parse_sources(text: str) -> list[dict[str, Any]]:
    """``"1,2,8"`` -> sources s1, s2, s3 at the origin with those noise intensities."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(f"--sources: {text!r} is not a comma-separated list of numbers") from None
    return [{"id": f"s{i + 1}", "intensity": v} for i, v in enumerate(values)]


@app.command(
    epilog="Examples:\n\n"
    "    tltrack experiment --scenario ct --preset arasaratnam-haykin --truth noise-free "
    "--filters pf,tl-pf --particles 6000 --runs 200 --primary-intensity 4 --seed 1 --out /tmp/e\n\n"
    "    tltrack experiment --config my.toml --filters ukf,tl-ukf --out out/ukf"
)
def experiment(
    scenario: Annotated[
        str | None,
        typer.Option(help="the motion model: cv (Scenario 1), ct (Scenario 2), ca, or a plugin's"),
    ] = None,
    preset: Annotated[str | None, typer.Option(help="paper or arasaratnam-haykin")] = None,
    config: Annotated[Path | None, typer.Option(help="TOML or JSON config file")] = None,
    filters: Annotated[str, typer.Option(help="comma-separated filter names")] = "pf,tl-pf",
    particles: Annotated[int | None, typer.Option(help="particles per PF")] = None,
    runs: Annotated[int | None, typer.Option(help="Monte-Carlo runs")] = None,
    source_intensity: Annotated[float | None, typer.Option(help="I_w of the source")] = None,
    sources: Annotated[
        str | None, typer.Option(help="several sources at the origin, by intensity, e.g. 1,2,8")
    ] = None,
    source_fault: Annotated[
        str | None, typer.Option(help="fault of the (first) source: none, bias, diverged or stale")
    ] = None,
    source_filter: Annotated[
        str | None,
        typer.Option(help="every source's filter kind (default: its TL primary's kind)"),
    ] = None,
    transfer_budget: Annotated[
        float | None, typer.Option(help="robust-tl-*: at most this share of steps with a transfer")
    ] = None,
    primary_intensity: Annotated[float | None, typer.Option(help="I_w of the primary")] = None,
    truth: Annotated[str | None, typer.Option(help="fixed, random or noise-free")] = None,
    seed: Annotated[int | None, typer.Option(help="master seed of every random stream")] = None,
    truth_seed: Annotated[int | None, typer.Option(help="seed of the fixed truth")] = None,
    truth_file: Annotated[
        Path | None,
        typer.Option(help="a recorded track as the truth (CSV t,x,y or t,lat,lon); no --truth"),
    ] = None,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/experiment"),
    recovery: Annotated[
        bool | None,
        typer.Option(
            "--recovery/--no-recovery", help="reinitialise lost particle filters (default: off)"
        ),
    ] = None,
    rpf_bandwidth: Annotated[
        float | None,
        typer.Option(help="rpf: regularisation kernel bandwidth h in [0, 1) (default 0: off)"),
    ] = None,
    workers: Workers = None,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
) -> None:
    """Run the Monte-Carlo engine; write DIR/results.json, rmse.png and trajectory.png."""
    from tltrack.engine.experiment import run_and_save
    from tltrack.engine.montecarlo import check_filters
    from tltrack.engine.registry import parse

    cfg = build_config(
        config,
        scenario=scenario,
        preset=preset,
        particles=particles,
        runs=runs,
        source_intensity=source_intensity,
        primary_intensity=primary_intensity,
        truth=truth,
        seed=seed,
        truth_seed=truth_seed,
        truth_file=truth_file,
        sources=sources,
        source_fault=source_fault,
        source_filter=source_filter,
        transfer_budget=transfer_budget,
        recovery=recovery,
        rpf_bandwidth=rpf_bandwidth,
    )
    names = [n.strip() for n in filters.split(",") if n.strip()]
    try:
        for n in names:
            parse(n, trusted=True)
        check_filters(cfg, names)
    except ValueError as err:
        console.print(f"[red]error:[/red] --filters: {err}")
        raise typer.Exit(2) from None
    with engine_pool(scheduler, workers) as executor, progress_bar(cfg.runs, "runs") as bar:
        task = bar.add_task("runs", total=cfg.runs)
        doc = run_and_save(
            cfg,
            names,
            out,
            workers=workers,
            batch_size=batch_size,
            progress=lambda n: bar.advance(task, n),
            executor=executor,
        )
    _print_table(doc)
    console.print(f"wrote {out / 'results.json'}, {out / 'rmse.png'}, {out / 'trajectory.png'}")


def _print_table(doc: dict[str, Any]) -> None:
    from rich.table import Table

    t = Table(
        title="position RMSE (paper's overall definition)",
        caption="NEES*: the covariance was singular (a collapsed cloud) on some run-steps",
    )
    for col in ("filter", "RMSE [m]", "lost", "NEES", "ms/step"):
        t.add_column(col, justify="right" if col != "filter" else "left")
    for name, r in doc["filters"].items():
        ms = r["ms_per_step"]
        t.add_row(
            name,
            f"{r['rmse_overall']:.2f}",
            f"{r['lost_fraction']:.1%}",
            f"{r['nees']:.4g}{'*' if r['nees_singular_rate'] > 0 else ''}",
            "-" if ms is None else f"{ms:.3f}",
        )
    Console().print(t)


@app.command()
def plot(
    results_json: Annotated[Path, typer.Argument(help="a results.json written by experiment")],
    out: Annotated[Path | None, typer.Option(help="directory (default: beside the file)")] = None,
) -> None:
    """Redraw the figures of a saved result.

    Example: `tltrack plot out/experiment/results.json`
    """
    from tltrack.engine.experiment import draw
    from tltrack.engine.results import read

    try:
        doc = read(results_json)
    except (OSError, ValueError, KeyError) as err:
        console.print(f"[red]error:[/red] cannot read {results_json}: {err}")
        raise typer.Exit(2) from None
    for p in draw(doc, out or results_json.parent):
        console.print(f"wrote {p}")


@app.command(
    epilog="Examples:\n\n    tltrack reproduce --runs 500 --out out/reproduce\n\n"
    "    tltrack reproduce --runs 200 --preset arasaratnam-haykin --truth noise-free"
)
def reproduce(
    runs: Annotated[int, typer.Option(help="Monte-Carlo runs per point (paper: 10000)")] = 500,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/reproduce"),
    preset: Annotated[str, typer.Option(help="paper or arasaratnam-haykin")] = "paper",
    truth: Annotated[str, typer.Option(help="fixed, random or noise-free")] = "fixed",
    seed: Annotated[int, typer.Option(help="master seed")] = 0,
    workers: Workers = None,
    table2_pf_only: Annotated[
        bool, typer.Option(help="only Table 2's particle-filter rows (the 10,000-run benchmark)")
    ] = False,
    losses_only: Annotated[
        bool, typer.Option(help="only the lost-track table, for both presets and truth modes")
    ] = False,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
) -> None:
    """Regenerate every figure and table of the paper's Simulation Results, with report.md."""
    from tltrack.studies import reproduce as rep

    if table2_pf_only and losses_only:
        console.print("[red]error:[/red] --table2-pf-only and --losses-only: choose one")
        raise typer.Exit(2)
    try:
        base = rep.base_config(preset, truth, runs, seed)
    except ConfigError as err:
        console.print(f"[red]error:[/red] invalid configuration: {err}")
        raise typer.Exit(2) from None
    if table2_pf_only:
        todo, write = rep.table2_pf_jobs(base), rep.table2_pf_report
    elif losses_only:
        todo, write = rep.loss_jobs(base), rep.losses_report
    else:
        todo, write = rep.jobs(base) + rep.loss_jobs(base), rep.report
    with engine_pool(scheduler, workers) as executor, progress_bar(runs, "reproduce") as bar:
        tasks = {j.label: bar.add_task(j.label, total=runs) for j in todo}
        docs = rep.run_all(
            todo,
            out,
            workers=workers,
            batch_size=batch_size,
            executor=executor,
            progress=lambda label, n: bar.advance(tasks[label], n),
        )
    made = write(docs, out)
    console.print(f"wrote {made}")


@app.command()
def router(
    listen: Annotated[list[str] | None, typer.Option(help="endpoint(s) to listen on")] = None,
    connect: Annotated[
        list[str] | None, typer.Option(help="other routers to dial (redialled when lost)")
    ] = None,
    operator: Annotated[
        str | None,
        typer.Option(
            help="be this operator's router of the federated topology (referee, primary, "
            "source/<id>): the package's ACL and dictionary for it, dialling as router-<operator>"
        ),
    ] = None,
) -> None:
    """Run a Zenoh router (the Python package in router mode) until Ctrl-C or SIGTERM.

    Example: `tltrack router --listen tcp/0.0.0.0:7447`; the primary's router of the federated
    topology: `tltrack router --operator primary --listen tcp/0.0.0.0:7447 --connect
    tls/referee.example.org:7448`. The environment (TLTRACK_ZENOH_*) overrides what --operator sets.
    """
    import os
    import tempfile

    from tltrack.live import topology
    from tltrack.wire import keys
    from tltrack.wire.transport import ZenohSettings, run_router

    if operator is not None and not (
        operator in (keys.REFEREE, keys.PRIMARY)
        or f"router-{operator.replace('/', '-')}" in topology.all_passwords()
    ):
        console.print(f"[red]error:[/red] --operator: unknown operator {operator!r}")
        raise typer.Exit(2)
    with tempfile.TemporaryDirectory(prefix="tltrack-router-") as tmp:
        if operator is not None:
            for name, value in topology.access_env(operator, Path(tmp)).items():
                os.environ.setdefault(name, value)
        run_router(listen or ["tcp/0.0.0.0:7447"], ZenohSettings(), connect=connect)


@app.command(
    epilog="Examples:\n\n    tltrack demo\n\n    tltrack demo --steps 50 --particles 2000 "
    "--json /tmp/d.json\n\n    tltrack demo --realtime\n\n    tltrack demo --serve   "
    "# then open http://127.0.0.1:8050/ ; Ctrl-C stops everything"
)
def demo(
    config: Annotated[
        Path | None, typer.Option(help="TOML or JSON config: every source gets a tracker")
    ] = None,
    steps: Annotated[int | None, typer.Option(help="steps K of the episode [100]")] = None,
    particles: Annotated[int | None, typer.Option(help="particles per PF [6000]")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the summary here")] = None,
    pace: Annotated[float, typer.Option(help="steps per second")] = 20.0,
    realtime: Annotated[bool, typer.Option(help="pace at one step per Ts")] = False,
    preset: Annotated[
        str | None, typer.Option(help="paper or arasaratnam-haykin [arasaratnam-haykin]")
    ] = None,
    truth: Annotated[str | None, typer.Option(help="fixed, random or noise-free [fixed]")] = None,
    seed: Annotated[int | None, typer.Option(help="master seed [0]")] = None,
    out: Annotated[Path, typer.Option(help="logs and the scorer's database")] = Path("out/demo"),
    serve: Annotated[
        bool, typer.Option(help="also run the live dashboard; keep everything up until Ctrl-C")
    ] = False,
    port: Annotated[int, typer.Option(help="dashboard port (with --serve)")] = 8050,
    host: Annotated[str, typer.Option(help="dashboard address (with --serve)")] = "127.0.0.1",
    topology: Annotated[
        TopologyKind, typer.Option(help="a router per operator (federated), or one for all")
    ] = "federated",
) -> None:
    """Start the routers, the scorer, the trackers, the sensors and sensor_sim on loopback, run
    one episode, print the summary.

    Without --config the episode is the arasaratnam-haykin preset with a fixed truth, K = 100,
    N = 6000 (the values in brackets); with it, the file's values, unless an option overrides
    them. Federated: one router per operator (referee, primary, each source), each letting out
    only what its owner shares; single: one router for all. The routers enforce the package's
    access control; every service runs as its operator. Any stop signal (or the death of this
    process) stops every process it started.
    """
    from tltrack.live import supervisor as d

    if config is None:
        preset, truth = preset or "arasaratnam-haykin", truth or "fixed"
        steps, particles, seed = steps or 100, particles or 6000, seed or 0
    cfg = build_config(config, preset=preset, truth=truth, K=steps, particles=particles, seed=seed)
    try:
        d.check_access(cfg)
    except d.AccessControlMissingError as err:
        console.print(f"[red]error:[/red] {err}")
        raise typer.Exit(2) from None
    flags = d.sim_flags(steps, particles, pace, realtime, preset, truth, seed, config=config)
    try:
        with d.stop_on_signals():
            summary = _run_demo(d, cfg, flags, pace, realtime, out, serve, port, host, topology)
    except d.Interrupted as stop:
        console.print(f"stopped by {stop}; the router and every service are stopped")
        raise typer.Exit(128 + stop.signum) from None
    if json_out:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(summary, indent=1))
        console.print(f"wrote {json_out}")


def _run_demo(
    d: Any,
    cfg: Config,
    sim_flags: list[str],
    pace: float,
    realtime: bool,
    out: Path,
    serve: bool,
    port: int,
    host: str,
    kind: TopologyKind = "federated",
) -> dict[str, Any]:
    """One episode on a fresh stack; the scorer's summary, with ``access_control`` and
    ``topology`` set."""
    from tltrack.filters.warm import warm_up
    from tltrack.live import topology
    from tltrack.live.summary import print_summary

    topo = topology.build(kind, [s.id for s in cfg.sources])
    endpoint = topo.referee.endpoint
    db = out / "scorer.sqlite"
    for suffix in ("", "-wal", "-shm"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    console.print(
        f"{kind} topology, routers: {topology.describe(topo)} (access control: "
        f"{d.ACCESS_DIR}); logs in {out / 'logs'}"
    )
    warm_up()  # compile the kernels once here, not in several services at once
    with d.Stack(endpoint, out / "logs", secure=True, topology=topo) as stack:
        stack.start_router()
        stack.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db)})
        wait_for = stack.start_trackers(cfg)
        page = ""
        if serve:
            from tltrack.services.dashboard import launch

            page = launch.start(stack, port, host)
            if not launch.wait_ready(page, 30):
                console.print(
                    f"[red]error:[/red] the dashboard did not start (port {port} "
                    f"taken?); see {out / 'logs' / 'dashboard.log'}"
                )
                raise typer.Exit(1)
            wait_for.append(launch.TOKEN)  # sensor_sim also waits for the page: no step missed
            console.print(f"dashboard: [bold]{page}[/bold]  (Prometheus metrics: {page}metrics)")
        sim_env = {"TLTRACK_SIM_WAIT_FOR": json.dumps(wait_for)}
        stack.start_service("sensor_sim", *sim_flags, env=sim_env)
        K = cfg.K
        budget = K * (cfg.Ts if realtime else 1.0 / pace if pace > 0 else 0.0) + 120
        with progress_bar(K, "episode") as bar:
            task = bar.add_task("episode", total=None)
            rc = stack.wait("sensor_sim", budget)
            bar.update(task, completed=K, total=K)
        if rc != 0:
            console.print(f"[red]error:[/red] sensor_sim ended with {rc}; see {out / 'logs'}")
            raise typer.Exit(1)
        summary = d.wait_for_scored(endpoint, 1, 120, "referee")
        if summary is None:
            console.print(f"[red]error:[/red] the scorer gave no summary; see {out / 'logs'}")
            raise typer.Exit(1)
        summary["access_control"] = True  # the routers enforced the ACL; every service logged in
        summary["topology"] = kind
        print_summary(summary)
        if serve:
            console.print(f"dashboard: [bold]{page}[/bold] stays up; Ctrl-C stops everything")
            d.serve_until_interrupted(stack, "dashboard")
        else:
            console.print(
                "live page: tltrack demo --serve  ->  http://127.0.0.1:8050/ "
                "(Prometheus metrics at /metrics)"
            )
    return summary


@app.command(
    epilog="Examples:\n\n    tltrack study robust --runs 200\n\n"
    "    tltrack study robust --kind rpf --source-filter pf --preset paper --truth fixed\n\n"
    "    tltrack study heterogeneous --runs 200\n\n"
    "    tltrack study realizations --realizations 100 --runs 50 --preset paper"
)
def study(
    name: Annotated[
        str,
        typer.Argument(
            help="robust, sources, budget, heterogeneous, presets, intensities or realizations"
        ),
    ],
    runs: Annotated[int, typer.Option(help="Monte-Carlo runs per configuration")] = 200,
    out: Annotated[Path, typer.Option(help="output directory")] = Path("out/studies"),
    seed: Annotated[int, typer.Option(help="master seed (the robust design was tuned on 1)")] = 0,
    kind: Annotated[str, typer.Option(help="the filter kind studied (pf, ukf, ...)")] = "pf",
    source_filter: Annotated[
        str | None, typer.Option(help="the sources' filter kind (default: --kind)")
    ] = None,
    preset: Annotated[str, typer.Option(help="paper or arasaratnam-haykin")] = "arasaratnam-haykin",
    truth: Annotated[str, typer.Option(help="fixed, random or noise-free")] = "noise-free",
    truth_file: Annotated[
        Path | None, typer.Option(help="a recorded track as the truth (not realizations)")
    ] = None,
    particles: Annotated[
        int | None, typer.Option(help="particles per PF (default: the study's own)")
    ] = None,
    realizations: Annotated[int, typer.Option(help="realizations (study realizations)")] = 100,
    filters: Annotated[
        str, typer.Option(help="filters (study realizations)")
    ] = "pf,tl-pf,ukf,tl-ukf,ckf3,tl-ckf3,ckf5,tl-ckf5",
    workers: Workers = None,
    batch_size: BatchSize = None,
    scheduler: Scheduler = None,
) -> None:
    """A study beyond the paper: a markdown report, its numbers (JSON) and a figure."""
    from tltrack import studies
    from tltrack.filters.kinds import FILTERS

    def known_kind(k: str | None) -> bool:
        try:
            return k is None or FILTERS.get(k, trusted=True) is not None
        except ValueError:
            return False

    by_name = {
        "robust": studies.robust,
        "sources": studies.sources,
        "budget": studies.budget,
        "heterogeneous": studies.heterogeneous,
        "presets": studies.presets,
        "intensities": studies.intensities,
    }
    known = [*by_name, "realizations"]
    problems = [
        "" if name in known else f"unknown study {name!r}; use {', '.join(known)}",
        "" if known_kind(kind) else f"--kind: unknown kind {kind!r}",
        "" if known_kind(source_filter) else f"--source-filter: unknown {source_filter!r}",
        "" if realizations >= 2 else "--realizations must be at least 2",
    ]
    if any(problems):
        console.print(f"[red]error:[/red] {'; '.join(p for p in problems if p)}")
        raise typer.Exit(2)
    setting = studies.Setting(runs, seed, kind, source_filter, preset, truth, truth_file, particles)
    total = runs * (realizations if name == "realizations" else 1)
    with engine_pool(scheduler, workers) as executor, progress_bar(total, name) as bar:
        task = bar.add_task(name, total=None)
        runner = studies.Runner(lambda n: bar.advance(task, n), workers, batch_size, executor)
        try:
            if name == "realizations":
                names = [f.strip() for f in filters.split(",") if f.strip()]
                path = studies.realizations(setting, runner, out, count=realizations, filters=names)
            else:
                path = by_name[name](setting, runner, out)
        except ValueError as err:  # a refused configuration or filter
            console.print(f"[red]error:[/red] {err}")
            raise typer.Exit(2) from None
    console.print(Path(path).read_text(), markup=False)
    console.print(f"wrote {path}")


@app.command("bench-live")
def bench_live(
    particles: Annotated[int, typer.Option(help="particles per PF")] = 6000,
    pace: Annotated[float, typer.Option(help="steps/s for the latency run")] = 50.0,
    steps: Annotated[int, typer.Option(help="steps of the latency episode")] = 500,
    rates: Annotated[
        str, typer.Option(help="step rates to try, ascending; the ladder stops at the first missed")
    ] = "100,200,300,500,800,1000",
    ladder_steps: Annotated[int, typer.Option(help="steps per rung of the rate ladder")] = 5000,
    filters: Annotated[str, typer.Option(help="particle filter kinds, comma-separated")] = "rpf,pf",
    json_out: Annotated[Path | None, typer.Option("--json", help="write the figures here")] = None,
    topology: Annotated[
        Literal["federated", "single", "both"],
        typer.Option(help="a router per operator (federated), one for all (single), or both"),
    ] = "both",
) -> None:
    """Benchmark the live pair: latency at a moderate pace, the routed round trip and the TL step
    it is compared with, and the highest sustained rate, for each topology x filter kind (one
    entry each under `runs`; the defaults, federated and rpf, also at the top level).

    Example: `tltrack bench-live --particles 6000 --pace 50 --json out/live.json`
    """
    from tltrack.live.supervisor import Interrupted, stop_on_signals
    from tltrack.perf import livebench

    kinds = get_args(TopologyKind) if topology == "both" else (topology,)
    from tltrack.filters.kinds import FILTERS

    kinds_of_filter = tuple(f.strip() for f in filters.split(","))
    if unknown := [f for f in kinds_of_filter if f not in FILTERS or not FILTERS.get(f).particle]:
        console.print(f"[red]error:[/red] --filters: not a particle filter kind: {unknown}")
        raise typer.Exit(2)
    try:
        ladder = [float(r) for r in rates.split(",")]
    except ValueError:
        console.print(f"[red]error:[/red] --rates: not a list of numbers: {rates!r}")
        raise typer.Exit(2) from None
    try:
        with stop_on_signals():
            result = livebench.run(
                particles, pace, steps, ladder, kinds, kinds_of_filter, ladder_steps
            )
    except Interrupted as stop:
        console.print(f"stopped by {stop}; the router and every service are stopped")
        raise typer.Exit(128 + stop.signum) from None
    text = json.dumps(result, indent=1)
    console.print(text)
    if json_out:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(text)


@app.command()
def bench(
    particles: Annotated[int, typer.Option(help="particles per PF")] = 6000,
    repeats: Annotated[int, typer.Option(help="passes over the K steps")] = 3,
    json_out: Annotated[Path | None, typer.Option("--json", help="write the figures here")] = None,
) -> None:
    """Time one filter step (tl-pf, pf, source-pf) against plain NumPy and Stone Soup, side by side.

    Example: `tltrack bench --json out/bench.json` (Stone Soup needs the `bench` extra)
    """
    from tltrack.perf.bench import format_table, run_bench

    result = run_bench(particles=particles, repeats=repeats)
    console.print(format_table(result))
    if json_out:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(result, indent=1))
        console.print(f"wrote {json_out}")
