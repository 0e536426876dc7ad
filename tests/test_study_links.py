"""``tltrack study links``: the cost of a lossy, late link, in the engine. A tiny study checks
what each cell's link does to the transfers: all on time up to a period of delay (the slack a
transfer made one step ahead has), about half late at one period with its jitter, none at two,
and a lost or late transfer never used."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from tltrack.studies import Runner, Setting
from tltrack.studies.links import cell_names, links

pytestmark = pytest.mark.unit

K, RUNS = 15, 3


def test_a_tiny_study_writes_its_table_numbers_and_plots(tmp_path: Path) -> None:
    ticks: list[int] = []
    path = links(Setting(runs=RUNS, particles=150), Runner(ticks.append, workers=1), tmp_path, K)
    assert sum(ticks) == RUNS * len(cell_names())
    assert "TL worse than the isolated filter" in path.read_text()
    for png in ("links_loss.png", "links_delay.png", "links_rates.png", "links_clocks.png"):
        assert (tmp_path / png).stat().st_size > 10_000
    cells = json.loads((tmp_path / "links.json").read_text())["cells"]
    used = {name: c["tl-pf"]["transfer_rate"] for name, c in cells.items()}
    perfect = (K - 1) / K  # every step but the first has a transfer
    assert used["loss 0%"] == pytest.approx(perfect)
    assert used["loss 90%"] < 0.4 * perfect
    for delay in ("delay 0 T", "delay 0.25 T", "delay 0.5 T"):  # at most T/2 + T/2 of jitter
        assert cells[delay]["tl-pf"] == cells["loss 0%"]["tl-pf"], delay
    assert 0.1 * perfect < used["delay 1 T"] < 0.9 * perfect  # 1 + U(0, 0.5) T against 1.25 T
    late = cells["delay 2 T"]
    assert used["delay 2 T"] == 0.0
    assert late["tl-pf"]["run_rmse"] == late["pf"]["run_rmse"]  # nothing used: the isolated pf
    assert late["tl_vs_isolated"] == [0.0, 0.0, "same"]
    # the clocks: a source 4 times slower steps at 4, 8, 12 T and sends for the primary's next
    # four samples, so steps 5..15 have a transfer; one 4 times faster sends for every step
    assert used["rates 1:4"] == pytest.approx((K - 4) / K)
    assert used["rates 4:1"] == 1.0  # its step a quarter period before the primary's first
    assert cells["rates 1:1"]["pf"] == cells["loss 0%"]["pf"]  # the paper's timeline
    assert cells["clock offset 0 T"]["pf"] == cells["loss 0%"]["pf"]  # the primary's own
    # a clock bound widens every transfer: the same runs, other transfers
    assert cells["clock offset 0 T"]["tl-pf"] != cells["loss 0%"]["tl-pf"]
