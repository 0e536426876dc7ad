import pytest
from tltrack.app import app
from typer.testing import CliRunner


# the whole reproduction (every N to 6000): over a minute, so not in make check's unit tier
@pytest.mark.system
def test_reproduce_writes_every_table_and_figure(tmp_path):
    # --workers 1: this process alone (a pool of every core is slower beside other tests)
    args = ["reproduce", "--runs", "2", "--workers", "1", "--out", str(tmp_path)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    report = (tmp_path / "report.md").read_text()
    for heading in (
        "Table 2",
        "RMSE(k) at the steps",
        "against I_p",
        "Delta RMSE",
        "lost track",
        "Lost tracks under each preset",
    ):
        assert heading in report, heading
    for png in (
        "fig_s1_rmse",
        "fig_s2_rmse",
        "fig_rmse_vs_ip",
        "fig_delta_rmse",
        "fig_rmse_time_vs_n",
    ):
        assert (tmp_path / f"{png}.png").stat().st_size > 10_000
    assert "16.7473" in report  # the paper's number stands beside ours


@pytest.mark.unit
def test_the_ip_sweep_and_a_repeated_job_share_one_run_each(tmp_path):
    from tltrack.config import make_config
    from tltrack.engine.montecarlo import run_experiment
    from tltrack.studies import reproduce as rep

    base = rep.base_config("arasaratnam-haykin", "noise-free", runs=3, seed=1)
    groups = rep.sweeps(rep.jobs(base) + rep.loss_jobs(base))
    labels = [[j.label for j in g] for g in groups]
    assert [f"s2_ip{i}" for i in rep.INTENSITIES] + ["loss_arasaratnam-haykin_noise-free"] in labels
    assert len(groups) == 1 + 1 + 3 + 5  # s1, the I_p sweep, three other N, five other losses

    cfg = make_config(preset="arasaratnam-haykin", K=8, particles=100, runs=3, seed=2)
    todo = [
        rep.Job("a", cfg.with_(primary_intensity=2), ["pf", "tl-pf", "tl-ukf"]),
        rep.Job("b", cfg, ["pf", "tl-pf", "tl-ukf"]),
        rep.Job("dup", cfg, ["tl-pf"]),
    ]
    docs = rep.run_all(todo, tmp_path, workers=1)
    assert set(docs["dup"]["filters"]) == {"source-pf", "tl-pf"}
    dup, b = docs["dup"]["filters"]["tl-pf"], docs["b"]["filters"]["tl-pf"]
    assert dup["rmse_per_step"] == b["rmse_per_step"]
    alone = run_experiment(todo[0].cfg, todo[0].filters, workers=1, time_steps=False)
    for name, r in alone.items():
        assert docs["a"]["filters"][name]["rmse_per_step"] == r.rmse_per_step, name
    assert rep.wall_minutes(docs) == docs["a"]["wall_s"] / 60  # one sweep, counted once


@pytest.mark.unit
def test_the_lost_track_table_alone_has_both_particle_filters_and_the_ukf(tmp_path):
    r = CliRunner().invoke(
        app, ["reproduce", "--runs", "2", "--losses-only", "--workers", "1", "--out", str(tmp_path)]
    )
    assert r.exit_code == 0, r.output
    table = (tmp_path / "losses.md").read_text()
    header = next(ln for ln in table.splitlines() if ln.startswith("| preset | truth | runs"))
    for name in ("source-pf", "tl-pf", "source-rpf", "tl-rpf", "robust-tl-rpf", "tl-ukf"):
        assert f"| {name} |" in header + " |", name
    rows = [ln for ln in table.splitlines() if ln.startswith(("| paper |", "| arasaratnam"))]
    assert len(rows) == 2 * 6  # both presets, three truth modes, lost shares then RMSE
    both = ["reproduce", "--runs", "2", "--losses-only", "--table2-pf-only"]
    assert CliRunner().invoke(app, [*both, "--out", str(tmp_path)]).exit_code == 2
