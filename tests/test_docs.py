"""The documentation site builds from scratch, offline, with no warning, and says what it should.

One build (``sphinx-build -W --keep-going``, as ``make docs`` runs it, with the gallery's tutorials
run again) into a temporary folder, with every proxy pointing nowhere so that any network request
fails the build; then checks on the HTML it wrote.
"""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.system, pytest.mark.timeout(900)]

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
TUTORIALS = ROOT / "examples" / "tutorials"
NOWHERE = "http://127.0.0.1:9"  # the discard port: nothing answers

#: a Sphinx role left as text: ``:class:`` (or ``:py:func:`` ...) outside code
RAW_ROLE = re.compile(
    r":(?:py:)?(?:class|mod|func|meth|attr|data|obj|exc|const|type|ref|doc|term|envvar|"
    r"option|any|math|numref|program|file|samp|kbd|abbr):"
)


class Build:
    def __init__(self, out: Path, done: subprocess.CompletedProcess[str], seconds: float) -> None:
        self.out, self.done, self.seconds = out, done, seconds
        self.html = out / "html"

    def pages(self) -> list[Path]:
        return sorted(self.html.rglob("*.html"))


@pytest.fixture(scope="module")
def build(tmp_path_factory: pytest.TempPathFactory) -> Build:
    out = tmp_path_factory.mktemp("docs")
    env = {
        **os.environ,
        "TLTRACK_DOCS_RERUN": "1",  # run the gallery's tutorials again, not from its cache
        "MPLBACKEND": "Agg",
        **{v: NOWHERE for v in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY")},
        **{v: NOWHERE for v in ("all_proxy", "ALL_PROXY")},
        "no_proxy": "",
        "NO_PROXY": "",
    }
    argv = [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q"]
    argv += [str(DOCS), str(out / "html"), "-d", str(out / "doctrees")]
    start = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=840)
    return Build(out, done, time.monotonic() - start)


def visible_text(page: str) -> str:
    """A page's text outside scripts, styles, code and literal blocks."""
    for tag in ("script", "style", "pre", "code", "textarea"):
        page = re.sub(rf"<{tag}\b.*?</{tag}>", " ", page, flags=re.S | re.I)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def text(page: str) -> str:
    """A page's text, code included (tags dropped, so a highlighted ``bench-live`` stays whole)."""
    return html.unescape(re.sub(r"<[^>]+>", "", page))


def test_the_site_builds_without_a_warning(build: Build) -> None:
    said = build.done.stderr + build.done.stdout
    assert build.done.returncode == 0, said[-6000:]
    assert "WARNING" not in said and "ERROR" not in said, said[-6000:]
    assert (build.html / "index.html").is_file()
    assert build.seconds < 600, f"the build took {build.seconds:.0f} s"


def test_no_raw_sphinx_role_is_left_in_the_html(build: Build) -> None:
    left = {}
    for page in build.pages():
        found = RAW_ROLE.findall(visible_text(page.read_text()))
        if found:
            left[str(page.relative_to(build.html))] = sorted(set(found))
    assert not left, f"raw roles in the HTML (a docstring or page that was not rendered): {left}"


def test_the_maths_are_rendered_by_a_local_mathjax_and_nothing_is_fetched(build: Build) -> None:
    concepts = (build.html / "concepts.html").read_text()
    scripts = re.findall(r'<script[^>]*src="([^"]+)"', concepts)
    mathjax = [s for s in scripts if "mathjax" in s.lower()]
    assert mathjax and all(not re.match(r"^[a-z]+:", s) for s in mathjax), scripts
    for src in mathjax:
        assert (build.html / src.split("?")[0]).is_file(), src
    assert r"\hat\eta" in concepts  # the equations are on the page, for MathJax to typeset
    remote = re.compile(r'<(?:script|link|img)[^>]+(?:src|href)="(?:https?:)?//', re.I)
    for page in build.pages():
        assert not remote.search(page.read_text()), f"{page.name} loads something remote"


def test_the_gallery_tutorials_ran_and_drew_their_figures(build: Build) -> None:
    scripts = sorted(TUTORIALS.glob("plot_*.py"))
    assert len(scripts) >= 3
    for script in scripts:
        page = build.html / "tutorials" / "gallery" / f"{script.stem}.html"
        text = page.read_text()
        figures = re.findall(rf'src="[^"]*(sphx_glr_{script.stem}_\d+\.png)"', text)
        assert figures, f"{page.name} shows no figure"
        for name in figures:
            assert (build.html / "_images" / name).stat().st_size > 5000, name
        assert "sphx-glr-script-out" in text, f"{page.name} shows no output"


def test_the_references_are_generated_from_the_code(build: Build) -> None:
    import typer.main
    from tltrack.app import app
    from tltrack.config import Config, SensorSpec, SourceSpec
    from tltrack.filters.kinds import FILTERS
    from tltrack.models.kinds import MOTIONS, SENSORS
    from tltrack.wire import keys
    from tltrack.wire.messages import MESSAGE_TYPES, REASONS

    reference = build.html / "reference"
    config = text((reference / "config.html").read_text())
    for model in (Config, SourceSpec, SensorSpec):
        for field in model.model_fields:
            assert field in config, f"{model.__name__}.{field} is not in the config reference"
    for registry in (SENSORS, MOTIONS, FILTERS):
        for kind in registry.names():
            assert kind in config
            for p in registry.get(kind).parameters:
                assert p.name in config and p.unit in config
    wire = text((reference / "wire.html").read_text())
    for tag, cls in MESSAGE_TYPES.items():
        assert tag in wire and cls.__name__ in wire
    assert all(reason in wire for reason in REASONS)
    assert keys.transfer(keys.ANY, keys.ANY) in wire
    cli = text((reference / "cli.html").read_text())
    for name in typer.main.get_command(app).commands:  # type: ignore[attr-defined]
        assert f"tltrack {name}" in cli, f"tltrack {name} is not in the CLI reference"
    api = "".join(p.read_text() for p in (build.html / "reference" / "api").glob("*.html"))
    for name in ("tltrack.declare.Parameter", "tltrack.wire.messages.Transfer", "tltrack.app"):
        assert f'id="{name}"' in api or f'id="module-{name}"' in api, name
