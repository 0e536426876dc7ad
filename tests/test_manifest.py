"""The operator manifest: the one place operators are declared. The committed access files and
compose.yaml follow from it, and a fourth source operator is one entry in it."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh
from livestack import estimates, logs, mostly_used, sim_flags
from tltrack.config import make_config
from tltrack.live import access, supervisor
from tltrack.live.manifest import Manifest, ManifestError, load_manifest
from tltrack.live.topology import federated
from tltrack.wire.transport import ZenohSettings, open_session

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.unit
def test_the_committed_access_files_and_compose_follow_from_the_packages_manifest() -> None:
    manifest = load_manifest()
    assert access.stale(manifest, ROOT) == [], "run `tltrack access generate`"
    sources = [*(s.model_dump() for s in manifest.sources), {"id": "s4"}]
    four = Manifest.model_validate({"sources": sources})
    changed = {p.name for p in access.stale(four, ROOT)}
    assert changed == {"acl.json5", "primary.json5", "referee.json5", "users.txt", "compose.yaml"}
    rendered = access.repository_files(four, ROOT)
    acl = rendered[ROOT / "shared/tltrack/access/acl.json5"]
    assert 'id: "source-s4-publish"' in acl
    assert 'id: "transfers-in-s4"' in rendered[ROOT / "shared/tltrack/access/routers/primary.json5"]
    cfg = zenoh.Config()
    cfg.insert_json5("access_control", acl)  # zenoh parses what the template renders
    assert "router-s4:" in rendered[ROOT / "compose.yaml"]


@pytest.mark.unit
def test_a_bad_manifest_is_refused_naming_the_file_and_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "ops.toml"
    bad.write_text('[[sources]]\nid = "s1"\n[[sources]]\nid = "s1"\n')
    with pytest.raises(ManifestError, match=r"ops\.toml.*appears twice"):
        load_manifest(bad)
    bad.write_text('[[sources]]\nid = "s/1"\n')
    with pytest.raises(ManifestError, match=r"ops\.toml: sources\.0\.id"):
        load_manifest(bad)
    with pytest.raises(ManifestError, match="cannot read"):
        load_manifest(tmp_path / "missing.toml")
    bad.write_bytes(b"\xff\xfe\x00bad")  # was a UnicodeDecodeError's traceback
    with pytest.raises(ManifestError, match=r"ops\.toml: not UTF-8 text"):
        load_manifest(bad)
    bad.write_text("x = " + "[" * 100_000 + "]" * 100_000)  # was a RecursionError's traceback
    with pytest.raises(ManifestError, match=r"ops\.toml: not valid TOML: nested too deeply"):
        load_manifest(bad)
    for one, other in (("s1", "S1"), ("s-1", "s_1")):  # one password variable, one host name
        bad.write_text(f'[[sources]]\nid = "{one}"\n[[sources]]\nid = "{other}"\n')
        with pytest.raises(ManifestError, match="differ only in case or in - against _"):
            load_manifest(bad)


@pytest.mark.unit
def test_a_refusal_prints_the_pattern_it_names(tmp_path: Path) -> None:
    """rich took the pattern's [a-z0-9-] for markup and printed '^{1,40}$'."""
    from tltrack.app import app
    from typer.testing import CliRunner

    bad = tmp_path / "ops.toml"
    bad.write_text('[[sources]]\nid = "s1"\ncompose_profile = "Bad Profile"\n')
    r = CliRunner().invoke(app, ["access", "show", "--manifest", str(bad)])
    assert r.exit_code == 2 and "^[a-z0-9-]{1,40}$" in r.output, r.output


@pytest.mark.integration
def test_a_fourth_source_from_the_manifest_runs_live_and_a_stranger_is_refused_everywhere(
    tmp_path: Path,
) -> None:
    """A manifest with a fourth source s4, an episode whose only source is s4 on the federated
    stack with every router's ACL on: its transfers reach the primary. An identity the manifest
    does not list gets no session on any router, and s4's own identity gets one on its router."""
    ops = tmp_path / "operators.toml"
    ops.write_text("".join(f'[[sources]]\nid = "{s}"\n' for s in ("s1", "s2", "s3", "s4")))
    K, db = 12, tmp_path / "scorer.sqlite"
    cfg = make_config(preset="arasaratnam-haykin", truth="fixed", K=K, particles=300,
                      sources=[{"id": "s4"}])  # fmt: skip
    config = tmp_path / "s4.json"
    config.write_text(cfg.model_dump_json())
    topo = federated(["s4"])
    with supervisor.Stack(topo.referee.endpoint, tmp_path / "logs", True, topology=topo,
                          manifest_file=ops) as s:  # fmt: skip
        s.start_router()
        s.start_service("scorer", env={"TLTRACK_SCORER_DB": str(db)})
        wait = s.start_trackers(cfg)
        flags = [*sim_flags(K, 300), f"--config={config}"]
        s.start_service("sensor_sim", *flags, env=supervisor.sim_env(wait))
        assert s.wait("sensor_sim", 120) == 0, logs(s)
        assert supervisor.wait_for_scored(s.endpoint, 1, 120, "referee") is not None, logs(s)
        for router in topo.routers.values():
            with pytest.raises(zenoh.ZError):  # a stranger: no session at all
                open_session(ZenohSettings(
                    endpoints=[router.endpoint], username="source-s9",
                    password="demo-source-s9-pw", connect_timeout_ms=1500,
                ))  # fmt: skip
        with open_session(ZenohSettings(
            endpoints=[topo.routers["source/s4"].endpoint], username="source-s4",
            password="demo-source-s4-pw", connect_timeout_ms=5000,
        )) as z:  # fmt: skip
            assert z.info.routers_zid()
    live = estimates(db)
    used = [live["tl-rpf"][k][1] for k in range(1, K + 1)]
    # mostly: a heartbeat held back past its timeout on a loaded machine cuts a step's transfer
    assert not used[0] and mostly_used(used[1:]), used


@pytest.mark.unit
def test_generate_into_a_partial_repository_writes_nothing(tmp_path: Path) -> None:
    """It wrote acl.json5, then failed with a traceback on the missing routers/ folder."""
    import shutil

    from tltrack.app import app
    from typer.testing import CliRunner

    (tmp_path / "deploy").mkdir()
    shutil.copy(ROOT / "deploy" / "compose.template.yaml", tmp_path / "deploy")
    (tmp_path / "shared" / "tltrack" / "access").mkdir(parents=True)
    r = CliRunner().invoke(app, ["access", "generate", "--root", str(tmp_path)])
    said = "".join(r.output.split())  # rich breaks a long path anywhere
    assert r.exit_code == 2 and "isnotatltrackrepository(no" in said, r.output
    assert "access/routers" in said and not any((tmp_path / "shared").rglob("*.*"))
