"""The dashboard in a real browser: headless Chromium (Debian's ``chromium`` and
``chromium-driver``) driven by selenium watches a paced demo episode in clutter being drawn: the
tracks, and the primary's latest scan with its false alarms in light grey.

A test tool's own browser download cannot work on these offline machines, so the browser comes
from apt: installed here when missing (as root with apt-get), skipped with the reason otherwise.
The screenshot goes to ``out/artifacts/dashboard.png``; with ``TLTRACK_UPDATE_SCREENSHOT=1`` it
also replaces the committed ``docs/dashboard.png``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from livestack import WAIT_WITH_DASHBOARD, logs, sim_flags, stack
from tltrack.live import supervisor
from tltrack.services.dashboard import launch
from tltrack.wire import keys
from tltrack.wire.transport import LivelinessWatcher

pytestmark = pytest.mark.system

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
ROOT = Path(__file__).resolve().parents[1]
ARTIFACT = ROOT / "out" / "artifacts" / "dashboard.png"
COMMITTED = ROOT / "docs" / "dashboard.png"
K, PACE = 60, 10.0  # six seconds of episode: plenty of polls to see it grow
#: false alarms over a sector around the track, so that some fall inside the plot every scan
CLUTTER = {
    "primary_detection": {
        "pd": 0.9,
        "clutter_rate": 10.0,
        "fov": {"range_m": [1000.0, 7500.0], "bearing_rad": [-1.5, 1.0]},
    }
}
CLUTTER_RGB = (196, 201, 209)  # dashboard.js's CLUTTER_COLOR, #c4c9d1

PAGE_STATE = """
const q = (sel) => Array.from(document.querySelectorAll(sel));
return {
  drawn: Number(document.getElementById("steps-drawn").dataset.steps),
  rmse: q("#rmse-table td.rmse, #rmse-table td.rmse-k").map((c) => c.textContent).join("|"),
  status: document.getElementById("episode-status").textContent,
  filters: Object.fromEntries(q("#rmse-table tbody tr[data-filter]").map(
    (r) => [r.dataset.filter, Number(r.cells[2].textContent)])),
  alive: q("#health li[data-alive='true']").map((li) => li.dataset.service),
  scan: Object.fromEntries(Object.entries(document.getElementById("scan-drawn").dataset)
    .map(([name, v]) => [name, Number(v)])),
};
"""


def _install_chromium() -> str | None:
    """Install Chromium and its driver from apt if missing; the reason to skip if impossible."""
    if CHROMIUM.exists() and CHROMEDRIVER.exists():
        return None
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        return (
            "Chromium is missing and cannot be installed here (needs root and apt-get): "
            "apt-get install chromium chromium-driver"
        )
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (
        ["apt-get", "update", "-q"],
        ["apt-get", "install", "-y", "-q", "chromium", "chromium-driver"],
    ):
        try:
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        except subprocess.TimeoutExpired:
            return f"{' '.join(cmd)} timed out: Chromium cannot be installed"
        if r.returncode != 0:
            return f"{' '.join(cmd)} failed, Chromium cannot be installed: {r.stderr[-400:]}"
    return None if CHROMIUM.exists() and CHROMEDRIVER.exists() else "apt installed no chromium"


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    reason = _install_chromium()
    if reason:
        pytest.skip(reason)
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (dev extra) missing")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,1150",
        "--hide-scrollbars",
    ):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    os.environ.setdefault("SE_OFFLINE", "true")  # never let Selenium Manager go online
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


def _until(pred: Callable[[], Any], timeout: float, what: str, diag: Callable[[], str]) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if value := pred():
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}\n{diag()}")


@pytest.mark.timeout(90, func_only=True)  # the one-off apt install is in the fixture, not here
def test_the_page_draws_the_episode_and_its_clutter_as_it_runs(
    tmp_path: Path, browser: Any
) -> None:
    port = supervisor.free_port()
    given = tmp_path / "clutter.json"
    given.write_text(json.dumps(CLUTTER))
    with stack(tmp_path) as s:
        s.start_router()
        s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(tmp_path / "scorer.sqlite")})
        s.start_service("primary_tracker")
        s.start_service("source_tracker")
        page = launch.start(s, port)
        with supervisor.client(s.endpoint) as session, LivelinessWatcher(session, keys.ALIVE) as w:
            for who in WAIT_WITH_DASHBOARD:  # startup is the services' business, not the page's
                assert w.wait_until(keys.alive(*who.split(":")), True, 60), f"{who}\n{logs(s)}"
        assert launch.wait_ready(page, 10), logs(s)
        browser.get(page)
        flags = [*sim_flags(K, 500, pace=PACE), "--config", str(given)]
        s.start_service("sensor_sim", *flags, env=supervisor.sim_env(WAIT_WITH_DASHBOARD))

        def look() -> dict[str, Any]:
            """What the page shows, read in one script: the DOM is rebuilt on every poll."""
            return dict(browser.execute_script(PAGE_STATE))

        def drawn() -> int:
            return int(look()["drawn"])

        def rmse_text() -> str:
            return str(look()["rmse"])

        def diag() -> str:
            return f"page: {look()}\nbrowser log: {browser.get_log('browser')}\n{logs(s)}"

        first = _until(lambda: drawn() >= 5 and drawn(), 20, "the first steps", diag)
        rmse_first = _until(lambda: "–" not in rmse_text() and rmse_text(), 10, "RMSE", diag)
        assert first < K, "the episode was over before the page saw it"
        _until(lambda: drawn() >= first + 10, 20, "ten more steps", diag)
        assert rmse_text() != rmse_first, "the RMSE did not change as steps arrived"

        _until(lambda: drawn() >= K // 2, 20, "half the episode", diag)
        scan = _until(lambda: look()["scan"]["clutter"] and look()["scan"], 10, "clutter", diag)
        assert scan["k"] > first, scan
        grey = browser.execute_script(
            "const [r, g, b] = arguments[0];"
            "const c = document.getElementById('trajectory');"
            "const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
            "let n = 0; for (let i = 0; i < d.length; i += 4)"
            "  if (d[i] === r && d[i + 1] === g && d[i + 2] === b) n++;"
            "return n;",
            list(CLUTTER_RGB),
        )
        assert grey > 0, f"no false alarm in the plot's pixels, though the page counts {scan}"
        ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
        assert browser.save_screenshot(str(ARTIFACT))
        if os.environ.get("TLTRACK_UPDATE_SCREENSHOT") == "1":
            COMMITTED.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(ARTIFACT, COMMITTED)
        assert drawn() < K, "the screenshot is not mid-episode"

        _until(lambda: drawn() == K, 30, "the whole episode", diag)
        every_track = {"source-rpf": K, "tl-rpf": K, "rpf": K}
        _until(lambda: look()["filters"] == every_track, 30, "every filter's last step", diag)
        _until(lambda: "complete" in look()["status"], 10, "the episode's end", diag)
        seen = look()
        assert {
            "primary/primary_tracker",
            "source/s1/source_tracker",
            "referee/scorer",
            "referee/dashboard",
        } <= set(seen["alive"]), seen
        inked = browser.execute_script(
            "const c = document.getElementById('trajectory');"
            "const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
            "let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n;"
        )
        assert inked > 5000, f"the trajectory canvas is nearly blank ({inked} px)"
        # Chromium aborts a request in flight when the host's interfaces change, as the container
        # tests' Docker networks come and go beside this test; the page polls again (its own
        # handling of a failed poll), so only the page's own errors count
        errors = [
            e
            for e in browser.get_log("browser")
            if e["level"] == "SEVERE" and "net::ERR_NETWORK_CHANGED" not in e["message"]
        ]
        assert not errors, errors
