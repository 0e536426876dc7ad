"""The scorer's SQLite file: every record it accepted, durable across crashes (WAL mode).

Records are keyed by (episode, k) and (episode, filter, k) and written with INSERT OR IGNORE, so a
replayed message is harmless and a restart picks up where the file left off. Nothing is ever
interpolated: a step that never arrived is simply absent, and shows as a gap.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

from tltrack.wire.messages import EpisodeEnd, EpisodeStart, EstimateMsg, Truth

SCHEMA = """
CREATE TABLE IF NOT EXISTS episodes (
    episode TEXT PRIMARY KEY, run INTEGER, K INTEGER, config TEXT,
    started REAL, ended REAL, end_reason TEXT);
CREATE TABLE IF NOT EXISTS truth (
    episode TEXT, k INTEGER, x TEXT, t_sensor REAL, pos TEXT, PRIMARY KEY (episode, k));
CREATE TABLE IF NOT EXISTS estimates (
    episode TEXT, filter TEXT, k INTEGER, x TEXT, P TEXT, transfer_used INTEGER,
    t_sensor REAL, t_sent REAL, t_recv REAL, step_ms REAL, pos TEXT, recovered INTEGER,
    t_received REAL, t_step REAL, nis REAL, nis_window REAL, nis_band TEXT,
    PRIMARY KEY (episode, filter, k));
CREATE TABLE IF NOT EXISTS service_stats (
    operator TEXT, service TEXT, t REAL, stats TEXT, PRIMARY KEY (operator, service));
"""


class Store:
    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.executescript(SCHEMA)
        added = [("truth", "pos", "TEXT"), ("estimates", "pos", "TEXT")]
        added += [("estimates", "recovered", "INTEGER")]
        added += [("estimates", "t_received", "REAL"), ("estimates", "t_step", "REAL")]
        added += [("estimates", "nis", "REAL"), ("estimates", "nis_window", "REAL")]
        added += [("estimates", "nis_band", "TEXT")]
        for table, column, kind in added:  # a file from before these fields
            columns = [row[1] for row in self.db.execute(f"PRAGMA table_info({table})")]
            if column not in columns:
                self.db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")
        self.db.execute("BEGIN")

    def commit(self) -> None:
        """Make everything so far durable; the scorer calls it whenever its inbox runs dry."""
        self.db.execute("COMMIT")
        self.db.execute("BEGIN")

    def episode_start(self, m: EpisodeStart) -> bool:
        cur = self.db.execute(
            "INSERT OR IGNORE INTO episodes (episode, run, K, config, started) VALUES (?,?,?,?,?)",
            (m.episode, m.run, m.K, json.dumps(m.config), m.t_sensor),
        )
        return cur.rowcount == 1

    def episode_end(self, m: EpisodeEnd) -> None:
        self.db.execute(
            "UPDATE episodes SET ended = ?, end_reason = ? WHERE episode = ?",
            (m.t_sensor, m.reason, m.episode),
        )

    def truth(self, m: Truth) -> bool:
        cur = self.db.execute(
            "INSERT OR IGNORE INTO truth (episode, k, x, t_sensor, pos) VALUES (?,?,?,?,?)",
            (m.episode, m.k, json.dumps(m.x), m.t_sensor, json.dumps(m.pos)),
        )
        return cur.rowcount == 1

    def estimate(self, m: EstimateMsg, t_recv: float) -> bool:
        cur = self.db.execute(
            "INSERT OR IGNORE INTO estimates (episode, filter, k, x, P, transfer_used,"
            " t_sensor, t_sent, t_recv, step_ms, pos, recovered, t_received, t_step, nis,"
            " nis_window, nis_band) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                m.episode,
                m.filter,
                m.k,
                json.dumps(m.x),
                json.dumps(m.P),
                int(m.transfer_used),
                m.t_sensor,
                m.t_sent,
                t_recv,
                m.step_ms,
                json.dumps(m.pos),
                int(m.recovered),
                m.t_received,
                m.t_step,
                m.nis,
                m.nis_window,
                None if m.nis_band is None else json.dumps(m.nis_band),
            ),
        )
        return cur.rowcount == 1

    def service_stats(self, operator: str, service: str, t: float, stats: dict[str, Any]) -> None:
        self.db.execute(
            "INSERT OR REPLACE INTO service_stats VALUES (?,?,?,?)",
            (operator, service, t, json.dumps(stats)),
        )

    def rows(self, sql: str, *args: Any) -> list[tuple[Any, ...]]:
        return self.db.execute(sql, args).fetchall()

    def close(self) -> None:
        self.db.execute("COMMIT")
        self.db.close()
