"""RMSE, latency, transfer use, gaps and rejected messages, computed from the store alone.

RMSE follows the paper: RMSE(k) = sqrt(mean over episodes of the squared position error at k),
overall = mean over k. Latency is end to end: sensor timestamp to the estimate's arrival here
(meaningful on one host; across hosts it needs synchronised clocks). ``stages_ms`` splits it into
the p50 of each stage of :mod:`tltrack.live.latency`. Each step's error and latency are those of
:mod:`tltrack.live.scores`, which ``tltrack scores --jsonl`` writes one by one.

Each episode is scored on its own, from its rows alone (read through the tables' primary keys), and
a :class:`Summarizer` keeps the scores of the episodes the scorer has finished with: a summary then
reads only the episodes under way, however many the store holds (``benchmarks/scorer_summary.py``
times both ways).
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Container
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tltrack.config import make_config
from tltrack.config.timeline import Timeline
from tltrack.engine.names import operator_of
from tltrack.filters import consistency
from tltrack.live import latency
from tltrack.live.scores import squared_error
from tltrack.services.scorer.store import Store


def _rmse(k: NDArray[np.int64], sq: NDArray[np.float64]) -> dict[str, Any]:
    """RMSE(k) = sqrt(mean over episodes of the squared error at k), and its mean over k."""
    if len(k) == 0:
        return {"rmse_overall": None, "rmse_per_step": []}
    _steps, at = np.unique(k, return_inverse=True)
    per_step = np.sqrt(np.bincount(at, weights=sq) / np.bincount(at))
    return {"rmse_overall": float(np.mean(per_step)), "rmse_per_step": per_step.tolist()}


@dataclass(frozen=True)
class _Scores:
    """One filter's record in one episode, as arrays, so that a summary over many episodes
    concatenates them instead of looping over rows."""

    k: NDArray[np.int64]  #: the steps with both an estimate and the truth
    sq: NDArray[np.float64]  #: their squared position errors
    steps: int
    expected: int  #: the steps its operator took (K on the paper's shared clock)
    used: int
    recoveries: int
    end_to_end: NDArray[np.float64]  #: ms, one per step
    split: NDArray[np.float64]  #: (n, 5) :func:`tltrack.live.latency.stages`, ms
    nis: NDArray[np.float64]  #: the NIS of the filter's own z_k, at each step that had one
    #: at each step with a full window: was its mean above (1), below (-1) or in (0) its band
    band: NDArray[np.int64]


def episode_timeline(store: Store, episode: str) -> Timeline:
    """When each operator of ``episode`` sampled, from its stored config."""
    (config,) = store.rows("SELECT config FROM episodes WHERE episode = ?", episode)[0]
    return make_config(json.loads(config)).timeline


def episode_scores(store: Store, episode: str) -> dict[str, _Scores]:
    """Every filter's scores in ``episode``, from its rows alone: each estimate against the
    truth at its operator's sample (on the paper's shared clock, the truth's own step)."""
    timeline = episode_timeline(store, episode)
    sources = [sid for sid in timeline.clocks if sid != timeline.primary]
    truth = {
        k: json.loads(pos)
        for k, pos in store.rows(
            "SELECT k, pos FROM truth WHERE episode = ? AND pos IS NOT NULL", episode
        )
    }
    rows: dict[str, list[tuple[Any, ...]]] = defaultdict(list)
    for row in store.rows(
        "SELECT filter, k, pos, transfer_used, recovered, t_sensor, t_recv, t_sent, step_ms,"
        " t_received, t_step, nis, nis_window, nis_band FROM estimates WHERE episode = ?",
        episode,
    ):
        rows[row[0]].append(row[1:])
    scores = {}
    for name, mine in rows.items():  # (episode, filter, k) is the key: one row per step
        operator = operator_of(name, sources)
        if operator not in timeline.clocks:  # a source the episode's config does not name
            operator = timeline.primary  # is scored at the primary's samples
        k, sq, split, nis, band = [], [], [], [], []
        for row in mine:
            step, pos, _tu, _rec, t_sensor, t_recv, t_sent, step_ms, t_received, t_step = row[:10]
            row_nis, window, edges = row[10:]
            if row_nis is not None:
                nis.append(row_nis)
            if window is not None and edges is not None:
                lo, hi = json.loads(edges)
                band.append(1 if window > hi else -1 if window < lo else 0)
            tick = timeline.tick(operator, step)
            if tick in truth and pos is not None:
                k.append(step)
                sq.append(squared_error(json.loads(pos), truth[tick]))
            if t_received is not None and t_step is not None:
                split.append(latency.stages(t_sensor, t_received, t_step, step_ms, t_sent, t_recv))
        scores[name] = _Scores(
            k=np.array(k, dtype=np.int64),
            sq=np.array(sq),
            steps=len(mine),
            expected=timeline.steps(operator),
            used=sum(r[2] for r in mine),
            recoveries=sum(r[3] or 0 for r in mine),
            end_to_end=np.array([latency.end_to_end_ms(r[4], r[5]) for r in mine]),
            split=np.array(split).reshape(-1, len(latency.STAGES)),
            nis=np.array(nis),
            band=np.array(band, dtype=np.int64),
        )
    return scores


def _consistency(nis: NDArray[np.float64], band: NDArray[np.int64]) -> dict[str, Any]:
    """The mean NIS, the shares of full windows above and below their band, and the verdict
    (:func:`tltrack.filters.consistency.verdict`)."""
    above = float(np.mean(band > 0)) if len(band) else 0.0
    below = float(np.mean(band < 0)) if len(band) else 0.0
    return {
        "nis": float(np.mean(nis)) if len(nis) else None,
        "nis_above_band": above,
        "nis_below_band": below,
        "consistency": consistency.verdict(above, below) if len(band) else None,
    }


class Summarizer:
    """Summaries of a growing store. The scores of an episode named ``final`` are kept after it
    is read; a row that still arrives for it must be followed by :meth:`forget`."""

    def __init__(self, store: Store) -> None:
        self.store = store
        self._kept: dict[str, dict[str, _Scores]] = {}
        self._timelines: dict[str, Timeline] = {}

    def forget(self, episode: str) -> None:
        self._kept.pop(episode, None)

    def timeline(self, episode: str) -> Timeline:
        """:func:`episode_timeline`, read once per episode."""
        if episode not in self._timelines:
            self._timelines[episode] = episode_timeline(self.store, episode)
        return self._timelines[episode]

    def summary(
        self, episodes: list[str] | None = None, final: Container[str] = ()
    ) -> dict[str, Any]:
        """The summary over ``episodes`` (default: all in the store)."""
        eps = self.store.rows(
            "SELECT episode, run, K, ended, end_reason FROM episodes ORDER BY started"
        )
        if episodes is not None:
            eps = [e for e in eps if e[0] in episodes]
        per_episode = []
        for ep, *_ in eps:
            scores = self._kept.get(ep)
            if scores is None:
                scores = episode_scores(self.store, ep)
                if ep in final:
                    self._kept[ep] = scores
            per_episode.append(scores)
        filters = {}
        end_to_end = [np.empty(0)]  # every filter's, for the overall latency
        split = [np.empty((0, len(latency.STAGES)))]
        for name in sorted({n for scores in per_episode for n in scores}):
            mine = [scores[name] for scores in per_episode if name in scores]
            end_to_end.append(np.concatenate([s.end_to_end for s in mine]))
            split.append(np.concatenate([s.split for s in mine]))
            steps = sum(s.steps for s in mine)
            # an episode without this filter's rows expected K of it
            expected = sum(
                sc[name].expected if name in sc else e[2]
                for sc, e in zip(per_episode, eps, strict=True)
            )
            filters[name] = {
                **_rmse(np.concatenate([s.k for s in mine]), np.concatenate([s.sq for s in mine])),
                "steps": steps,
                "gaps": expected - steps,
                "steps_with_transfer": sum(s.used for s in mine),
                "recoveries": sum(s.recoveries for s in mine),
                "latency_ms": latency.percentiles(end_to_end[-1]),
                "stages_ms": latency.p50(split[-1]),
                **_consistency(
                    np.concatenate([s.nis for s in mine]), np.concatenate([s.band for s in mine])
                ),
            }
        rejected: dict[str, dict[str, int]] = {}
        empty: dict[str, int] = {}  #: scans with no detection each tracker stepped through
        dropped = 0
        for operator, service, _t, stats in self.store.rows("SELECT * FROM service_stats"):
            st = json.loads(stats)
            rejected[f"{operator}/{service}"] = st.get("rejected", {}).get("by_reason", {})
            dropped += int(st.get("dropped", 0))
            if n := int(st.get("counters", {}).get("empty_scans", 0)):
                empty[f"{operator}/{service}"] = n
        return {
            "episodes": [
                {"episode": e, "run": r, "K": K, "complete": reason == "complete"}
                for e, r, K, _ended, reason in eps
            ],
            "filters": filters,
            "latency_ms": latency.percentiles(np.concatenate(end_to_end)),
            "stages_ms": latency.p50(np.concatenate(split)),
            "messages": {
                "rejected": rejected,
                "rejected_total": sum(sum(v.values()) for v in rejected.values()),
                "dropped": dropped,
                "missing_estimates": sum(f["gaps"] for f in filters.values()),
                "empty_scans": empty,
            },
        }
