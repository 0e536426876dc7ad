"""The test tiers, and what every test module may import from this folder.

Every test carries exactly one tier mark (a collection error names any that does not):

- ``unit``: one process, no router; ``make check`` runs these;
- ``integration``: real processes over loopback Zenoh (routers, services, the CLI's live
  commands);
- ``system``: Docker, the built wheel, Chromium, the golden worktree, the whole reproduction.

``make test`` runs all three on every core (pytest-xdist); live tests whose timing matters share
the xdist group ``live`` so that they never run beside each other.
"""

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

TIERS = ("unit", "integration", "system")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--cpu-profile",
        action="store_true",
        help="record each test's CPU, its child processes' included (tests/cpu_profile.py)",
    )


def pytest_configure(config: pytest.Config) -> None:
    if config.getoption("--cpu-profile"):
        config.pluginmanager.import_plugin("cpu_profile")


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """``--dist loadgroup`` under pytest >= 9.2: pytest-xdist 3.8 marks a test's group by
    assigning ``item._nodeid``, which pytest 9.2 no longer reads (the node id is ``item._id``), so
    every ``xdist_group`` was ignored and the tests of a group spread over the workers (two compose
    stacks at once, fighting for the dashboard's host port). Put the group in the id as xdist
    means to: ``<nodeid>@<group>``, which the controller's scheduler reads.

    And every test carries exactly one tier."""
    wrong = []
    for item in items:
        tiers = [t for t in TIERS if any(m.name == t for m in item.iter_markers())]
        if len(tiers) != 1:
            wrong.append(f"  {item.nodeid}: {', '.join(tiers) or 'no tier'}")
    if wrong:
        raise pytest.UsageError(
            f"every test carries exactly one of the marks {', '.join(TIERS)}:\n" + "\n".join(wrong)
        )
    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        names = {
            str(m.args[0] if m.args else m.kwargs.get("name", "default"))
            for m in item.iter_markers("xdist_group")
        }
        suffix = "@" + "_".join(sorted(names))
        if names and not item.nodeid.endswith(suffix):
            from _pytest.nodeid import NodeId  # pytest >= 9.2; older ones take xdist's _nodeid

            item._id = NodeId.parse(item.nodeid + suffix)  # type: ignore[attr-defined]


@pytest.fixture(autouse=True)
def _kinds_imported_by_a_test_stay_in_that_test() -> Iterator[None]:
    """A test that names a kind by import path (``doubles:PositionSensor``) registers it in this
    process, and every stack started afterwards in the same process passes it on to its services
    (``plugins.passed_on``), which cannot import tests/doubles.py and exit: under pytest-xdist,
    whether a live test failed so depended on which unit tests its worker had run before."""
    from tltrack.config import plugins

    saved = {
        concept: (dict(r._kinds), dict(r.imported), r._plugins_loaded)
        for concept, r in plugins.REGISTRIES.items()
    }
    yield
    for concept, (kinds, imported, loaded) in saved.items():
        r = plugins.REGISTRIES[concept]
        r._found, r.imported, r._plugins_loaded = kinds, imported, loaded
