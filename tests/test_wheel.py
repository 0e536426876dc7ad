"""The package as a user gets it: sdist and wheel by ``python -m build``, the wheel installed into a
fresh venv outside the clone (dependencies from the wheelhouse scripts/build_wheels.sh makes), and
``tltrack demo`` run from an unrelated directory, with access control on.

The wheels go to the test's own folder, not build/wheels: the image's build (tests/test_compose.py)
rewrites that one, maybe at the same moment in the other test process, and waiting for it left
this one idle for minutes (the wheelhouse takes 20 s from pip's local wheels)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# one test process runs the module: one wheel build and one venv
pytestmark = [pytest.mark.system, pytest.mark.xdist_group("wheel")]

ROOT = Path(__file__).resolve().parents[1]


def run(argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHON"))}
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with only the wheel (and its pinned dependencies) installed."""
    where = tmp_path_factory.mktemp("fresh")
    wheels = where / "wheels"
    build = run(["bash", str(ROOT / "scripts" / "build_wheels.sh"), str(wheels)], ROOT, timeout=900)
    assert build.returncode == 0, build.stderr
    made = sorted(p.name for p in (wheels / "app").iterdir())
    assert len(made) == 2 and made[0].endswith(".whl") and made[1].endswith(".tar.gz"), made
    subprocess.run([sys.executable, "-m", "venv", str(where / "venv")], check=True)
    pip = str(where / "venv" / "bin" / "pip")
    wheel = str(wheels / "app" / made[0])
    from_wheelhouse = ["--find-links", str(wheels / "deps")]
    install = run([pip, "install", "--no-index", "-q", *from_wheelhouse, wheel], where, 600)
    assert install.returncode == 0, install.stderr
    return where / "venv"


def test_the_wheel_runs_the_demo_from_any_directory_with_access_control(
    venv: Path, tmp_path: Path
) -> None:
    out = run(
        [str(venv / "bin" / "tltrack"), "demo", "--steps=10", "--particles=300", "--json=s.json"],
        tmp_path,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "access control on" in out.stdout.replace("\n", " "), out.stdout
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["access_control"] is True
    assert {f: s["steps"] for f, s in summary["filters"].items()} == {
        "rpf": 10,
        "tl-rpf": 10,
        "source-rpf": 10,
    }
    shown = out.stderr.replace("\n", "")
    assert f"access control: {venv}" in shown, shown  # the package's ACL, not the clone's


def test_the_wheel_installs_no_top_level_services_package(venv: Path, tmp_path: Path) -> None:
    bad = run([str(venv / "bin" / "python"), "-c", "import services"], tmp_path, timeout=60)
    assert bad.returncode != 0 and "No module named 'services'" in bad.stderr, bad.stderr
    code = "import tltrack.services.scorer.scorer as s; print(s.__file__)"
    good = run([str(venv / "bin" / "python"), "-c", code], tmp_path, timeout=60)
    assert good.returncode == 0, good.stderr
    assert good.stdout.startswith(str(venv)), good.stdout
