"""Filter names, as the CLI and the services spell them, and how to build each one.

A name is ``[role-]kind``: the kind is the posterior approximation (``pf``, the paper's bootstrap
SIR; ``rpf``, the auxiliary particle filter that keeps the track, docs/rpf.md; ``ukf``, ``ckf3``,
``ckf5``) and the role is how it is fed:

- no prefix: the isolated primary, its own measurement only;
- ``tl-``: the primary with every source's transfer (Algorithm 2 / the stacked TL-KF update);
- ``source-``: a source operator's filter (Algorithm 1); by default of the same kind as its TL
  primary, or of the kind its config names (``sources[].filter``, ``--source-filter``);
- ``fusion-``: centralized fusion, the primary given every source's *raw* measurement too. It is
  the bound that transfer trades away for privacy;
- ``robust-tl-``: TL that first decides which transfers to use (a consistency gate, and the
  optional communication budget of the config), see :mod:`tltrack.filters.decision`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from tltrack.config import PARTICLE_KINDS, Config, FilterKind
from tltrack.engine.streams import streams
from tltrack.filters.auxiliary import AuxiliaryParticleFilter
from tltrack.filters.base import Filter
from tltrack.filters.particle import ParticleFilter
from tltrack.filters.recovery import Recovery
from tltrack.filters.sigma_point import SigmaPointFilter, cubature3, cubature5, unscented
from tltrack.models.base import MotionModel

Kind = FilterKind
Role = Literal["isolated", "tl", "robust", "source", "fusion"]
KINDS: tuple[Kind, ...] = get_args(FilterKind)
_PREFIX: dict[str, Role] = {"tl": "tl", "source": "source", "fusion": "fusion"}


@dataclass(frozen=True)
class FilterSpec:
    name: str
    kind: Kind
    role: Role


def source_name(spec: FilterSpec, cfg: Config, source_id: str) -> str:
    """The filter of source ``source_id`` that a TL primary of ``spec``'s kind listens to."""
    kind = next((s.filter for s in cfg.sources if s.id == source_id), None) or spec.kind
    return f"source-{kind}"


def parse(name: str) -> FilterSpec:
    """``"tl-ckf5"`` -> FilterSpec("tl-ckf5", "ckf5", "tl"); refuses unknown names clearly."""
    if name.startswith("robust-tl-") and name[len("robust-tl-") :] in KINDS:
        return FilterSpec(name, name[len("robust-tl-") :], "robust")  # type: ignore[arg-type]
    prefix, _, rest = name.partition("-")
    role: Role = "isolated"
    kind = name
    if rest:
        if prefix not in _PREFIX:
            raise ValueError(f"unknown filter {name!r}; known: {', '.join(all_names())}")
        role, kind = _PREFIX[prefix], rest
    if kind not in KINDS or (role == "fusion" and kind not in PARTICLE_KINDS):
        raise ValueError(f"unknown filter {name!r}; known: {', '.join(all_names())}")
    return FilterSpec(name, kind, role)


def all_names() -> list[str]:
    names = [f"{p}{k}" for k in KINDS for p in ("", "tl-", "robust-tl-", "source-")]
    return [*names, "fusion-pf"]


def stream_purpose(spec: FilterSpec, source_id: str | None = None) -> str:
    """The random-stream purpose of a filter; a source's carries its operator id.

    The primary's variants of one kind (isolated, TL, robust, fusion) share their numbers: common
    random numbers, so that a run where the transfer changes nothing gives the isolated result
    exactly, and paired differences between them measure the transfer, not the dice.
    """
    return f"{spec.name}/{source_id}" if spec.role == "source" else spec.kind


def recovery(spec: FilterSpec, cfg: Config) -> Recovery | None:
    """The lost-track recovery of a particle filter, when the config asks for it."""
    return Recovery(np.diag(cfg.P0_diag)) if cfg.recovery and spec.kind in PARTICLE_KINDS else None


def build(
    spec: FilterSpec,
    cfg: Config,
    model: MotionModel,
    x0_hat: NDArray[np.float64],
    runs: Sequence[int],
    source_id: str | None = None,
) -> Filter:
    """A filter of ``spec``'s kind for the batch ``runs``, started at (x0_hat, P0)."""
    P0 = np.diag(cfg.P0_diag)
    if spec.kind in PARTICLE_KINDS:
        rngs = streams(cfg.seed, list(runs), stream_purpose(spec, source_id))
        if spec.kind == "pf":
            return ParticleFilter(model, x0_hat, P0, cfg.particles, rngs)
        return AuxiliaryParticleFilter(
            model, x0_hat, P0, cfg.particles, rngs, bandwidth=cfg.rpf_bandwidth
        )
    n = model.n
    rule = {
        "ukf": lambda: unscented(n, cfg.kappa),
        "ckf3": lambda: cubature3(n),
        "ckf5": lambda: cubature5(n),
    }[spec.kind]()
    return SigmaPointFilter(model, rule, x0_hat, P0)
