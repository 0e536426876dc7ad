"""A sweep stopped part-way resumes from its checkpoint folder, to the uninterrupted numbers."""

import json

import pytest
from tltrack.app import app
from tltrack.config import make_config
from tltrack.engine import montecarlo
from tltrack.engine.montecarlo import run_sweep
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


@pytest.fixture
def batches_run(monkeypatch):
    """The runs of every batch that the engine actually ran (not read back)."""
    seen: list[list[int]] = []
    real = montecarlo.run_sweep_batch

    def counted(cfgs, names, runs, **kw):
        seen.append(list(runs))
        return real(cfgs, names, runs, **kw)

    monkeypatch.setattr(montecarlo, "run_sweep_batch", counted)
    return seen


def _same(a, b):
    for x, y in zip(a, b, strict=True):
        assert x.keys() == y.keys()
        for name in x:
            assert x[name].run_rmse == y[name].run_rmse, name
            assert list(x[name].rmse_per_step) == list(y[name].rmse_per_step), name
            assert x[name].lost_fraction == y[name].lost_fraction, name


def test_a_stopped_sweep_resumes_to_the_uninterrupted_numbers(tmp_path, batches_run):
    cfgs = _cfgs()
    whole = _sweep(cfgs)
    batches_run.clear()

    calls = []

    def stop_after_two(n):
        calls.append(n)
        if len(calls) == 2:
            raise StopError  # as a kill would, after the second batch was kept

    with pytest.raises(StopError):
        run_sweep(
            cfgs, NAMES, batch_size=3, workers=1, time_steps=False, checkpoint=tmp_path,
            progress=stop_after_two,
        )  # fmt: skip
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
    victim = sorted(tmp_path.glob("batch-*.pkl"))[0]
    victim.write_bytes(victim.read_bytes()[:40])  # as a disk that filled up might leave it
    batches_run.clear()
    with pytest.warns(UserWarning, match="unreadable"):
        _same(_sweep(cfgs, tmp_path), whole)
    assert len(batches_run) == 1


def test_the_cli_resumes_an_experiment_from_its_checkpoint(tmp_path):
    keep = tmp_path / "keep"
    args = ["experiment", "--preset", "arasaratnam-haykin", "--filters", "pf,tl-pf"]
    args += ["--runs", "4", "--particles", "150", "--batch-size", "2", "--workers", "1"]
    args += ["--checkpoint", str(keep)]
    first = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "a")])
    assert first.exit_code == 0, first.output
    assert len(list(keep.glob("batch-*.pkl"))) == 2
    again = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "b")])
    assert again.exit_code == 0, again.output
    a, b = (json.loads((tmp_path / d / "results.json").read_text()) for d in "ab")
    for name in ("pf", "tl-pf"):
        assert a["filters"][name]["run_rmse"] == b["filters"][name]["run_rmse"]
