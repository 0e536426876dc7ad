"""A sweep stopped part-way resumes from its checkpoint folder, to the uninterrupted numbers."""

import dataclasses
import hashlib
import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from tltrack.app import app
from tltrack.config import make_config
from tltrack.config.load import load_config
from tltrack.engine import montecarlo
from tltrack.engine.checkpoint import Checkpoint, code_digest, environment, plugin_digest
from tltrack.engine.montecarlo import FilterStats, run_batch, run_sweep
from tltrack.filters.kinds import FILTERS
from tltrack.studies.common import Runner
from tltrack.studies.finished import Finished
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

NAMES = ["pf", "tl-pf", "tl-ukf"]


def _cfgs(runs=7, seed=4):
    return [
        make_config(
            {
                "preset": "arasaratnam-haykin",
                "K": 12,
                "particles": 150,
                "runs": runs,
                "seed": seed,
                "primary_intensity": i,
            }
        )
        for i in (2, 6)
    ]


def _sweep(cfgs, folder=None):
    return run_sweep(cfgs, NAMES, batch_size=3, workers=1, time_steps=False, checkpoint=folder)


class StopError(Exception):
    """What a kill would be."""


def _stopped(cfgs, folder):
    """Run the sweep of ``cfgs`` (7 runs: batches of 3, 3 and 1) with ``folder`` as its checkpoint
    and stop it as a kill would, as it hears of its second batch: both batches are kept, the first
    alone merged (and so in the prefix file)."""
    calls = []

    def stop_after_two(n):
        calls.append(n)
        if len(calls) == 2:
            raise StopError

    with pytest.raises(StopError):
        run_sweep(
            cfgs, NAMES, batch_size=3, workers=1, time_steps=False, checkpoint=folder,
            progress=stop_after_two,
        )  # fmt: skip


def _drop(folder, pattern):
    """Delete the files of ``folder`` that match ``pattern``."""
    for file in folder.glob(pattern):
        file.unlink()


def _as_another_cpus(file, kind):
    """Make ``file`` (a ``kind`` file, sweep or prefix, of batches of 3) one that another CPU
    wrote: its recorded CPU, and its name, which differs as its digest does."""
    doc = json.loads(file.read_text())
    doc["made"]["environment"]["cpu"] = "another-cpu"
    file.unlink()
    (file.parent / f"{kind}-000000000000000000000000-b3.json").write_text(json.dumps(doc))


def _prefix(folder):
    """The prefix file in ``folder`` and its document."""
    (file,) = folder.glob("prefix-*.json")
    return file, json.loads(file.read_text())


@pytest.fixture
def batches_run(monkeypatch):
    """The runs of every batch that the engine actually ran (not read back), in this process
    (``workers=1``); the timing run of ``time_steps`` and the figure's traced run aside."""
    seen: list[list[int]] = []
    real = montecarlo.run_sweep_batch

    def counted(cfgs, names, runs, **kw):
        if not kw.get("timing") and not kw.get("keep_tracks"):
            seen.append(list(runs))
        return real(cfgs, names, runs, **kw)

    monkeypatch.setattr(montecarlo, "run_sweep_batch", counted)
    return seen


def _same(a, b):
    """Every field of every filter's result equal, NaN to NaN."""
    for x, y in zip(a, b, strict=True):
        assert x.keys() == y.keys()
        for name in x:
            fx, fy = (json.dumps(dataclasses.asdict(r[name]), default=list) for r in (x, y))
            assert fx == fy, name


def test_a_stopped_sweep_resumes_to_the_uninterrupted_numbers(tmp_path, batches_run):
    cfgs = _cfgs()
    whole = _sweep(cfgs)
    batches_run.clear()
    _stopped(cfgs, tmp_path)
    assert batches_run == [[0, 1, 2], [3, 4, 5]]
    assert len(list(tmp_path.glob("batch-*.pkl"))) == 2
    batches_run.clear()
    _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == [[6]]  # only the batch that had not finished
    batches_run.clear()
    _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == []  # all read back


def test_more_runs_reuse_the_batches_of_fewer_and_other_settings_reuse_none(tmp_path, batches_run):
    _sweep(_cfgs(runs=4), tmp_path)  # batches [0, 1, 2] and [3]
    batches_run.clear()
    _same(_sweep(_cfgs(runs=7), tmp_path), _sweep(_cfgs(runs=7)))
    assert batches_run[:2] == [[3, 4, 5], [6]]  # [0, 1, 2] was read back; [3] is not a batch now
    batches_run.clear()
    _sweep(_cfgs(runs=4, seed=5), tmp_path)
    assert batches_run == [[0, 1, 2], [3]]  # another seed: nothing of the other sweep's


def test_an_unreadable_batch_file_is_run_again_with_a_warning(tmp_path, batches_run):
    cfgs = _cfgs(runs=4)
    whole = _sweep(cfgs, tmp_path)
    _drop(tmp_path, "prefix-*.json")  # else read first, and the batch files not at all
    victim = sorted(tmp_path.glob("batch-*.pkl"))[0]
    victim.write_bytes(victim.read_bytes()[:40])  # as a crash of the disk's cache might leave it
    batches_run.clear()
    with pytest.warns(UserWarning, match="unreadable"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert len(batches_run) == 1


def test_the_cli_resumes_an_experiment_from_its_checkpoint(tmp_path, batches_run):
    keep = tmp_path / "keep"
    args = ["experiment", "--preset", "arasaratnam-haykin", "--filters", "pf,tl-pf"]
    args += ["--runs", "4", "--particles", "150", "--batch-size", "2", "--workers", "1"]
    args += ["--checkpoint", str(keep)]
    first = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "a")])
    assert first.exit_code == 0, first.output
    assert len(list(keep.glob("batch-*.pkl"))) == 2
    batches_run.clear()
    again = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "b")])
    assert again.exit_code == 0, again.output
    assert batches_run == []  # both batches read back
    a, b = (json.loads((tmp_path / d / "results.json").read_text()) for d in "ab")
    for name in ("pf", "tl-pf"):
        assert a["filters"][name]["run_rmse"] == b["filters"][name]["run_rmse"]


def test_a_pool_resumes_from_batches_that_are_not_a_prefix(tmp_path):
    cfgs = _cfgs(runs=13)  # batches of 3: [0..2], [3..5], [6..8], [9..11], [12]
    kw = {"batch_size": 3, "workers": 2, "time_steps": False}
    whole = run_sweep(cfgs, NAMES, checkpoint=tmp_path, **kw)
    kept = Checkpoint(tmp_path, cfgs, NAMES)
    for runs in ([0, 1, 2], [6, 7, 8], [12]):
        kept.path(runs).unlink()
    _drop(tmp_path, "prefix-*.json")
    assert len(list(tmp_path.glob("batch-*.pkl"))) == 2
    _same(run_sweep(cfgs, NAMES, checkpoint=tmp_path, **kw), whole)
    assert len(list(tmp_path.glob("batch-*.pkl"))) == 5


def test_a_recorded_truth_edited_under_the_same_name_is_run_again(tmp_path, batches_run):
    track = tmp_path / "track.csv"
    shutil.copy(Path(__file__).parents[1] / "examples/tracks/flight-HHH008.csv", track)
    cfg = load_config(None, truth_file=track, K=8, runs=3, particles=100)
    run = {"batch_size": 3, "workers": 1, "time_steps": False, "checkpoint": tmp_path / "keep"}
    run_sweep([cfg], ["pf"], **run)
    run_sweep([cfg], ["pf"], **run)
    assert batches_run == [[0, 1, 2]]  # the second read it back
    (tmp_path / "elsewhere").mkdir()
    copy = shutil.copy(track, tmp_path / "elsewhere" / "renamed.csv")
    run_sweep([load_config(None, truth_file=copy, K=8, runs=3, particles=100)], ["pf"], **run)
    assert batches_run == [[0, 1, 2]]  # the same bytes under another path: read back
    track.write_text(track.read_text() + "\n")  # the same track, other bytes
    run_sweep([cfg], ["pf"], **run)
    assert batches_run == [[0, 1, 2], [0, 1, 2]]


def test_the_code_digest_follows_code_and_not_docstrings(tmp_path):
    def digest(source):
        (tmp_path / "filters").mkdir(exist_ok=True)
        (tmp_path / "filters" / "f.py").write_text(source)
        code_digest.cache_clear()
        return code_digest(tmp_path)

    base = digest('"""A module."""\n\ndef f(x):\n    """Why."""\n    return 2 * x\n')
    reworded = '"""Reworded."""\n\ndef f(x):\n    """Why not."""\n    return 2 * x  # !\n'
    assert digest(reworded) == base
    assert digest('"""A module."""\n\ndef f(x):\n    """Why."""\n    return 3 * x\n') != base
    (tmp_path / "engine").mkdir()
    (tmp_path / "engine" / "plots.py").write_text("def g():\n    return 1\n")
    assert digest(reworded) == base  # a module beside the numbers: its edits keep the files
    (tmp_path / "engine" / "montecarlo.py").write_text("def g():\n    return 1\n")
    assert digest(reworded) != base
    code_digest.cache_clear()
    with pytest.raises(RuntimeError, match="no source"):
        code_digest(tmp_path / "elsewhere")
    code_digest.cache_clear()


def test_a_checkpoint_that_cannot_be_written_is_refused_before_any_run(tmp_path):
    taken = tmp_path / "a-file"
    taken.write_text("")
    args = ["experiment", "--runs", "2", "--out", str(tmp_path / "o"), "--checkpoint", str(taken)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2, r.output
    assert "--checkpoint" in r.output and not (tmp_path / "o").exists()


def test_a_save_that_fails_warns_and_the_sweep_goes_on(tmp_path, monkeypatch):
    cfgs = _cfgs(runs=4)
    whole = _sweep(cfgs)

    def full(*_args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("tltrack.engine.checkpoint.os.replace", full)
    with pytest.warns(UserWarning, match="cannot save"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert not list(tmp_path.iterdir())  # no batch, no prefix, nor a temporary file left behind


def _study_sweep(folder, batch_size=3, progress=None):
    runner = Runner(workers=1, batch_size=batch_size, checkpoint=folder, progress=progress)
    return runner.sweep(_cfgs(runs=4), NAMES, time_steps=False)


def _sweep_file_alone(folder):
    """A study's sweep, run with ``folder`` as its checkpoint, and its sweep file, every batch and
    prefix file deleted: what a copy of the sweep files alone carries."""
    results = _study_sweep(folder)
    (kept,) = folder.glob("sweep-*.json")
    _drop(folder, "batch-*.pkl")
    _drop(folder, "prefix-*.json")
    return results, kept


def test_a_finished_sweep_is_read_back_whole_from_its_file_alone(tmp_path, batches_run):
    studied, kept = _sweep_file_alone(tmp_path)
    whole = _sweep(_cfgs(runs=4))
    _same(studied, whole)
    batches_run.clear()
    heard: list[int] = []
    _same(_study_sweep(tmp_path, progress=heard.append), whole)
    assert batches_run == []
    assert heard == [4]  # the bar counts the sweep's runs
    _study_sweep(tmp_path, batch_size=2)  # another batch size: another file, run again
    assert len(batches_run) == 2 and len(list(tmp_path.glob("sweep-*.json"))) == 2
    assert kept.exists()


def test_a_sweep_finished_on_another_machine_is_read_back_with_a_warning(tmp_path, batches_run):
    whole, kept = _sweep_file_alone(tmp_path)
    _as_another_cpus(kept, "sweep")
    batches_run.clear()
    with pytest.warns(UserWarning, match=r"another environment \(cpu differ; CPU another-cpu"):
        _same(_study_sweep(tmp_path), whole)
    assert batches_run == []
    batches_run.clear()
    _study_sweep(tmp_path, batch_size=2)  # another sweep: not that file's, so run
    assert len(batches_run) == 2


@pytest.mark.parametrize(
    "damage",
    [
        lambda d: d["results"][0]["pf"]["run_rmse"].pop(),  # a run short
        # each was a traceback, or a result no study could read
        lambda d: d["results"].__setitem__(0, [1]),
        lambda d: d["results"][0]["pf"].__setitem__("run_rmse", "abcd"),
        lambda d: d["results"][0]["pf"].__setitem__("rmse_overall", None),
    ],
    ids=["a-run-short", "a-list", "a-string", "a-null"],
)
def test_a_damaged_sweep_file_is_run_again_with_a_warning(tmp_path, batches_run, damage):
    whole, kept = _sweep_file_alone(tmp_path)
    doc = json.loads(kept.read_text())
    damage(doc)
    kept.write_text(json.dumps(doc))
    batches_run.clear()
    with pytest.warns(UserWarning, match="running its sweep again"):
        _same(_study_sweep(tmp_path), whole)
    assert batches_run == [[0, 1, 2], [3]]
    assert len(json.loads(kept.read_text())["results"][0]["pf"]["run_rmse"]) == 4  # rewritten


def test_the_keys_are_the_digests_that_named_the_files_before_them(tmp_path):
    """Batch and sweep files (papers/manoeuvres/results/checkpoint) were named by these digests
    before :meth:`Checkpoint.key` computed them: they are found by it."""
    cfgs, runs = _cfgs(runs=4), list(range(4))
    what = {
        "configs": [c.model_dump(mode="json", exclude={"runs"}) for c in cfgs],
        "truth_files": [None, None],
        "filters": NAMES,
        "code": code_digest(),
        "plugins": plugin_digest(),
        "environment": environment(),
    }

    def digest(text):
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    kept = Checkpoint(tmp_path, cfgs, NAMES)
    machine = digest(f"{json.dumps(what, sort_keys=True)}|{runs}")
    assert kept.path(runs).name == f"batch-{machine}.pkl" and kept.key(runs) == machine
    del what["environment"]
    finished = Finished(tmp_path, cfgs, NAMES, 3, True)
    assert finished.file.name == f"sweep-{machine}-b3-timed.json"
    assert finished.key == digest(f"{json.dumps(what, sort_keys=True)}|{runs}|-b3-timed")


def _prefix_alone(folder, cfgs):
    """The sweep of ``cfgs`` stopped after its first merged batch, every batch file deleted: what
    a copy of its prefix file alone carries; that file."""
    _stopped(cfgs, folder)
    _drop(folder, "batch-*.pkl")
    file, doc = _prefix(folder)
    assert doc["batches"] == 1
    return file


def test_a_stopped_sweep_resumes_from_its_prefix_file_alone(tmp_path, batches_run):
    cfgs = _cfgs()
    whole = _sweep(cfgs, tmp_path / "whole")
    _prefix_alone(tmp_path, cfgs)
    batches_run.clear()
    heard: list[int] = []
    resumed = run_sweep(
        cfgs, NAMES, batch_size=3, workers=1, time_steps=False, checkpoint=tmp_path,
        progress=heard.append,
    )  # fmt: skip
    _same(resumed, whole)
    assert batches_run == [[3, 4, 5], [6]]
    assert heard == [3, 3, 1]  # the prefix's runs at once
    # every statistic of every filter, bit for bit: the prefixes of both are the same file
    file, doc = _prefix(tmp_path)
    assert doc["batches"] == 2  # the full batches: [6] is not one of a longer sweep
    assert file.read_bytes() == (tmp_path / "whole" / file.name).read_bytes()


def test_a_longer_sweep_goes_on_from_a_shorter_ones_prefix(tmp_path, batches_run):
    _sweep(_cfgs(runs=7), tmp_path)  # batches of 3, 3 and 1: a prefix of the first two
    _drop(tmp_path, "batch-*.pkl")
    batches_run.clear()
    _same(_sweep(_cfgs(runs=10), tmp_path), _sweep(_cfgs(runs=10)))
    assert batches_run[:2] == [[6, 7, 8], [9]]  # the 7-run sweep's [6] is not a batch here
    assert _prefix(tmp_path)[1]["batches"] == 3
    batches_run.clear()
    with pytest.warns(UserWarning, match="of a longer sweep, .* neither used nor overwritten"):
        _sweep(_cfgs(runs=4), tmp_path)
    assert batches_run == [[0, 1, 2], [3]]
    assert _prefix(tmp_path)[1]["batches"] == 3


def test_a_prefix_made_on_another_machine_is_read_with_a_warning(tmp_path, batches_run):
    cfgs = _cfgs()
    whole = _sweep(cfgs)
    _as_another_cpus(_prefix_alone(tmp_path, cfgs), "prefix")
    batches_run.clear()
    with pytest.warns(UserWarning, match=r"another environment \(cpu differ; CPU another-cpu"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == [[3, 4, 5], [6]]
    # the prefix that continued it, of this machine's name, says that it is partly another's
    with pytest.warns(UserWarning, match=r"were made in another environment \(cpu differ"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == [[3, 4, 5], [6]]
    _drop(tmp_path, "batch-*.pkl")
    _sweep(_cfgs(runs=6, seed=5), tmp_path)  # another sweep: not that file's, nor this one's
    assert batches_run[2:] == [[0, 1, 2], [3, 4, 5]]


def test_a_sweep_back_on_a_machine_it_ran_on_names_the_other_machine(tmp_path, batches_run):
    """Carried A -> B -> A, the prefix lists A among the environments that made it: the warning
    compared A with A and said "( differ; CPU a, here a)"."""
    from tltrack.engine.checkpoint import environment

    cfgs = _cfgs()
    whole = _sweep(cfgs)
    _as_another_cpus(_prefix_alone(tmp_path, cfgs), "prefix")
    with pytest.warns(UserWarning, match="another environment"):
        _sweep(cfgs, tmp_path)  # this machine's prefix, partly another's
    (file, doc), *_ = [
        (p, d)
        for p in tmp_path.glob("prefix-*.json")
        if (d := json.loads(p.read_text()))["made"]["environment"] == environment()
    ]  # this machine's, beside the other's
    doc["made"]["elsewhere"] = [environment(), *doc["made"]["elsewhere"]]  # A first, then B
    file.write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match=r"another environment \(cpu differ; CPU another-cpu"):
        _same(_sweep(cfgs, tmp_path), whole)


def test_of_one_prefix_per_machine_the_longest_is_read(tmp_path, batches_run):
    """A sweep carried from machine to machine leaves a prefix file on each: the next goes on
    from the one that got furthest, whatever the files' names, this machine's own included."""
    cfgs = _cfgs(runs=10)  # batches of 3, 3, 3 and 1
    whole = _sweep(cfgs)
    own = _prefix_alone(tmp_path / "one", cfgs)  # the first batch, in this machine's file
    _sweep(_cfgs(runs=6), tmp_path / "two")  # the first two
    for name, made_of, cpu in [
        (own.name, own, None),
        ("prefix-000000000000000000000000-b3.json", _prefix(tmp_path / "two")[0], "cpu-a"),
        ("prefix-fff000000000000000000000-b3.json", own, "cpu-b"),
    ]:
        doc = json.loads(made_of.read_text())
        if cpu:
            doc["made"]["environment"]["cpu"] = cpu
        (tmp_path / name).write_text(json.dumps(doc))
    batches_run.clear()
    with pytest.warns(UserWarning, match=r"prefix-0{24}-b3.json: this sweep's first .*CPU cpu-a"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == [[6, 7, 8], [9]]


def test_the_prefix_holds_every_full_batch_when_the_short_one_finished_first(tmp_path):
    """The last full batch and a short last batch that finished before it were merged at once,
    and the prefix, which holds full batches only, was not written: the 200-run clutter sweeps
    kept 14 of their 15 full batches (182 runs, not 195) for the 1000-run ones."""
    cfgs = _cfgs(runs=10)  # batches of 3, 3, 3 and 1
    _sweep(cfgs, tmp_path)
    _drop(tmp_path, "prefix-*.json")
    short = Checkpoint(tmp_path, cfgs, NAMES).path([9]).name
    for file in tmp_path.glob("batch-*.pkl"):
        if file.name != short:
            file.unlink()  # the short batch alone is read back: it is done before the others
    _sweep(cfgs, tmp_path)
    assert _prefix(tmp_path)[1]["batches"] == 3


@pytest.mark.parametrize(
    "damage", ["cut short", "a run short", "nested too deeply", "no environment"]
)  # the last two were a RecursionError's and a KeyError's traceback
def test_a_damaged_prefix_file_is_ignored_with_a_warning(tmp_path, batches_run, damage):
    cfgs = _cfgs()
    whole = _sweep(cfgs)
    file = _prefix_alone(tmp_path, cfgs)
    if damage == "cut short":
        file.write_bytes(file.read_bytes()[:100])
    elif damage == "nested too deeply":
        file.write_text("[" * 100_000 + "]" * 100_000)
    elif damage == "no environment":
        doc = json.loads(file.read_text())
        del doc["made"]["environment"]
        file.write_text(json.dumps(doc))
    else:
        doc = json.loads(file.read_text())
        doc["stats"][0]["pf"]["run_mse"][0].pop()
        file.write_text(json.dumps(doc))
    batches_run.clear()
    with pytest.warns(UserWarning, match="unreadable .* ignored"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert batches_run == [[0, 1, 2], [3, 4, 5], [6]]
    assert _prefix(tmp_path)[1]["batches"] == 2  # rewritten


def _bits(value):
    """``value``'s type and bits: arrays by dtype, shape and bytes, floats by their 8 bytes."""
    if isinstance(value, np.ndarray):
        return ("array", value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, list):
        return [_bits(v) for v in value]
    return type(value).__name__, struct.pack("<d", value) if isinstance(value, float) else value


@pytest.mark.filterwarnings("error")
def test_every_filter_kinds_statistics_round_trip_through_json():
    # K past one NIS window, an rpf that regularises: every field holds something
    cfg = make_config(
        {"preset": "arasaratnam-haykin", "K": 24, "particles": 60, "rpf_bandwidth": 0.5}
    )
    names = [f"{role}{kind}" for kind in FILTERS.names() for role in ("", "tl-")]
    stats = run_batch(cfg, names, [0, 1], timing=True, keep_tracks=True)
    assert set(names) <= set(stats)
    assert stats["tl-rpf"].regularised and stats["tl-pf"].windows and stats["pf"].tracks
    odd = stats["pf"]  # what a diverged or empty run leaves
    odd.sq_err[0], odd.nees[1], odd.run_mse[0][0] = np.nan, np.inf, -0.0
    odd.nis_sum = float("nan")
    fields = [f.name for f in dataclasses.fields(FilterStats)]
    for name, s in stats.items():
        doc = s.to_json()
        assert list(doc) == fields
        back = FilterStats.from_json(json.loads(json.dumps(doc)))
        for f in fields:
            assert _bits(getattr(back, f)) == _bits(getattr(s, f)), (name, f)
    with pytest.raises(ValueError, match=r"sums of \(24,\) and \(24,\) steps, K = 23"):
        FilterStats.from_json({**stats["ukf"].to_json(), "K": 23})
