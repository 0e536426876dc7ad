"""The names filters are reported under, and whose filter a name is.

The engine, the live trackers, the scorer and the dashboard all speak of a filter by the name it
is reported under (``pf``, ``tl-rpf``, ``source-ukf``, ``source-ukf/s2``). The scorer and the
dashboard only read those names, so the rule lives here, apart from the filters: a service that
scores or draws never imports them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from tltrack.config import PRIMARY

if TYPE_CHECKING:
    from tltrack.engine.registry import FilterSpec


def reported_name(spec: FilterSpec, source_id: str, n_sources: int) -> str:
    """``source-pf`` for the paper's single source; ``source-pf/<id>`` when there are several."""
    return spec.name if n_sources == 1 else f"{spec.name}/{source_id}"


def operator_of(name: str, source_ids: Sequence[str]) -> str:
    """Whose filter a reported name is (:func:`reported_name`'s inverse): a source's id, or the
    primary's."""
    if not name.startswith("source-"):
        return PRIMARY
    return name.split("/", 1)[1] if "/" in name else source_ids[0]
