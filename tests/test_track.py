"""Recorded scans (tltrack.engine.scan_file) and ``tltrack track``: the trackers over a scan file,
offline, with the engine's numbers for the run the file records."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest
from tltrack.app import app
from tltrack.config import Config, load_config, make_config
from tltrack.config.truth_file import file_truth
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scan_file import ScanFileError, ScansDoNotFitError, read_scans
from tltrack.engine.scenario import Run, simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.track import track
from tltrack.models.scan import MAX_DETECTIONS
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

#: a cluttered primary radar and a clean source radar, short: every filter kind runs in seconds
CLUTTER = {"primary_detection": {"pd": 0.9, "clutter_rate": 5.0}, "K": 25, "particles": 400}
HEADER = ["k", "sensor", "range_m", "bearing_rad", "is_clutter"]


def write_scans(path: Path, setup: Setup, run: Run) -> Path:
    """A run's scans as the file a recorder would write: one row per detection (repr floats,
    so the file holds exactly the engine's numbers)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        for sid in setup.sensor_ids:
            for k in range(1, setup.cfg.K + 1):
                if sid in run.scans:
                    dets, fake = run.scans[sid].detections[k - 1], run.scans[sid].is_clutter[k - 1]
                else:
                    dets, fake = run.z[sid][k - 1][None, :], np.array([False])
                for z, c in zip(dets, fake, strict=True):
                    w.writerow([k, sid, *map(repr, map(float, z)), int(c)])
    return path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Config, Run, Path]:
    cfg = make_config(preset="arasaratnam-haykin", **CLUTTER)
    setup = Setup(cfg)
    run = simulate(setup, 3)
    return cfg, run, write_scans(tmp_path_factory.mktemp("scans") / "scans.csv", setup, run)


def sensors(cfg: Config) -> dict:
    setup = Setup(cfg)
    return {sid: setup.sensor(sid) for sid in setup.sensor_ids}


def test_a_recorded_run_tracked_offline_gives_the_engines_numbers(recorded) -> None:
    """Every filter kind in its roles, over the file, from the run's x0_hat and random streams:
    exactly the Monte-Carlo engine's estimates of that run."""
    cfg, run, path = recorded
    names = ["rpf", "tl-rpf", "ukf", "tl-ckf3", "robust-tl-pf", "fusion-pf"]
    scans = read_scans(path, sensors(cfg), cfg.K)
    done = track(cfg, names, scans, x0_hat=run.x0_hat, run=run.run)
    engine = trace_run(cfg, names, run.run)
    got: dict[str, list[np.ndarray]] = {}
    for _k, name, x, _P in done.tracks.estimates:
        got.setdefault(name, []).append(x)
    for name in names:
        np.testing.assert_array_equal(np.array(got[name]), engine[name], err_msg=name)
    # the sources' transfers: one per step, for the next
    assert [k for k, name, *_ in done.tracks.transfers if name == "source-rpf"] == list(
        range(2, cfg.K + 2)
    )


def test_the_files_clutter_labels_are_read_for_scoring_only(recorded) -> None:
    cfg, run, path = recorded
    scans = read_scans(path, sensors(cfg), cfg.K)
    for k in range(1, cfg.K + 1):
        labels = scans.is_clutter[PRIMARY][k - 1]
        assert labels is not None
        np.testing.assert_array_equal(labels, run.scans[PRIMARY].is_clutter[k - 1])


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_track_runs_a_file_with_duplicates_empty_scans_and_a_scan_over_the_bound(
    recorded, tmp_path: Path
) -> None:
    _cfg, _run, path = recorded
    rows = _rows(path)
    primary = [r for r in rows if r["sensor"] == PRIMARY]
    kept = [r for r in rows if not (r["sensor"] == PRIMARY and r["k"] in ("4", "5"))]  # empty
    kept += [primary[0]] * 2  # a detection recorded twice: two detections
    kept += [{**primary[-1], "k": "9"}] * (MAX_DETECTIONS + 1)  # step 9: one too many
    bad = tmp_path / "scans.csv"
    with open(bad, "w", newline="") as fh:
        w = csv.DictWriter(fh, HEADER)
        w.writeheader()
        w.writerows(kept)
    out = tmp_path / "out"
    args = ["track", "--scans", str(bad), "--preset", "arasaratnam-haykin", "--steps", "25"]
    args += ["--pd", "0.9", "--clutter-rate", "5", "--particles", "400"]
    args += ["--filters", "rpf,tl-rpf,ukf", "--out", str(out)]
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 0, done.output
    text = "".join(done.output.split())  # the console wraps long paths anywhere
    nine = [i for i, r in enumerate(kept) if r["sensor"] == PRIMARY and r["k"] == "9"]
    line = nine[MAX_DETECTIONS] + 2  # the 4097th detection of step 9 (the header is line 1)
    assert f"scans.csv:{line}:step9ofsensor'primary'hasmorethan4096" in text, text
    assert "1scan(s)refused" in text
    estimates = _rows(out / "estimates.csv")
    by_filter: dict[str, list[int]] = {}
    for r in estimates:
        by_filter.setdefault(r["filter"], []).append(int(r["k"]))
    assert by_filter.keys() == {"rpf", "tl-rpf", "ukf", "source-rpf"}
    assert all(ks == list(range(1, 26)) for ks in by_filter.values()), by_filter
    assert list(estimates[0])[:6] == ["k", "filter", "x_m", "y_m", "vx_mps", "vy_mps"]
    assert all(np.isfinite(float(r["P_xx"])) for r in estimates)
    transfers = _rows(out / "transfers.csv")
    assert [int(t["k_apply"]) for t in transfers] == list(range(2, 27))
    assert {t["source"] for t in transfers} == {"s1"}
    assert not (out / "results.json").exists()  # no truth, no scores
    assert (out / "scans.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("row", "says"),
    [
        ("26,primary,1000,0.5,0", ":2: k = 26 is beyond the config's K = 25"),
        ("0,primary,1000,0.5,0", ":2: need k >= 1"),
        ("1,primary,nan,0.5,0", ":2: range_m must be finite and in (0, 1e9]"),
        ("1,primary,1e300,0.5,0", ":2: range_m must be finite and in (0, 1e9]"),
        ("1,primary,1000,4,0", ":2: bearing_rad must be finite and in [-pi, pi]"),
        ("1,primary,1000,east,0", ":2: a range-bearing sensor needs bearing_rad as a number"),
        ("1,radar,1000,0.5,0", ":2: unknown sensor 'radar'"),
        ("1,primary,1000,0.5,maybe", ":2: is_clutter must be 1, 0, true, false or empty"),
        ("1,primary,1000", ":2: a range-bearing sensor needs bearing_rad as a number"),
    ],
)
def test_a_bad_row_refuses_the_file_naming_its_line(recorded, tmp_path, row, says) -> None:
    cfg, _run, _path = recorded
    p = tmp_path / "bad.csv"
    p.write_text(",".join(HEADER) + "\n" + row + "\n")
    with pytest.raises(ScanFileError, match=re.escape(says)):
        read_scans(p, sensors(cfg), cfg.K)
    done = CliRunner().invoke(app, ["track", "--scans", str(p), "--steps", "25", "--out", "x"])
    assert done.exit_code == 2, done.output
    assert says.replace(" ", "") in "".join(done.output.split()), done.output  # wrapped anywhere


@pytest.mark.parametrize(
    ("row", "says"),
    [
        # K follows from the file: 1e9 steps of empty scans hung the replay's start
        ("1000000000,primary,1000,0.5,0", ":2: k = 1000000000 is beyond the 100000 steps of a run"),
        # csv's own limit on a field: its csv.Error was a traceback
        ("1,primary," + "1" * 200_000 + ",0.5,0", ":2: not CSV: field larger than field limit"),
    ],
    ids=["k-1e9", "huge-field"],
)
def test_a_file_whose_last_step_is_its_K_is_refused_past_a_runs_steps(
    recorded, tmp_path, row, says
) -> None:
    cfg, _run, _path = recorded
    p = tmp_path / "bad.csv"
    p.write_text(",".join(HEADER) + "\n" + row + "\n")
    with pytest.raises(ScanFileError, match=re.escape(says)):
        read_scans(p, sensors(cfg))


def test_a_sensor_the_config_says_is_clean_takes_one_detection_per_step(recorded, tmp_path) -> None:
    _cfg, _run, path = recorded
    clean = make_config(preset="arasaratnam-haykin", K=25)
    with pytest.raises(ScansDoNotFitError, match=r"step \d+ of sensor 'primary' has \d+ detect"):
        track(clean, ["rpf"], read_scans(path, sensors(clean), clean.K))
    out = tmp_path / "out"
    args = ["track", "--scans", str(path), "--preset", "arasaratnam-haykin", "--steps", "25"]
    done = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert done.exit_code == 2 and "detect" in done.output, done.output
    assert "steps" not in done.output and not out.exists(), "refused after a progress bar"


def test_with_a_truth_file_track_writes_the_scores_of_its_estimates(tmp_path: Path) -> None:
    t = np.arange(0.0, 31.0)
    xy = 3000.0 + 800.0 * np.stack([np.cos(0.05 * t), np.sin(0.05 * t)], 1)
    truth_csv = tmp_path / "circle.csv"
    truth_csv.write_text(
        "t,x,y\n" + "".join(f"{a},{x},{y}\n" for a, (x, y) in zip(t, xy, strict=True))
    )
    cfg = load_config(None, preset="arasaratnam-haykin", truth_file=truth_csv, **CLUTTER)
    setup = Setup(cfg)
    path = write_scans(tmp_path / "scans.csv", setup, simulate(setup, 0))
    out = tmp_path / "out"
    args = ["track", "--scans", str(path), "--preset", "arasaratnam-haykin", "--steps", "25"]
    args += ["--pd", "0.9", "--clutter-rate", "5", "--particles", "400", "--filters", "tl-rpf"]
    args += ["--truth-file", str(truth_csv), "--out", str(out)]
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 0, done.output
    scores = json.loads((out / "results.json").read_text())["filters"]["tl-rpf"]
    est = [r for r in _rows(out / "estimates.csv") if r["filter"] == "tl-rpf"]
    x = file_truth(cfg)
    err = [np.hypot(float(r["x_m"]) - x[int(r["k"]), 0], float(r["y_m"]) - x[int(r["k"]), 2])
           for r in est]  # fmt: skip
    np.testing.assert_allclose(scores["rmse_per_step"], err, rtol=1e-9)


def test_a_scan_file_saved_with_a_byte_order_mark_reads_as_without(recorded, tmp_path) -> None:
    """Spreadsheets save CSV with a UTF-8 BOM; truth files already accept one."""
    cfg, _run, path = recorded
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    plain, marked = read_scans(path, sensors(cfg), cfg.K), read_scans(bom, sensors(cfg), cfg.K)
    for sid, scans in plain.detections.items():
        assert all(np.array_equal(a, b) for a, b in zip(scans, marked.detections[sid], strict=True))
