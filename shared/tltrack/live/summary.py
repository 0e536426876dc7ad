"""The scorer's summary as a table: printed by the scorer after each episode and by ``demo``."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def table(summary: dict[str, Any]) -> Table:
    eps = summary.get("episodes", [])
    t = Table(title=f"tltrack scorer: {len(eps)} episode(s)")
    for col in (
        "filter",
        "RMSE [m]",
        "steps",
        "gaps",
        "with transfer",
        "p50 ms",
        "p95 ms",
        "p99 ms",
        "NIS",
    ):
        t.add_column(col, justify="left" if col == "filter" else "right")
    for name, f in summary.get("filters", {}).items():
        lat = f["latency_ms"]
        rmse = f["rmse_overall"]
        t.add_row(
            name,
            "-" if rmse is None else f"{rmse:.2f}",
            str(f["steps"]),
            str(f["gaps"]),
            str(f["steps_with_transfer"]),
            _ms(lat["p50"]),
            _ms(lat["p95"]),
            _ms(lat["p99"]),
            _ms(f.get("nis")),
        )
    m = summary.get("messages", {})
    lat = summary.get("latency_ms", {})
    access = summary.get("access_control")
    stages = summary.get("stages_ms") or {}
    where = ", ".join(f"{name} {_ms(v)}" for name, v in stages.items() if v is not None)
    t.caption = (
        f"latency p50/p95/p99: {_ms(lat.get('p50'))}/{_ms(lat.get('p95'))}/"
        f"{_ms(lat.get('p99'))} ms"
        + (f" (p50 by stage, ms: {where})" if where else "")
        + f"; rejected {m.get('rejected_total', 0)}, "
        f"dropped {m.get('dropped', 0)}, missing estimates {m.get('missing_estimates', 0)}"
        + ("" if access is None else f"; access control {'on' if access else 'OFF'}")
    )
    return t


def warnings(summary: dict[str, Any]) -> list[str]:
    """What the NIS says of each filter whose model does not fit (the consistency monitor)."""
    return [
        f"{name}: {f['consistency']}"
        for name, f in summary.get("filters", {}).items()
        if f.get("consistency")
    ]


def print_summary(summary: dict[str, Any]) -> None:
    console = Console(width=110)
    console.print(table(summary))
    for line in warnings(summary):
        console.print(f"[yellow]warning:[/yellow] {line}")
