"""The documentation site builds from scratch, offline, with no warning, and says what it should.

One build (``sphinx-build -W --keep-going``, as ``make docs`` runs it, with the gallery's tutorials
run again) into a temporary folder, with every proxy pointing nowhere so that any network request
fails the build; then checks on the HTML it wrote (the system tier).

And, without a build (the unit tier), the pages written by hand that must follow the code: every
pinned dependency on the contributing page, and every field of results.json on its reference page.
"""

from __future__ import annotations

import ast
import dataclasses
import html
import inspect
import os
import re
import subprocess
import sys
import textwrap
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest
from batch import BELOW

T = TypeVar("T", bound=Callable[..., Any])


def on_the_built_site(test: T) -> T:
    """A check of the built site: the system tier, with time for the build, in one test process
    (the xdist group ``docs``), so that the module's one build serves every check (spread over
    three processes, each built the site itself: 114 s and 90 s of setup in one run)."""
    marked: T = pytest.mark.system(pytest.mark.timeout(1800)(pytest.mark.xdist_group("docs")(test)))
    return marked


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
    argv = [*BELOW, sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q"]
    argv += [str(DOCS), str(out / "html"), "-d", str(out / "doctrees")]
    start = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1700)
    return Build(out, done, time.monotonic() - start)


def visible_text(page: str) -> str:
    """A page's text outside scripts, styles, code and literal blocks."""
    for tag in ("script", "style", "pre", "code", "textarea"):
        page = re.sub(rf"<{tag}\b.*?</{tag}>", " ", page, flags=re.S | re.I)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def text(page: str) -> str:
    """A page's text, code included (tags dropped, so a highlighted ``bench-live`` stays whole)."""
    return html.unescape(re.sub(r"<[^>]+>", "", page))


@on_the_built_site
def test_the_site_builds_without_a_warning(build: Build) -> None:
    said = build.done.stderr + build.done.stdout
    assert build.done.returncode == 0, said[-6000:]
    assert "WARNING" not in said and "ERROR" not in said, said[-6000:]
    assert (build.html / "index.html").is_file()
    print(f"the site built in {build.seconds:.0f} s")  # a time, not a target (a loaded machine)


@on_the_built_site
def test_no_raw_sphinx_role_is_left_in_the_html(build: Build) -> None:
    left = {}
    for page in build.pages():
        found = RAW_ROLE.findall(visible_text(page.read_text()))
        if found:
            left[str(page.relative_to(build.html))] = sorted(set(found))
    assert not left, f"raw roles in the HTML (a docstring or page that was not rendered): {left}"


@on_the_built_site
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


@on_the_built_site
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


@on_the_built_site
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


# ---- the pages written by hand that must follow the code (no build) ---------------------------

CONTRIBUTING = DOCS / "contributing.md"
RESULTS_JSON = DOCS / "reference" / "results-json.md"


def _package(requirement: str) -> str:
    return re.split(r"[\s\[<>=!~;@]", requirement, maxsplit=1)[0].lower().replace("_", "-")


def _section(page: Path, heading: str) -> str:
    """The text of a page's section, from its heading to the next heading of the same level."""
    level = heading.split(" ", 1)[0]
    text = page.read_text()
    assert f"\n{heading}" in text, f"{page.name} has no section {heading!r}"
    return text.split(f"\n{heading}", 1)[1].split(f"\n{level} ", 1)[0]


def _first_cells(section: str) -> list[list[str]]:
    """The names in backticks of the first cell of each table row (the header row aside)."""
    rows = [line.split("|")[1] for line in section.splitlines() if line.startswith("| `")]
    return [re.findall(r"`([^`]+)`", cell) for cell in rows]


@pytest.mark.unit
def test_every_pinned_dependency_is_on_the_contributing_page_with_why() -> None:
    """The project's rule: the docs say why each dependency is there. Each ``###`` of the page's
    dependency section names its group (``dependencies`` or an extra) in its first backticks; its
    table lists exactly that group's packages of pyproject.toml, each pinned to one version."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    groups = {"dependencies": project["dependencies"], **project["optional-dependencies"]}
    unpinned = [r for reqs in groups.values() for r in reqs if "==" not in r]
    assert not unpinned, f"pyproject.toml: not pinned to one version: {unpinned}"
    pinned = {_package(r): group for group, reqs in groups.items() for r in reqs}
    section = _section(CONTRIBUTING, "## Dependencies")
    listed: dict[str, str] = {}
    for part in section.split("\n### ")[1:]:
        heading, _, table = part.partition("\n")
        group = re.search(r"`([^`]+)`", heading)
        assert group, f"contributing.md: the heading {heading!r} names no group"
        for names in _first_cells(table):
            for name in names:
                assert name not in listed, f"contributing.md lists {name} twice"
                listed[name.lower()] = group.group(1)
    missing = {p: g for p, g in pinned.items() if p not in listed}
    stale = {p: g for p, g in listed.items() if p not in pinned}
    moved = {p: (listed[p], g) for p, g in pinned.items() if p in listed and listed[p] != g}
    assert not missing, f"pinned in pyproject.toml, not on docs/contributing.md: {missing}"
    assert not stale, f"on docs/contributing.md, not in pyproject.toml: {stale}"
    assert not moved, f"in another group on docs/contributing.md (page, pyproject): {moved}"


def _keys_written(func: Callable[..., Any]) -> set[str]:
    """The string keys a function writes: of its dict displays, and ``doc["key"] = ...``."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            found |= {k.value for k in node.keys if isinstance(k, ast.Constant)}
        elif isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Store):
            found |= {node.slice.value} if isinstance(node.slice, ast.Constant) else set()
    return {k for k in found if isinstance(k, str)}


@pytest.mark.unit
def test_the_results_json_page_names_every_field_the_code_writes() -> None:
    from tltrack.engine import results
    from tltrack.engine.montecarlo import FilterResult
    from tltrack.studies import reproduce

    page = RESULTS_JSON.read_text()
    for func in (
        results.assemble,
        results.provenance,
        results.position_bounds,
        results.truth_file_record,
        reproduce.run_all,
    ):
        written = _keys_written(func)
        assert written, f"{func.__qualname__} writes no key: is this test still reading it?"
        absent = sorted(k for k in written if f"`{k}`" not in page)
        assert not absent, f"{func.__qualname__} writes {absent}, which {RESULTS_JSON.name} omits"
    version = _section(RESULTS_JSON, "## The document").split("| `schema_version` |", 1)[1]
    assert f"`{results.SCHEMA_VERSION}`" in version.split("\n", 1)[0]
    table = _section(RESULTS_JSON, "## `filters`")
    rows = [name for names in _first_cells(table) for name in names]
    fields = [f.name for f in dataclasses.fields(FilterResult)]
    assert sorted(rows) == sorted(fields), "the filters table is not FilterResult's fields"
