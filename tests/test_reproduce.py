import pytest
from tltrack.cli import app
from typer.testing import CliRunner

pytestmark = pytest.mark.slow


def test_reproduce_writes_every_table_and_figure(tmp_path):
    r = CliRunner().invoke(app, ["reproduce", "--runs", "2", "--out", str(tmp_path)])
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
