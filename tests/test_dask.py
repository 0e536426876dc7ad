"""Monte-Carlo sweeps on a Dask cluster (``--scheduler``), against the local process pool.

The cluster is real processes on loopback, as docs/howto/dask.md starts them by hand:
`dask scheduler` and `dask worker` commands (never an in-process LocalCluster). Worker A has the
preload and a fresh NUMBA_CACHE_DIR, so it compiles the kernels at start; worker B has no
preload. Every process a test starts is stopped by its id at the end, the worker processes the
nannies spawned included (their ids come from the cluster itself).

The first tests need no cluster: how the options combine, and that results are merged in batch
order whatever order batches complete in.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from livestack import wait_until
from test_compose import ROOT, _clean_env, _remove_leftovers, _run, compose, image  # noqa: F401
from tltrack.app import app
from tltrack.config import Config, make_config
from tltrack.engine import cluster
from tltrack.engine.montecarlo import FilterResult, run_experiment
from typer.testing import CliRunner

BIN = Path(sys.executable).parent
FILTERS = ["pf", "tl-pf", "tl-ukf"]
#: what results.json holds of each filter, bar the timing (ms_per_step)
FIELDS = (
    "rmse_per_step",
    "rmse_overall",
    "nees",
    "nees_singular_rate",
    "lost_fraction",
    "transfer_rate",
)


def small(runs: int = 24, **kw: Any) -> Config:
    return make_config(preset="arasaratnam-haykin", K=40, particles=1500, runs=runs, seed=5, **kw)


def same(a: dict[str, Any], b: dict[str, Any]) -> None:
    """Every filter's results equal (np.array_equal), timing aside."""
    assert a.keys() == b.keys()
    for name in a:
        ra, rb = (r if isinstance(r, dict) else asdict(r) for r in (a[name], b[name]))
        for f in FIELDS:
            assert np.array_equal(ra[f], rb[f], equal_nan=True), (name, f)


# ---- no cluster needed ---------------------------------------------------------------------------


@pytest.mark.unit
def test_scheduler_comes_from_the_option_else_the_environment(monkeypatch):
    monkeypatch.delenv(cluster.ENV, raising=False)
    assert cluster.address(None) is None
    monkeypatch.setenv(cluster.ENV, "tcp://10.0.0.1:8786")
    assert cluster.address(None) == "tcp://10.0.0.1:8786"
    assert cluster.address("tcp://127.0.0.1:1") == "tcp://127.0.0.1:1"
    assert cluster.address("") is None  # --scheduler "" picks the local pool despite the env
    monkeypatch.setenv(cluster.ENV, " ")
    assert cluster.address(None) is None


@pytest.mark.parametrize("command", [["experiment"], ["reproduce"], ["study", "robust"]])
@pytest.mark.unit
def test_workers_with_a_scheduler_is_refused_saying_why(tmp_path, monkeypatch, command):
    monkeypatch.delenv(cluster.ENV, raising=False)
    runner = CliRunner()
    args = [*command, "--workers", "2", "--out", str(tmp_path)]
    r = runner.invoke(app, [*args, "--scheduler", "tcp://127.0.0.1:9"])
    assert r.exit_code == 2, r.output
    text = " ".join(r.output.split())
    assert "--workers sizes the local process pool" in text and "dask worker --nworkers" in text
    r = runner.invoke(app, args, env={cluster.ENV: "tcp://127.0.0.1:9"})
    assert r.exit_code == 2 and "TLTRACK_SCHEDULER" in r.output, r.output
    assert not any(tmp_path.iterdir())  # refused before anything ran


@pytest.mark.unit
def test_every_engine_command_takes_scheduler_workers_and_batch_size():
    runner = CliRunner()
    for command in (["experiment"], ["reproduce"], ["study"]):
        text = runner.invoke(app, [*command, "--help"], terminal_width=200).output
        for option in ("--scheduler", "--workers", "--batch-size", "TLTRACK_SCHEDULER"):
            assert option in text, (command, option)


class LastFirst(Executor):
    """Runs each batch at submit, then completes them last first, one at a time."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.out: list[tuple[Future[Any], Any]] = []

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        fut: Future[Any] = Future()
        self.out.append((fut, fn(*args, **kwargs)))
        if len(self.out) == self.n:
            threading.Thread(target=self._finish).start()
        return fut

    def _finish(self) -> None:
        for fut, result in reversed(self.out):
            fut.set_result(result)
            time.sleep(0.05)


@pytest.mark.unit
def test_batches_merge_in_batch_order_whatever_order_they_complete_in():
    cfg = small(runs=7).with_(K=15, particles=300)
    heard: list[int] = []
    backwards = run_experiment(
        cfg, FILTERS, batch_size=2, executor=LastFirst(4), progress=heard.append, time_steps=False
    )
    assert heard == [1, 2, 2, 2]  # progress as batches complete: the short last batch first
    same(backwards, run_experiment(cfg, FILTERS, batch_size=2, workers=1, time_steps=False))
    with pytest.raises(ValueError, match="not both"):
        run_experiment(cfg, FILTERS, workers=2, executor=LastFirst(4))


# ---- a real cluster on loopback ------------------------------------------------------------------


@dataclass
class Cluster:
    """`dask scheduler` and `dask worker` processes, each with its log file."""

    dir: Path
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    address: str = ""

    def start(self, name: str, *args: str, env: dict[str, str] | None = None) -> None:
        log = (self.dir / f"{name}.log").open("wb")
        self.procs[name] = subprocess.Popen(
            [str(BIN / "dask"), *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, **(env or {})},
        )

    def start_scheduler(self) -> None:
        file = self.dir / "scheduler.json"
        self.start(
            "scheduler",
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--scheduler-file",
            str(file),
            "--no-dashboard",
        )
        assert wait_until(file.exists, 60), self.logs()
        self.address = json.loads(file.read_text())["address"]

    def start_worker(self, name: str, *args: str, env: dict[str, str] | None = None) -> None:
        self.start(
            name,
            "worker",
            "--scheduler-file",
            str(self.dir / "scheduler.json"),
            "--nworkers",
            "1",
            "--nthreads",
            "1",
            "--no-dashboard",
            "--name",
            name,
            *args,
            env=env,
        )

    def client(self) -> Any:
        from distributed import Client

        return Client(self.address, timeout=30, set_as_default=False)

    def worker_pids(self) -> dict[str, int]:
        """worker name -> the id of its worker process (the nanny's child), of the workers the
        scheduler knows and that answer. (A worker may come or go between the two calls, as a
        restarted one does: it is left out, not a KeyError or a CommClosedError.)"""
        with self.client() as c:
            names = {a: w["name"] for a, w in c.scheduler_info(n_workers=-1)["workers"].items()}
            pids = c.run(os.getpid, workers=list(names), on_error="return")
            return {names[a]: pid for a, pid in pids.items() if isinstance(pid, int)}

    def wait_for_workers(self, n: int, timeout: float) -> None:
        with self.client() as c:
            try:
                c.wait_for_workers(n, timeout=timeout)
            except TimeoutError:
                pytest.fail(f"{n} workers did not register within {timeout} s\n{self.logs()}")

    def logs(self) -> str:
        return "\n".join(
            f"---- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
            for p in sorted(self.dir.glob("*.log"))
        )

    def stop(self, extra_pids: list[int] | None = None) -> None:
        """SIGTERM every process started here, SIGKILL any left after 20 s; then the same for the
        worker processes that outlived their nanny."""
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)  # a test may have stopped it
                p.terminate()
        for p in self.procs.values():
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)
        for pid in extra_pids or []:
            if not wait_until(lambda pid=pid: not _alive(pid), 20):
                os.kill(pid, signal.SIGKILL)
        left = [pid for pid in [*(extra_pids or []), *(p.pid for p in self.procs.values())]]
        assert not [pid for pid in left if _alive(pid)], left


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purpose (its parent reaps it)
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


@pytest.fixture(scope="module")
def two_workers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    """A scheduler, worker A (preload, fresh NUMBA_CACHE_DIR) and worker B (no preload)."""
    c = Cluster(tmp_path_factory.mktemp("dask"))
    seen: set[int] = set()
    try:
        c.start_scheduler()
        env_a = {"NUMBA_CACHE_DIR": str(c.dir / "numba-a")}
        c.start_worker("a", "--preload", "tltrack.engine.dask_preload", env=env_a)
        c.start_worker("b")
        t0 = time.monotonic()
        c.wait_for_workers(2, timeout=240)  # worker A compiles every kernel first
        print(f"both workers registered after {time.monotonic() - t0:.1f} s")
        seen.update(c.worker_pids().values())
        yield c
        seen.update(c.worker_pids().values())
    finally:
        c.stop(sorted(seen))


@pytest.fixture(scope="module")
def reference() -> dict[str, FilterResult]:
    """The local process pool's results for :func:`small`, 3 runs a batch."""
    return run_experiment(small(), FILTERS, batch_size=3, workers=2, time_steps=False)


#: the tests on :func:`two_workers` run in one test process, so that its cluster (whose worker A
#: compiles every kernel) starts once
ON_TWO_WORKERS = pytest.mark.xdist_group("dask")


@ON_TWO_WORKERS
@pytest.mark.integration
def test_scheduler_gives_the_local_pools_results_with_batches_on_both_workers(
    two_workers, reference, tmp_path
):
    c = two_workers
    cache = c.dir / "numba-a"
    index = {p.name: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")}
    assert any(n.startswith("propagation.") for n in index), sorted(index)  # by the preload
    log_a = (c.dir / "a.log").read_text()
    assert "tltrack kernels ready" in log_a
    assert "malloc thresholds: 32 MiB / 64 MiB" in log_a  # the nanny's trim threshold undone
    pids = c.worker_pids()
    with c.client() as client:
        before = len(client.get_task_stream())  # (also starts the scheduler's record of tasks)
        cfg = tmp_path / "cfg.json"
        cfg.write_text(small().model_dump_json())
        cmd = [str(BIN / "tltrack"), "experiment", "--config", str(cfg)]
        cmd += ["--filters", ",".join(FILTERS), "--batch-size", "3", "--out", str(tmp_path)]
        proc = subprocess.run(
            cmd,
            env={**os.environ, cluster.ENV: c.address},  # as a user would: the variable
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert proc.returncode == 0, proc.stdout + proc.stderr + c.logs()
        assert f"batches go to the Dask cluster at {c.address}" in proc.stderr
        stream = [t for t in client.get_task_stream()[before:] if "run_sweep_batch" in t["key"]]
        names = {a: w["name"] for a, w in client.scheduler_info(n_workers=-1)["workers"].items()}
    doc = json.loads((tmp_path / "results.json").read_text())
    same(doc["filters"], reference)
    ran_on = {names[t["worker"]] for t in stream}
    print(
        f"batches per worker: { {w: sum(names[t['worker']] == w for t in stream) for w in ran_on} }"
    )
    assert len(stream) == 8 and ran_on == {"a", "b"}, stream
    assert set(pids) == {"a", "b"} and len(set(pids.values())) == 2, pids
    # the preload compiled the kernels once: no batch compiled or rewrote any
    assert {p.name: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")} == index


@ON_TWO_WORKERS
@pytest.mark.integration
def test_a_worker_killed_mid_sweep_costs_only_its_batches(two_workers, reference):
    """Only B's batches run again: those it was running, and those it had finished whose
    results still lived in its memory (the client had not gathered them yet)."""
    c = two_workers
    victim = c.worker_pids()["b"]
    killed: list[float] = []

    def kill_b_once(n: int) -> None:
        if not killed:
            os.kill(victim, signal.SIGKILL)
            killed.append(time.monotonic())

    with c.client() as client:
        workers = client.scheduler_info(n_workers=-1)["workers"]
        at_b = {a for a, w in workers.items() if w["name"] == "b"}
        before = len(client.get_task_stream())
        with cluster.pool(c.address) as ex:
            res = run_experiment(
                small(), FILTERS, batch_size=3, executor=ex, progress=kill_b_once, time_steps=False
            )
        stream = [t for t in client.get_task_stream()[before:] if "run_sweep_batch" in t["key"]]
    assert killed and not _alive(victim)
    same(res, reference)
    keys = [t["key"] for t in stream]
    assert len(set(keys)) == 8, keys  # every batch completed, none lost
    again = [t for t in stream if keys.count(t["key"]) > 1]
    for key in {t["key"] for t in again}:  # every run but the last was on B
        runs = [t["worker"] for t in stream if t["key"] == key]
        assert set(runs[:-1]) <= at_b and runs[-1] not in at_b, (key, runs, at_b)
    # the nanny brought worker B back
    assert wait_until(lambda: "b" in c.worker_pids(), 60), c.logs()
    assert c.worker_pids()["b"] != victim


@pytest.fixture
def lone_worker(tmp_path: Path) -> Iterator[Cluster]:
    c = Cluster(tmp_path)
    seen: list[int] = []
    try:
        c.start_scheduler()
        c.start_worker("w")
        c.wait_for_workers(1, timeout=120)
        seen = list(c.worker_pids().values())
        yield c
    finally:
        c.stop(seen)


@pytest.mark.parametrize("how", ["SIGKILL", "SIGSTOP"])
@pytest.mark.integration
def test_a_scheduler_that_dies_or_hangs_mid_sweep_fails_the_sweep_within_30_s(lone_worker, how):
    """Killed, the client's connection closes; stopped (it holds its connections but answers
    nothing), the watchdog's ping goes unanswered."""
    c = lone_worker
    hit: list[float] = []

    def strike(n: int) -> None:
        if not hit:
            c.procs["scheduler"].send_signal(getattr(signal, how))
            hit.append(time.monotonic())

    with pytest.raises(cluster.SchedulerError) as err, cluster.pool(c.address) as ex:
        run_experiment(small(), FILTERS, batch_size=3, executor=ex, progress=strike)
    waited = time.monotonic() - hit[0]
    print(f"{how}: {err.value} ({waited:.1f} s after the signal)")
    assert waited < 30, waited
    assert c.address in str(err.value)


def _silent_listener() -> socket.socket:
    """A port that accepts connections and never says a word."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    return s


@pytest.mark.integration
def test_a_scheduler_that_does_not_answer_gives_a_clear_error_after_its_connect_timeout(tmp_path):
    """Measured from the command's launch, so the bound is the connect timeout plus the start
    of a process that imports NumPy, SciPy and Dask: the whole took under 30 s in clean-clone
    runs, and 33 s in one beside two CPU-bound jobs, hence 30 s of room for that start."""
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        refused = f"tcp://127.0.0.1:{free.getsockname()[1]}"
    with _silent_listener() as silent:
        mute = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        t0 = time.monotonic()
        procs = {
            a: subprocess.Popen(
                [
                    *[str(BIN / "tltrack"), "reproduce", "--runs", "2", "--table2-pf-only"],
                    *["--scheduler", a, "--out", str(tmp_path / a.rsplit(":", 1)[1])],
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for a in (refused, mute)
        }
        out = {a: p.communicate(timeout=60) for a, p in procs.items()}
        waited = time.monotonic() - t0
    for a, p in procs.items():
        text = " ".join(out[a][1].split())
        assert p.returncode == 1, (a, out[a])
        assert f"no Dask scheduler answers at {a}" in text, text
        assert "Traceback" not in text, text
    assert waited < cluster.CONNECT_TIMEOUT_S + 30.0, waited


# ---- the compose profile mc ----------------------------------------------------------------------


@dataclass
class Mc:
    project: str
    run: Callable[..., Any]  # compose with the profile mc, in the project
    address: str  # the scheduler, as the host reaches it


@pytest.fixture
def mc_cluster(compose: list[str], image: str) -> Iterator[Mc]:  # noqa: F811
    """compose.yaml's profile mc, up with two workers."""
    project = f"tltrack-test-{os.getpid()}-{secrets.token_hex(3)}"  # test_compose reaps these
    env = {**_clean_env(), "TLTRACK_MC_BIND": "127.0.0.1", "TLTRACK_MC_PORT": "0"}

    def run(*args: str, timeout: float = 300, check: bool = True) -> Any:
        cmd = [*compose, "-f", str(ROOT / "compose.yaml"), "-p", project, "--profile", "mc"]
        return _run([*cmd, *args], env=env, timeout=timeout, check=check)

    try:
        run("up", "-d", "--scale", "mc-worker=2", "mc-scheduler", "mc-worker")
        port = run("port", "mc-scheduler", "8786").stdout.strip().rsplit(":", 1)[-1]
        yield Mc(project, run, f"tcp://127.0.0.1:{int(port)}")
    finally:
        print(run("logs", "--no-color", "--tail", "30", check=False).stdout[-6000:])
        down = run("down", "-v", "--remove-orphans", "--timeout", "10", check=False)
        left = _remove_leftovers(project)
        assert down.returncode == 0 and not left, (down.stderr[-3000:], left)


@pytest.mark.timeout(900)
@pytest.mark.xdist_group("compose")  # after or before test_compose's stack, never beside it
@pytest.mark.system
def test_compose_profile_mc_runs_reproduce_with_the_local_pools_results(mc_cluster, tmp_path):
    """A small `tltrack reproduce --table2-pf-only` against the profile's scheduler, from a
    client container on the cluster's network and from the host through the loopback port;
    both equal the local pool's results."""
    from distributed import Client
    from tltrack.studies import reproduce as rep

    run, address = mc_cluster.run, mc_cluster.address
    cluster.probe(address, 60)  # Docker publishes the port before the scheduler listens
    with Client(address, timeout=60, set_as_default=False) as c:
        c.wait_for_workers(2, timeout=240)
        workers = c.scheduler_info(n_workers=-1)["workers"]
    assert len(workers) == 2, workers
    # the workers are on the internal network `mc` only: nothing outside the host reaches them
    for cid in run("ps", "-q", "mc-worker").stdout.split():
        nets = _run(["docker", "inspect", "-f", "{{json .NetworkSettings.Networks}}", cid]).stdout
        assert list(json.loads(nets)) == [f"{mc_cluster.project}_mc"], nets

    runs = 2  # the batches of four jobs (one per N) on two workers
    script = (
        f"tltrack reproduce --runs {runs} --table2-pf-only --out /data/r >&2 && python -c "
        "\"import json, glob; print(json.dumps({p.split('/')[-2]: json.load(open(p))['filters'] "
        "for p in glob.glob('/data/r/*/results.json')}))\""
    )
    t0 = time.monotonic()
    inside = run("run", "--rm", "--no-deps", "mc-client", "sh", "-c", script)
    print(f"client in a container: {time.monotonic() - t0:.1f} s")
    assert "batches go to the Dask cluster at tcp://mc-scheduler:8786" in inside.stderr
    from_container = json.loads(inside.stdout.strip().splitlines()[-1])

    t0 = time.monotonic()
    host = subprocess.run(
        [
            *[str(BIN / "tltrack"), "reproduce", "--runs", str(runs), "--table2-pf-only"],
            *["--scheduler", address, "--out", str(tmp_path / "host")],
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    print(f"client on the host: {time.monotonic() - t0:.1f} s")
    assert host.returncode == 0, host.stderr[-4000:]

    local = rep.run_all(
        rep.table2_pf_jobs(rep.base_config("paper", "fixed", runs, 0)), tmp_path / "local"
    )
    assert set(from_container) == set(local) == {rep.s2_label(4, n) for n in rep.PARTICLES}
    for label, doc in local.items():
        same(from_container[label], doc["filters"])
        on_host = json.loads((tmp_path / "host" / label / "results.json").read_text())
        same(on_host["filters"], doc["filters"])
