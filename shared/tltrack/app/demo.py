"""``tltrack demo``: the live dual tracker on loopback, one episode, the scorer's summary."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from tltrack.app.access import ManifestOption, manifest_or_exit
from tltrack.app.common import (
    app,
    build_config,
    checked_file,
    checked_folder,
    console,
    progress_bar,
    say_error,
)
from tltrack.config import Config
from tltrack.live.topology import Kind as TopologyKind


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
    pace: Annotated[
        float, typer.Option(min=0, help="steps per second; 0: as fast as possible")
    ] = 20.0,
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
    port: Annotated[
        int, typer.Option(min=1, max=65535, help="dashboard port (with --serve)")
    ] = 8050,
    host: Annotated[str, typer.Option(help="dashboard address (with --serve)")] = "127.0.0.1",
    topology: Annotated[
        TopologyKind, typer.Option(help="a router per operator (federated), or one for all")
    ] = "federated",
    manifest: ManifestOption = None,
) -> None:
    """Start the routers, the scorer, the trackers, the sensors and sensor_sim on loopback, run
    one episode, print the summary.

    Without --config the episode is the arasaratnam-haykin preset with a fixed truth, K = 100,
    N = 6000 (the values in brackets); with it, the file's values, unless an option overrides
    them. Federated: one router per operator (referee, primary, each source), each letting out
    only what its owner shares; single: one router for all. The routers enforce the package's
    access control, from the operator manifest; every service runs as its operator. Any stop
    signal (or the death of this process) stops every process it started.
    """
    from tltrack.live import supervisor as d

    if config is None:
        preset, truth = preset or "arasaratnam-haykin", truth or "fixed"
        steps = 100 if steps is None else steps  # 0 is the config's to refuse, not a default
        particles = 6000 if particles is None else particles
        seed = 0 if seed is None else seed
    cfg = build_config(config, preset=preset, truth=truth, K=steps, particles=particles, seed=seed)
    checked_folder(out)
    if json_out:
        checked_file(json_out, "--json")
    if serve:
        _check_can_serve(host, port)
    try:
        d.check_access(manifest_or_exit(manifest), cfg)
    except (ValueError, d.AccessControlMissingError) as err:
        say_error(str(err))
        raise typer.Exit(2) from None
    flags = d.sim_flags(steps, particles, pace, realtime, preset, truth, seed, config=config)
    try:
        with d.stop_on_signals():
            summary = _run_demo(
                cfg, flags, pace, realtime, out, serve, port, host, topology, manifest
            )
    except d.Interrupted as stop:
        console.print(f"stopped by {stop}; the router and every service are stopped")
        raise typer.Exit(128 + stop.signum) from None
    if json_out:
        json_out.write_text(json.dumps(summary, indent=1))
        console.print(f"wrote {json_out}")


def _run_demo(
    cfg: Config,
    sim_flags: list[str],
    pace: float,
    realtime: bool,
    out: Path,
    serve: bool,
    port: int,
    host: str,
    kind: TopologyKind = "federated",
    manifest: Path | None = None,
) -> dict[str, Any]:
    """One episode on a fresh stack; the scorer's summary, with ``access_control`` and
    ``topology`` set."""
    from tltrack.filters.warm import warm_up
    from tltrack.live import supervisor as d
    from tltrack.live import topology
    from tltrack.live.access import ACCESS_DIR
    from tltrack.live.summary import print_summary

    topo = topology.build(kind, [s.id for s in cfg.sources])
    endpoint = topo.referee.endpoint
    db = out / "scorer.sqlite"
    for suffix in ("", "-wal", "-shm"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    console.print(
        f"{kind} topology, routers: {topology.describe(topo)} (access control: "
        f"{ACCESS_DIR}); logs in {out / 'logs'}"
    )
    warm_up()  # compile the kernels once here, not in several services at once
    with d.Stack(endpoint, out / "logs", True, topology=topo, manifest_file=manifest) as stack:
        stack.start_router()
        stack.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db)})
        wait_for = stack.start_trackers(cfg)
        page = ""
        if serve:
            from tltrack.services.dashboard import launch

            page = launch.start(stack, port, host)
            if not launch.wait_ready(page, 30):
                say_error(
                    f"the dashboard did not start (port {port} taken?); see "
                    f"{out / 'logs' / 'dashboard.log'}"
                )
                raise typer.Exit(1)
            wait_for.append(launch.TOKEN)  # sensor_sim also waits for the page: no step missed
            console.print(f"dashboard: [bold]{page}[/bold]  (Prometheus metrics: {page}metrics)")
        stack.start_service("sensor_sim", *sim_flags, env=d.sim_env(wait_for))
        K = cfg.K
        budget = K * (cfg.Ts if realtime else 1.0 / pace if pace > 0 else 0.0) + 120
        with progress_bar(K, "episode") as bar:
            task = bar.add_task("episode", total=K)
            rc = d.wait_for_episode(stack, budget, lambda k: bar.update(task, completed=k))
            if rc == 0:  # its last statistics may precede its last steps by up to a second
                bar.update(task, completed=K)
        if rc != 0:
            say_error(f"sensor_sim ended with {rc}; see {out / 'logs'}")
            raise typer.Exit(1)
        summary = d.wait_for_scored(endpoint, 1, 120, "referee")
        if summary is None:
            say_error(f"the scorer gave no summary; see {out / 'logs'}")
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


def _check_can_serve(host: str, port: int) -> None:
    """Exit 2 unless the dashboard could listen on host:port: found out only after the whole
    stack had started (a host with a space was a traceback, a taken port a 30 s wait)."""
    from tltrack.live.topology import why_cannot_listen

    if why := why_cannot_listen(host, port):
        say_error(f"--host {host!r} --port {port}: the dashboard cannot listen there: {why}")
        raise typer.Exit(2)
