"""compose.yaml end to end, over real containers: build, `up -d`, five scored episodes, a network
partition of the source tracker and its healing, three sources, and a teardown that leaves nothing
behind. compose.yaml runs a router per operator (the federated topology), each enforcing its
operator's rules (shared/tltrack/access/routers/); the tests on the host connect as the referee
to its router, or as the primary to the primary's, with the demo passwords compose.yaml defaults
to. The stack runs with tests/compose.relay.yaml on top: a relay on each of the three links between
the routers of the referee, the primary and source s1, which keeps what crosses it (the profile
three-sources' routers s2 and s3 dial directly).

Runs whenever a Docker Engine answers `docker info` (skipped with the reason otherwise), with
whichever of `docker compose` and `docker-compose` answers. The image is built with
scripts/build_image.sh, and reused while neither the sources nor the build files change
(a stamp in build/ records the image id and a digest of them; TLTRACK_TEST_REBUILD_IMAGE=1 forces
a build). The stack's logs are kept in pytest's temporary directory; the path is printed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import secrets
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import buildlock
import numpy as np
import pytest
import yaml
import zenoh
from batch import BELOW
from livestack import wait_until
from relay import captured, found, sentinels
from security_helpers import passwords
from tltrack.config import make_config
from tltrack.engine.scenario import measurements, truth
from tltrack.engine.setup import Setup
from tltrack.live.supervisor import IDENTITY
from tltrack.wire import keys
from tltrack.wire.transport import Subscriber, ZenohSettings, open_session, query

# one test process runs the whole module: its stack (a module fixture) is started once
pytestmark = [pytest.mark.system, pytest.mark.timeout(900), pytest.mark.xdist_group("compose")]

ROOT = Path(__file__).resolve().parents[1]
COMPOSE_FILE = ROOT / "compose.yaml"
RELAY_FILE = ROOT / "tests" / "compose.relay.yaml"  #: a relay on each link between routers
#: relay service -> the link it sits on, (dialler, dialled)
RELAYS = {
    "relay-s1-primary": ("source/s1", "primary"),
    "relay-s1-referee": ("source/s1", keys.REFEREE),
    "relay-primary-referee": ("primary", keys.REFEREE),
}
PROFILE = ["--profile", "three-sources"]
IMAGE = os.environ.get("TLTRACK_IMAGE", "tltrack:latest")
STAMP = ROOT / "build" / "test_compose.stamp"

EPISODES = 5
STEPS = 100
LEASE_S = 2.0  # TLTRACK_ZENOH_LEASE_MS in compose.yaml
# The partition episode: long enough to cut the source off, wait out the lease, heal, and see
# the transfer come back (the source's zenoh client retries its router with a backoff).
PART_STEPS, PART_PACE = 300, 10.0
PART_EPISODE = "part-r5"
SENSING = ("source_tracker", "sensor")  #: each source operator's services
# The three-source episode (deploy/three-sources.toml, profile three-sources)
THREE_STEPS = 40
THREE_EPISODE = "three-r6"
THREE_WAIT_FOR = [
    *(f"source/{sid}:{service}" for sid in ("s1", "s2", "s3") for service in SENSING),
    "primary:primary_tracker",
    "primary:sensor",
    "referee:scorer",
]

USERS = ROOT / "shared" / "tltrack" / "access" / "users.txt"
#: the identity each service of compose.yaml runs under
COMPOSE_IDENTITY = {
    **IDENTITY,
    "source_tracker_s2": "source-s2",
    "source_tracker_s3": "source-s3",
    "sensor_primary": "primary",
    **{f"sensor_{sid}": f"source-{sid}" for sid in ("s1", "s2", "s3")},
}
#: each operator's router in compose.yaml
COMPOSE_ROUTERS = {"router", "router-primary", "router-s1", "router-s2", "router-s3"}
#: how the host-side tests connect: as the referee (anyone may query the summary)
HOST_USER = "referee"
TRACK = ROOT / "examples" / "tracks" / "ais-nyharbor-2020-06-30-mmsi-367370920.csv"
TRUTH_SQL = "SELECT k, pos FROM truth WHERE episode = ? AND pos IS NOT NULL"
ESTIMATES_SQL = "SELECT k, pos FROM estimates WHERE episode = ? AND filter = ?"


def credentials(user: str) -> dict[str, Any]:
    """ZenohSettings fields for connecting as ``user`` with compose.yaml's default password."""
    return {"username": user, "password": passwords(USERS)[user]}


def _run(
    cmd: list[str], *, timeout: float = 120, env: dict[str, str] | None = None, check: bool = True
) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(
        cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout, check=False
    )
    if check and proc.returncode != 0:
        raise AssertionError(
            f"{' '.join(cmd)} exited with {proc.returncode}\n"
            f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}"
        )
    return proc


def _answers(cmd: list[str]) -> bool:
    try:
        return subprocess.run(cmd, capture_output=True, timeout=60, check=False).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def compose_tool() -> list[str]:
    """`docker compose` if the plugin answers, else `docker-compose`; fails if neither does."""
    if _answers(["docker", "compose", "version"]):
        return ["docker", "compose"]
    if shutil.which("docker-compose") and _answers(["docker-compose", "version"]):
        return ["docker-compose"]
    pytest.fail("a Docker Engine answers, but neither `docker compose` nor `docker-compose` does")


@pytest.fixture(scope="module")
def compose() -> list[str]:
    if shutil.which("docker") is None:
        pytest.skip("docker is not installed: no Docker Engine to run compose.yaml on")
    if not _answers(["docker", "info"]):
        pytest.skip("no Docker Engine answers `docker info`: compose.yaml is not exercised")
    return compose_tool()


# ---- the image ---------------------------------------------------------------------------------


def _sources_digest() -> str:
    """What the image is built from: the sources, the dependency pins and the build files."""
    h = hashlib.sha256()
    files = [ROOT / "pyproject.toml", ROOT / "Dockerfile", ROOT / ".dockerignore"]
    files += [ROOT / "scripts" / n for n in ("build_image.sh", "build_base_image.sh")]
    for top in ("shared", "services"):
        files += [
            p for p in (ROOT / top).rglob("*") if p.is_file() and "__pycache__" not in p.parts
        ]
    for p in sorted(files):
        if p.exists():
            h.update(str(p.relative_to(ROOT)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def _image_id() -> str | None:
    proc = _run(["docker", "image", "inspect", "-f", "{{.Id}}", IMAGE], check=False)
    return proc.stdout.strip() if proc.returncode == 0 else None


#: TLTRACK_TEST_REBUILD_IMAGE=1 forces one build per test run: the first test process to get here
#: builds, and leaves this mark (its pytest run's id) so that the others reuse what it built
RUN_ID = os.environ.get("PYTEST_XDIST_TESTRUNUID") or str(os.getpid())


@pytest.fixture(scope="module")
def image(compose: list[str]) -> str:
    # Under pytest-xdist each test process reaches this fixture (test_compose, test_dask): the
    # build lock makes the second wait for the first's build, and the stamp then lets it reuse it.
    with buildlock.held(f"the image {IMAGE}"):
        digest = _sources_digest()
        current = _image_id()
        stamp = STAMP.read_text().split() if STAMP.exists() else []
        forced = os.environ.get("TLTRACK_TEST_REBUILD_IMAGE") == "1"
        built_by_this_run = stamp[2:] == [RUN_ID]
        if (
            current is not None
            and stamp[:2] == [current, digest]
            and (not forced or built_by_this_run)
        ):
            print(f"reusing {IMAGE} ({current[:19]}): sources unchanged since it was built")
            return IMAGE
        t0 = time.monotonic()
        _run([*BELOW, str(ROOT / "scripts" / "build_image.sh")], timeout=1500)
        print(f"built {IMAGE} in {time.monotonic() - t0:.0f} s")
        built = _image_id()
        assert built is not None, f"scripts/build_image.sh left no {IMAGE}"
        STAMP.parent.mkdir(parents=True, exist_ok=True)
        STAMP.write_text(f"{built} {digest} {RUN_ID}\n")
        return IMAGE


# ---- the stack ---------------------------------------------------------------------------------


@dataclass
class Stack:
    """One compose project: its commands, environment, and the router's endpoint on the host."""

    compose: list[str]
    project: str
    env: dict[str, str]
    endpoint: str = ""  #: the referee's router
    primary_endpoint: str = ""  #: the primary's router

    def cmd(
        self,
        *args: str,
        env: dict[str, str] | None = None,
        timeout: float = 180,
        check: bool = True,
    ) -> subprocess.CompletedProcess[str]:
        files = ["-f", str(COMPOSE_FILE), "-f", str(RELAY_FILE)]
        base = [*self.compose, *files, "-p", self.project]
        return _run([*base, *args], env={**self.env, **(env or {})}, timeout=timeout, check=check)

    def run_sim(self, **env: str) -> None:
        """A fresh sensor_sim with these TLTRACK_SIM_* settings, beside the running services."""
        sim_env = {f"TLTRACK_SIM_{k.upper()}": v for k, v in env.items()}
        self.cmd("up", "-d", "--no-deps", "--force-recreate", "sensor_sim", env=sim_env)

    def container(self, service: str) -> str:
        """The id of the service's container, running or not (by the labels both tools set)."""
        proc = _run(
            [
                "docker",
                "ps",
                "-aq",
                "--filter",
                f"label=com.docker.compose.project={self.project}",
                "--filter",
                f"label=com.docker.compose.service={service}",
            ]
        )
        ids = proc.stdout.split()
        assert len(ids) == 1, f"{len(ids)} containers for {service}: {ids}"
        return ids[0]

    @property
    def network(self) -> str:
        return f"{self.project}_tracking"

    def health(self) -> dict[str, str]:
        """service -> its health status (`healthy`, `starting`, ...) for those with a check."""
        out = {}
        proc = _run(
            ["docker", "ps", "-aq", "--filter", f"label=com.docker.compose.project={self.project}"]
        )
        for cid in proc.stdout.split():
            fmt = (
                '{{index .Config.Labels "com.docker.compose.service"}} '
                "{{if .State.Health}}{{.State.Health.Status}}{{end}}"
            )
            service, _, status = _run(["docker", "inspect", "-f", fmt, cid]).stdout.partition(" ")
            if status.strip():
                out[service] = status.strip()
        return out

    def wait_healthy(self, *services: str, timeout: float = 120) -> bool:
        """Whether ``services`` all turn healthy within ``timeout`` s (the first check runs one
        `interval`, 30 s, after a container starts)."""
        return wait_until(
            lambda: all(self.health().get(s) == "healthy" for s in services), timeout, every=2.0
        )

    def logs(self, *services: str) -> str:
        return self.cmd("logs", "--no-color", "--timestamps", *services, check=False).stdout

    def restarts(self) -> dict[str, int]:
        """How often the engine restarted each long-running service (restart: on-failure)."""
        out = {}
        for service in ("router", "scorer", "primary_tracker", "source_tracker"):
            proc = _run(
                ["docker", "inspect", "-f", "{{.RestartCount}}", self.container(service)],
                check=False,
            )
            out[service] = int(proc.stdout.strip() or -1)
        return out

    def sql(self, query_sql: str, *args: Any) -> list[list[Any]]:
        """Rows of a read-only query on the scorer's database, run inside the scorer container."""
        script = (
            "import json, sqlite3, sys\n"
            "db = sqlite3.connect('file:/data/scorer.sqlite?mode=ro', uri=True)\n"
            "print(json.dumps(db.execute(sys.argv[1], json.loads(sys.argv[2])).fetchall()))\n"
        )
        proc = _run(
            [
                "docker",
                "exec",
                self.container("scorer"),
                "python",
                "-c",
                script,
                query_sql,
                json.dumps(list(args)),
            ],
            timeout=60,
        )
        return list(json.loads(proc.stdout))

    def steps(self, episode: str, name: str) -> dict[int, tuple[bool, float, float]]:
        """k -> (transfer_used, t_sensor, t_recv) of filter ``name``'s estimates in ``episode``."""
        rows = self.sql(
            "SELECT k, transfer_used, t_sensor, t_recv FROM estimates WHERE episode = ? "
            "AND filter = ? ORDER BY k",
            episode,
            name,
        )
        return {int(k): (bool(u), float(ts), float(tr)) for k, u, ts, tr in rows}


def _clean_env() -> dict[str, str]:
    """The caller's environment without its TLTRACK_* settings (they would leak into the stack)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("TLTRACK_", "COMPOSE_"))}
    env["TLTRACK_IMAGE"] = IMAGE
    return env


def _remove_leftovers(project: str) -> list[str]:
    """Remove whatever of ``project`` is left (containers, networks, volumes); what it removed."""
    label = f"label=com.docker.compose.project={project}"
    removed: list[str] = []
    for kind, ls, rm in (
        ("container", ["docker", "ps", "-aq"], ["docker", "rm", "-f"]),
        ("network", ["docker", "network", "ls", "-q"], ["docker", "network", "rm"]),
        ("volume", ["docker", "volume", "ls", "-q"], ["docker", "volume", "rm", "-f"]),
    ):
        ids = _run([*ls, "--filter", label], check=False).stdout.split()
        if ids:
            _run([*rm, *ids], check=False)
            removed += [f"{kind} {i}" for i in ids]
    return removed


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _reap_stale_projects() -> list[str]:
    """Remove the projects of earlier runs whose pytest process is gone (killed before its
    teardown could run); the names of those projects."""
    label = "com.docker.compose.project"
    projects: set[str] = set()
    for kind in (["ps", "-a"], ["network", "ls"], ["volume", "ls"]):
        proc = _run(
            [
                "docker",
                *kind,
                "--filter",
                f"label={label}",
                "--format",
                f'{{{{.Label "{label}"}}}}',
            ],
            check=False,
        )
        projects.update(proc.stdout.split())
    stale = []
    for project in sorted(projects):
        m = re.fullmatch(r"tltrack-test-(\d+)-[0-9a-f]{6}", project)
        if m and not _pid_alive(int(m[1])):
            _remove_leftovers(project)
            stale.append(project)
    return stale


@pytest.fixture(scope="module")
def stack(
    compose: list[str], image: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Stack]:
    if stale := _reap_stale_projects():
        print(f"removed what killed earlier runs left behind: {stale}")
    project = f"tltrack-test-{os.getpid()}-{secrets.token_hex(3)}"
    s = Stack(compose, project, _clean_env())
    # the router's port on a free loopback port of the host, chosen by the engine
    s.env.update(
        TLTRACK_ROUTER_BIND="127.0.0.1", TLTRACK_ROUTER_PORT="0", TLTRACK_PRIMARY_ROUTER_PORT="0"
    )
    # what sensor_sim runs first: the five scored episodes
    s.env.update(
        TLTRACK_SIM_PRESET="arasaratnam-haykin",
        TLTRACK_SIM_TRUTH="noise-free",
        TLTRACK_SIM_PRIMARY_INTENSITY="4",
        TLTRACK_SIM_PARTICLES="2000",
        TLTRACK_SIM_STEPS=str(STEPS),
        TLTRACK_SIM_EPISODES=str(EPISODES),
        TLTRACK_SIM_FIRST_RUN="0",
        TLTRACK_SIM_EPISODE_PREFIX="main",
        TLTRACK_SIM_PACE="20",
        TLTRACK_SCORER_GRACE_S="3",
    )
    logdir = tmp_path_factory.mktemp("compose")
    try:
        t0 = time.monotonic()
        s.cmd("up", "-d", timeout=300)
        print(f"{project}: up -d took {time.monotonic() - t0:.1f} s")
        for router, field in (("router", "endpoint"), ("router-primary", "primary_endpoint")):
            host_port = s.cmd("port", router, "7447").stdout.strip().rsplit(":", 1)[-1]
            setattr(s, field, f"tcp/127.0.0.1:{int(host_port)}")
        yield s
    finally:
        (logdir / f"{project}.log").write_text(s.logs())
        print(f"{project}: logs in {logdir / (project + '.log')}")
        t0 = time.monotonic()
        # with the profile, so that `down` also stops the three-source test's extra trackers
        down = s.cmd(*PROFILE, "down", "-v", "--remove-orphans", "--timeout", "10", check=False)
        left = _remove_leftovers(project)
        print(f"{project}: down -v took {time.monotonic() - t0:.1f} s; leftovers removed: {left}")
        assert down.returncode == 0, f"compose down failed:\n{down.stderr[-3000:]}"


# ---- talking to the scorer ---------------------------------------------------------------------


def wait_for_summary(
    endpoint: str, done: Any, timeout: float, every: float = 0.5
) -> dict[str, Any] | None:
    """Poll the scorer's summary until ``done(summary)``; the last summary seen, or None."""
    last: dict[str, Any] | None = None
    deadline = time.monotonic() + timeout
    settings = ZenohSettings(
        endpoints=[endpoint], connect_timeout_ms=60_000, **credentials(HOST_USER)
    )
    with open_session(settings) as session:
        while time.monotonic() < deadline:
            for reply in query(session, keys.SCORER_SUMMARY, 5.0):
                last = dict(json.loads(reply.payload))
                if done(last):
                    return last
            time.sleep(every)
    return last


def scored(summary: dict[str, Any], prefix: str) -> list[dict[str, Any]]:
    return [
        e for e in summary.get("episodes", []) if e["episode"].startswith(prefix) and e["scored"]
    ]


def condensed(logs: str, tail: int = 80) -> str:
    """The last ``tail`` log lines, with the per-step "no measurement ...; predicting" warnings
    counted instead of listed."""
    kept: list[str] = []
    predicted: dict[str, int] = {}
    for line in logs.splitlines():
        if "; predicting" in line:
            service = line.split("|", 1)[0].strip()
            predicted[service] = predicted.get(service, 0) + 1
        else:
            kept.append(line)
    notes = [f"({n} '... predicting' warnings of {svc} left out)" for svc, n in predicted.items()]
    return "\n".join([*kept[-tail:], *notes])


# ---- the tests ---------------------------------------------------------------------------------


@pytest.mark.parametrize("files", [[COMPOSE_FILE], [COMPOSE_FILE, RELAY_FILE]])
def test_compose_file_is_valid(compose: list[str], files: list[Path]) -> None:
    flags = [arg for f in files for arg in ("-f", str(f))]
    proc = _run([*compose, *flags, "config", "-q"], env=_clean_env())
    assert proc.returncode == 0


def test_the_relay_overlay_changes_only_where_the_routers_dial(compose: list[str]) -> None:
    """The stack under test is compose.yaml with tests/compose.relay.yaml: with each relay's name
    read as the router it relays to, every service of compose.yaml is exactly as compose.yaml
    says, so what the tests see is what compose.yaml runs."""

    def services(*files: Path) -> dict[str, Any]:
        flags = [arg for f in files for arg in ("-f", str(f))]
        proc = _run([*compose, *flags, "config"], env=_clean_env())
        out = dict(yaml.safe_load(proc.stdout)["services"])
        for service in out.values():  # one file prints a network without options as {}
            service["networks"] = {k: v or {} for k, v in service.get("networks", {}).items()}
        return out

    base, over = services(COMPOSE_FILE), services(COMPOSE_FILE, RELAY_FILE)
    relays = {name: over[name]["command"][3] for name in over if name.startswith("relay-")}
    assert set(relays) == {*RELAYS, "relay-s1-sensor"}, relays
    dialled = json.dumps({name: over[name] for name in base}, sort_keys=True)
    for relay, target in relays.items():
        dialled = dialled.replace(f"tcp/{relay}:7447", f"tcp/{target}")
    assert json.loads(dialled) == json.loads(json.dumps(base, sort_keys=True))


def service_env(config: str) -> dict[str, dict[str, str]]:
    """service -> its environment, read from the block YAML that `compose config` prints (both
    tools print `environment` as a mapping: services at indent 2, their keys at 4, entries at 6)."""
    out: dict[str, dict[str, str]] = {}
    section, service, in_env = "", "", False
    for line in config.splitlines():
        text = line.strip()
        if not text:
            continue
        indent = len(line) - len(line.lstrip(" "))
        if indent == 0:
            section = text.rstrip(":")
        elif section != "services":
            continue
        elif indent == 2:
            service, in_env = text.rstrip(":"), False
            out[service] = {}
        elif indent == 4:
            in_env = text == "environment:"
        elif indent == 6 and in_env:
            name, _, value = text.partition(":")
            out[service][name] = value.strip().strip("'\"")
    return out


def test_compose_identities_and_passwords_match_users_txt(compose: list[str]) -> None:
    """compose.yaml runs every service under its operator's identity with users.txt's password by
    default (so the two cannot drift apart), every router loads its operator's rules from the
    package, and each password can be overridden from the environment."""
    users = passwords(USERS)

    def config(**env: str) -> dict[str, dict[str, str]]:
        proc = _run(
            [*compose, "-f", str(COMPOSE_FILE), *PROFILE, "config"], env={**_clean_env(), **env}
        )
        return service_env(proc.stdout)

    # the profile mc (a Dask cluster) has no Zenoh identity; docker-compose 1.29 lists it anyway
    env = {s: e for s, e in config().items() if not s.startswith("mc-")}
    assert env.keys() == COMPOSE_ROUTERS | COMPOSE_IDENTITY.keys(), env.keys()
    for service, user in COMPOSE_IDENTITY.items():
        assert env[service].get("TLTRACK_ZENOH_USERNAME") == user, (service, env[service])
        assert env[service].get("TLTRACK_ZENOH_PASSWORD") == users[user], (service, user)
        assert "TLTRACK_ZENOH_ACCESS_CONTROL_FILE" not in env[service], service
    # each router takes its operator's rules and dictionary from the package (--operator)
    for router in COMPOSE_ROUTERS:
        assert (
            not {"TLTRACK_ZENOH_USERNAME", "TLTRACK_ZENOH_ACCESS_CONTROL_FILE"} & env[router].keys()
        )
    # ... as ``tltrack router --operator NAME`` (a source's rules: rendered from its template)
    services = yaml.safe_load(COMPOSE_FILE.read_text())["services"]
    for router in COMPOSE_ROUTERS:
        operator = {"router": "referee", "router-primary": "primary"}.get(
            router, "source/" + router.removeprefix("router-")
        )
        assert services[router]["command"][:4] == ["tltrack", "router", "--operator", operator], (
            router
        )

    def variable(user: str) -> str:
        return "TLTRACK_PASSWORD_" + user.upper().replace("-", "_")

    overridden = config(**{variable(user): f"not-{user}" for user in users})
    for service, user in COMPOSE_IDENTITY.items():
        assert overridden[service]["TLTRACK_ZENOH_PASSWORD"] == f"not-{user}", (service, user)


def test_five_episodes_score_and_transfer_helps(stack: Stack) -> None:
    t0 = time.monotonic()
    summary = wait_for_summary(
        stack.endpoint, lambda s: len(scored(s, "main-")) >= EPISODES, timeout=300
    )
    elapsed = time.monotonic() - t0
    assert summary is not None, "the scorer never answered\n" + stack.logs()[-6000:]
    eps = scored(summary, "main-")
    assert len(eps) == EPISODES, (
        f"{len(eps)} of {EPISODES} scored after {elapsed:.0f} s:\n" + (stack.logs()[-6000:])
    )
    print(f"{EPISODES} episodes scored {elapsed:.1f} s after up -d")
    assert all(e["complete"] and e["K"] == STEPS for e in eps), eps

    filters = summary["filters"]
    assert {"rpf", "tl-rpf", "source-rpf"} <= filters.keys(), filters.keys()
    for name, f in filters.items():
        assert f["rmse_overall"] is not None and math.isfinite(f["rmse_overall"]), (name, f)
        assert len(f["rmse_per_step"]) == STEPS, (name, len(f["rmse_per_step"]))
        assert all(math.isfinite(v) for v in f["rmse_per_step"]), (name, f["rmse_per_step"])
        assert f["steps"] == EPISODES * STEPS and f["gaps"] == 0, (name, f)
    for operator, service, stats in stack.sql("SELECT operator, service, stats FROM service_stats"):
        print(f"{operator}/{service}: {json.loads(stats).get('counters')}")
    tl, iso = filters["tl-rpf"]["rmse_overall"], filters["rpf"]["rmse_overall"]
    print(
        f"RMSE over {EPISODES} episodes: tl-rpf {tl:.2f} m, rpf {iso:.2f} m, "
        f"source-rpf {filters['source-rpf']['rmse_overall']:.2f} m"
    )
    assert tl < iso, f"TL-PF RMSE {tl:.2f} m is not below the isolated PF's {iso:.2f} m"
    assert filters["tl-rpf"]["steps_with_transfer"] > EPISODES * (STEPS - 1) // 2, filters["tl-rpf"]
    # every health check passes: each looks up its service's own liveliness token under the
    # service's identity, which the ACL grants (and nothing more)
    checked = ("router", "scorer", "primary_tracker", "source_tracker", "dashboard")
    assert stack.wait_healthy(*checked), stack.health()


def test_raw_data_never_leaves_its_owners_router_in_containers(
    stack: Stack, tmp_path: Path
) -> None:
    """The five episodes crossed the relays of tests/compose.relay.yaml: no raw measurement of
    either operator and no truth on any link between routers; the transfers on the source's link
    to the primary only. The controls: a tap between the source's sensor and its router sees
    every one of its measurements, and each operator's link to the referee carries every value of
    its estimates (which may go there), so each capture sees what crosses its link."""
    summary = wait_for_summary(
        stack.endpoint, lambda s: len(scored(s, "main-")) >= EPISODES, timeout=300
    )
    assert summary is not None and len(scored(summary, "main-")) == EPISODES, stack.logs()[-6000:]

    def wire_of(relay: str) -> bytes:
        _run(["docker", "cp", f"{stack.container(relay)}:/tmp/wire", str(tmp_path / relay)])
        return captured(tmp_path / relay)

    wire = {link: wire_of(relay) for relay, link in RELAYS.items()}
    tap = wire_of("relay-s1-sensor")  # between the source's sensor and its own router
    raw: dict[str, set[bytes]] = {"primary": set(), "s1": set(), "truth": set()}
    for run, cfg_json in stack.sql("SELECT run, config FROM episodes WHERE episode LIKE 'main-%'"):
        cfg = make_config(json.loads(cfg_json))
        x = truth(Setup(cfg), run)
        # the truth's positions: a noise-free truth keeps the turn rate of x0, which the
        # episode's config (allowed out) carries
        raw["truth"] |= sentinels(Setup(cfg).motion.layout.position(x[1:].T))
        for sid in ("primary", "s1"):
            raw[sid] |= sentinels(measurements(Setup(cfg), run, x, sid))
    assert all(len(v) >= STEPS for v in raw.values()), {k: len(v) for k, v in raw.items()}

    def estimated(name: str) -> set[bytes]:
        """What the filter ``name`` sent the referee: each value of its estimates."""
        sql = "SELECT x FROM estimates WHERE episode LIKE 'main-%' AND filter = ?"
        rows = stack.sql(sql, name)
        assert len(rows) == EPISODES * STEPS, (name, len(rows))
        return set().union(*(sentinels(np.array(json.loads(x))) for (x,) in rows))

    print({f"{a} -> {b}": f"{len(data)} bytes" for (a, b), data in wire.items()})
    assert found(raw["s1"], tap) == len(raw["s1"]), "the sentinels are not what travels"
    for name, link in (
        ("source-rpf", ("source/s1", keys.REFEREE)),
        ("tl-rpf", ("primary", keys.REFEREE)),
    ):
        sent = estimated(name)
        assert found(sent, wire[link]) == len(sent), f"{name}'s estimates not all seen on {link}"
    for link, data in wire.items():
        for what, patterns in raw.items():
            assert found(patterns, data) == 0, f"{what}'s raw data on the link {link}"
    assert b"\xa8transfer" in wire["source/s1", "primary"], "no transfer on the source's link"
    assert b"\xa8transfer" not in wire["source/s1", keys.REFEREE]
    assert b"\xa8transfer" not in wire["primary", keys.REFEREE]


def test_the_router_refuses_sessions_without_a_valid_password(stack: Stack) -> None:
    """compose.yaml's router authenticates every session (the ACL's identities)."""
    # the router is up and takes a known identity ...
    known = ZenohSettings(
        endpoints=[stack.endpoint], connect_timeout_ms=60_000, **credentials(HOST_USER)
    )
    with open_session(known) as z:
        assert z.info.routers_zid()
    # ... but neither a session without credentials nor a wrong password
    for creds in ({}, {"username": "primary", "password": "guess"}):
        with pytest.raises(zenoh.ZError):
            open_session(
                ZenohSettings(endpoints=[stack.endpoint], connect_timeout_ms=2000, **creds)
            )


def test_partitioned_source_primary_carries_on_and_transfer_resumes(stack: Stack) -> None:
    # Let the first test's episodes finish first (sensor_sim runs them in one container).
    wait_for_summary(stack.endpoint, lambda s: len(scored(s, "main-")) >= EPISODES, timeout=300)
    # The ACL is on: a session as the primary reads the primary's sensor, and (another session,
    # so the two subscriptions cannot share samples) never the source's.
    primary = ZenohSettings(
        endpoints=[stack.primary_endpoint], connect_timeout_ms=60_000, **credentials("primary")
    )
    with (
        open_session(primary) as own,
        open_session(primary) as other,
        Subscriber(own, keys.PRIMARY_MEAS) as own_meas,
        Subscriber(other, keys.SOURCE_MEAS) as source_meas,
    ):
        stack.run_sim(
            episodes="1",
            first_run="5",
            episode_prefix="part",
            steps=str(PART_STEPS),
            pace=str(PART_PACE),
        )

        # 1. the transfer works before the cut
        def transfers_flowing() -> bool:
            tl = stack.steps(PART_EPISODE, "tl-rpf")
            return sum(used for used, _, _ in tl.values()) >= 20

        assert wait_until(transfers_flowing, 120, every=0.5), (
            "no transfer before the cut\n" + stack.logs()[-6000:]
        )
        seen = {"primary": own_meas.received, "source": source_meas.received}
    print(f"measurements received by a session as the primary: {seen}")
    assert seen["primary"] >= 20, seen
    assert seen["source"] == 0, f"the primary's identity read the source's measurements: {seen}"
    source = stack.container("source_tracker")

    # 2. cut the source tracker off the network, for a few lease times
    t_cut = time.time()
    _run(["docker", "network", "disconnect", stack.network, source])

    # ... until the primary has stepped a while without it, its token gone (a lease and a step)
    def isolated_a_while() -> bool:
        tl = stack.steps(PART_EPISODE, "tl-rpf")
        return sum(ts > t_cut + LEASE_S + 1.0 for _, ts, _ in tl.values()) >= 5 * PART_PACE

    assert wait_until(isolated_a_while, 120, every=0.5), "the primary stalled\n" + condensed(
        stack.logs("primary_tracker", "source_tracker")
    )
    t_heal = time.time()
    _run(["docker", "network", "connect", "--alias", "source_tracker", stack.network, source])

    # 3. the transfer resumes, and the episode ends and is scored
    def resumed() -> bool:
        tl = stack.steps(PART_EPISODE, "tl-rpf")
        return any(used and ts > t_heal for used, ts, _ in tl.values())

    wait_until(resumed, 60, every=0.5)
    summary = wait_for_summary(stack.endpoint, lambda s: bool(scored(s, "part-")), timeout=120)
    logs = stack.logs("primary_tracker", "source_tracker")
    restarts = stack.restarts()
    tl = stack.steps(PART_EPISODE, "tl-rpf")
    iso = stack.steps(PART_EPISODE, "rpf")
    timeline = " ".join(
        f"{k}{'+' if used else '-'}@{ts - t_cut:+.1f}"
        for k, (used, ts, _) in sorted(tl.items())
        if t_cut - 2 < ts < t_heal + 15
    )
    context = (
        f"\ncut at t_cut, reconnected at t_cut{t_heal - t_cut:+.1f} s; restarts {restarts}"
        f"\ntl-pf steps, k(+ with transfer / - without)@(t_sensor - t_cut): {timeline}\n"
        + condensed(logs)
    )

    # the primary carried on while the source was cut off: every step, on time, and isolated
    cut = [k for k, (_, ts, _) in tl.items() if t_cut + LEASE_S + 1.0 < ts < t_heal]
    expected = (t_heal - t_cut - LEASE_S - 1.0) * PART_PACE
    assert len(cut) >= 0.6 * expected, f"{len(cut)} steps while cut off" + context
    assert all(k in iso for k in cut), "the isolated PF missed steps while cut off" + context
    assert not any(tl[k][0] for k in cut), "a step used a transfer while cut off" + context
    lag = max(tl[k][2] - tl[k][1] for k in cut)
    assert lag < 2.0, f"the primary stalled while the source was cut off ({lag:.1f} s)" + context
    assert "source s1 gone" in logs, "the primary never saw the source's token go" + context
    # nothing crashed (a restarted tracker has lost the episode)
    assert all(n == 0 for n in restarts.values()), f"a service crashed: {restarts}" + context
    # the transfer resumed after the reconnection
    after = sorted(k for k, (used, ts, _) in tl.items() if used and ts > t_heal)
    assert after, "no transfer after the source was reconnected" + context
    # the episode was scored, with every step of the primary
    assert summary is not None and scored(summary, "part-"), "partition episode not scored" + (
        context
    )
    assert sorted(tl) == list(range(1, PART_STEPS + 1)), "tl-rpf missed steps" + context
    assert sorted(iso) == list(range(1, PART_STEPS + 1)), "rpf missed steps" + context
    print(
        f"partition: k={min(cut)}..{max(cut)} isolated while cut off ({len(cut)} steps); "
        f"transfer back at k={after[0]}, {tl[after[0]][1] - t_heal:.1f} s after reconnecting; "
        f"{len(after)} steps with transfer after it"
    )


def test_three_sources_profile_under_the_acl(stack: Stack) -> None:
    """docs/tutorials/many-sources.md: the profile's trackers join the running stack under their
    own identities (source-s2, source-s3), and one episode of deploy/three-sources.toml is scored
    with the three sources' tracks and TL-PF using their transfers, nothing rejected."""
    before = wait_for_summary(stack.endpoint, lambda s: bool(scored(s, "part-")), timeout=300)
    assert before is not None, "the scorer never answered"
    # what the services rejected so far (the partition may leave a few late messages)
    rejected_before = before["messages"]["rejected"]
    print(f"rejected before the three-source episode: {rejected_before}")
    extra = [f"{kind}{sid}" for sid in ("s2", "s3") for kind in ("router-", "sensor_")]
    stack.cmd(*PROFILE, "up", "-d", "--no-deps", *extra, "source_tracker_s2", "source_tracker_s3")
    stack.run_sim(
        config="/config/three-sources.toml",
        wait_for=json.dumps(THREE_WAIT_FOR),
        episodes="1",
        first_run="6",
        episode_prefix="three",
        steps=str(THREE_STEPS),
    )
    summary = wait_for_summary(stack.endpoint, lambda s: bool(scored(s, "three-")), timeout=240)
    logs = condensed(stack.logs("sensor_sim", "primary_tracker", "source_tracker_s2"))
    assert summary is not None and scored(summary, "three-"), "not scored\n" + logs
    (episode,) = scored(summary, "three-")
    assert episode["episode"] == THREE_EPISODE and episode["complete"], episode
    counts = {
        name: (int(n), int(used))
        for name, n, used in stack.sql(
            "SELECT filter, count(*), sum(transfer_used) FROM estimates WHERE episode = ? "
            "GROUP BY filter",
            THREE_EPISODE,
        )
    }
    print(f"three sources, (estimates, with transfer) per filter: {counts}")
    for sid in ("s1", "s2", "s3"):
        assert counts.get(f"source-rpf/{sid}", (0, 0))[0] == THREE_STEPS, (sid, counts)
    assert counts["rpf"][0] == counts["tl-rpf"][0] == THREE_STEPS, counts
    assert counts["tl-rpf"][1] > THREE_STEPS // 2, counts
    # nothing rejected during this episode (each counter counts since its service started) but
    # a transfer later than the primary's deadline, which a loaded machine makes now and then
    # (that step went isolated, as it should: counted above)
    rejected = summary["messages"]["rejected"]
    new = {
        (service, reason): n - rejected_before.get(service, {}).get(reason, 0)
        for service, reasons in rejected.items()
        for reason, n in reasons.items()
        if reason != "late_transfer"
    }
    assert not {k: n for k, n in new.items() if n > 0}, (rejected_before, rejected)
    assert rejected.get("source/s2/source_tracker") == {}, rejected
    assert rejected.get("source/s3/source_tracker") == {}, rejected
    # their health checks (own liveliness token, under their own identity) pass under the ACL
    assert stack.wait_healthy("source_tracker_s2", "source_tracker_s3"), stack.health()


def test_a_recorded_track_is_the_truth(stack: Stack) -> None:
    """docs/tutorials/recorded-tracks.md: TLTRACK_SIM_TRUTH_FILE names a track under
    /config/tracks, where compose mounts examples/tracks; the truth mode is left empty, and the
    episode is scored against the track (K shortened by TLTRACK_SIM_STEPS)."""
    steps = 30
    stack.run_sim(
        truth="",
        truth_file=f"/config/tracks/{TRACK.name}",
        episodes="1",
        first_run="8",
        episode_prefix="file",
        steps=str(steps),
    )
    summary = wait_for_summary(stack.endpoint, lambda s: bool(scored(s, "file-")), timeout=240)
    logs = condensed(stack.logs("sensor_sim", "scorer"))
    assert summary is not None and scored(summary, "file-"), "not scored\n" + logs
    (episode,) = scored(summary, "file-")
    assert episode["complete"] and episode["K"] == steps, episode
    truth = {k: json.loads(pos) for k, pos in stack.sql(TRUTH_SQL, episode["episode"])}
    tl = {k: json.loads(pos) for k, pos in stack.sql(ESTIMATES_SQL, episode["episode"], "tl-rpf")}
    assert sorted(truth) == sorted(tl) == list(range(1, steps + 1)), (truth.keys(), tl.keys())
    # the track, resampled to Ts: the vessel moves a few metres a step, as the file says
    first, last = np.array(truth[1]), np.array(truth[steps])
    assert 1.0 < np.linalg.norm(last - first) / (steps - 1) < 15.0, (first, last)
    error = [np.linalg.norm(np.subtract(tl[k], truth[k])) for k in truth]
    assert max(error) < 100.0, error  # tracked, against the file's truth
