"""The package as a user gets it: the sdist and the wheel that scripts/build_image.sh builds with
``python -m build``, the wheel installed in the image's own venv (/opt/venv, no clone in sight),
and ``tltrack demo`` run there from an unrelated directory, with access control on.

The image is tests/test_compose.py's (built once per run, or reused while its sources are
unchanged): this module waits for its build, in a test process of its own (the xdist group
``wheel``), off the compose tests' chain. It used to build its own wheelhouse and venv and compile
the kernels cold: 3.5 minutes of a test process for what the image's build already does.
"""

from __future__ import annotations

import json
import subprocess

import pytest
from test_compose import ROOT, compose, image  # noqa: F401

pytestmark = [pytest.mark.system, pytest.mark.timeout(1500), pytest.mark.xdist_group("wheel")]

VENV = "/opt/venv"  #: where the Dockerfile installs the wheel


def in_image(image: str, *argv: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:  # noqa: F811
    """Run ``argv`` in a fresh container of ``image``, in /tmp (not the image's WORKDIR)."""
    cmd = ["docker", "run", "--rm", "--workdir", "/tmp", image, *argv]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)


def test_the_build_makes_a_wheel_and_an_sdist(image: str) -> None:  # noqa: F811
    made = sorted(p.name for p in (ROOT / "build" / "wheels" / "app").iterdir())
    assert len(made) == 2 and made[0].endswith(".whl") and made[1].endswith(".tar.gz"), made


def test_the_wheel_runs_the_demo_from_any_directory_with_access_control(image: str) -> None:  # noqa: F811
    script = "tltrack demo --steps=10 --particles=300 --json=s.json >&2 && cat s.json"
    out = in_image(image, "sh", "-c", script)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "access control on" in out.stderr.replace("\n", " "), out.stderr
    summary = json.loads(out.stdout)
    assert summary["access_control"] is True
    assert {f: s["steps"] for f, s in summary["filters"].items()} == {
        "rpf": 10,
        "tl-rpf": 10,
        "source-rpf": 10,
    }
    shown = out.stderr.replace("\n", "")
    assert f"access control: {VENV}/" in shown, shown  # the package's ACL, not a clone's


def test_the_wheel_installs_no_top_level_services_package(image: str) -> None:  # noqa: F811
    bad = in_image(image, "python", "-c", "import services")
    assert bad.returncode != 0 and "No module named 'services'" in bad.stderr, bad.stderr
    code = "import tltrack.services.scorer.scorer as s; print(s.__file__)"
    good = in_image(image, "python", "-c", code)
    assert good.returncode == 0, good.stderr
    assert good.stdout.startswith(f"{VENV}/"), good.stdout
