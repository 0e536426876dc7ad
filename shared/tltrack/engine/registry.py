"""Filter names, as the CLI and the services spell them, and how to build each one.

A name is ``[role-]kind``: the kind is the posterior approximation (``pf``, the paper's bootstrap
SIR; ``rpf``, the auxiliary particle filter that keeps the track, papers/rpf/README.md; ``ukf``,
``ckf3``, ``ckf5``) and the role is how it is fed:

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
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.declare import UnknownKindError
from tltrack.engine.setup import Setup
from tltrack.engine.streams import streams
from tltrack.filters.base import Filter
from tltrack.filters.imm import GaussianFilter, InteractingMultipleModel
from tltrack.filters.kinds import FILTERS
from tltrack.filters.recovery import Recovery

Role = Literal["isolated", "tl", "robust", "source", "fusion"]
_PREFIX: dict[str, Role] = {"tl": "tl", "source": "source", "fusion": "fusion"}


@dataclass(frozen=True)
class FilterSpec:
    name: str
    kind: str
    role: Role

    @property
    def particle(self) -> bool:
        """Does its kind draw particles (so fusion and recovery apply)?"""
        return bool(FILTERS.get(self.kind).particle)


def source_name(spec: FilterSpec, cfg: Config, source_id: str) -> str:
    """The filter of source ``source_id`` that a TL primary of ``spec``'s kind listens to."""
    kind = next((s.filter for s in cfg.sources if s.id == source_id), None) or spec.kind
    return f"source-{kind}"


def parse(name: str, *, trusted: bool = False) -> FilterSpec:
    """``"tl-ckf5"`` -> FilterSpec("tl-ckf5", "ckf5", "tl"); refuses unknown names clearly.

    ``trusted``: the name is the user's own, so installed plugin kinds are loaded first.
    """
    if name.startswith("robust-tl-"):
        role: Role = "robust"
        kind = name[len("robust-tl-") :]
    else:
        prefix, _, rest = name.partition("-")
        role, kind = (_PREFIX[prefix], rest) if rest and prefix in _PREFIX else ("isolated", name)
    try:
        cls = FILTERS.get(kind, trusted=trusted)
    except UnknownKindError:
        raise ValueError(f"unknown filter {name!r}; known: {', '.join(all_names())}") from None
    if role == "fusion" and not cls.particle:
        raise ValueError(f"{name!r}: centralized fusion is offered by particle filters only")
    return FilterSpec(name, cls.kind, role)


def all_names() -> list[str]:
    kinds = FILTERS.names()
    names = [f"{p}{k}" for k in kinds for p in ("", "tl-", "robust-tl-", "source-")]
    return [*names, *(f"fusion-{k}" for k in kinds if FILTERS.get(k).particle)]


def stream_purpose(spec: FilterSpec, source_id: str | None = None) -> str:
    """The random-stream purpose of a filter; a source's carries its operator id.

    The primary's variants of one kind (isolated, TL, robust, fusion) share their numbers: common
    random numbers, so that a run where the transfer changes nothing gives the isolated result
    exactly, and paired differences between them measure the transfer, not the dice. A kind that
    varies another (a proposal study's ``rpf-defensive``) may declare ``streams_of = "rpf"`` to
    draw that kind's numbers, so the two are paired run by run too.
    """
    kind = getattr(FILTERS.get(spec.kind), "streams_of", spec.kind)
    return f"source-{kind}/{source_id}" if spec.role == "source" else kind


def recovery(spec: FilterSpec, cfg: Config) -> Recovery | None:
    """The lost-track recovery of a particle filter, when the config asks for it."""
    return Recovery(np.diag(cfg.P0_diag)) if cfg.recovery and spec.particle else None


def build(
    spec: FilterSpec,
    setup: Setup,
    x0_hat: NDArray[np.float64],
    runs: Sequence[int],
    source_id: str | None = None,
    P0: NDArray[np.float64] | None = None,
) -> Filter:
    """A filter of ``spec``'s kind for the batch ``runs``, started at (x0_hat, P0) (default:
    the config's P0).

    With motion modes (config ``motion_modes``), a particle kind carries a mode per particle,
    and any other kind runs one filter per mode inside an interacting multiple-model filter.
    """
    cfg = setup.cfg
    cls = FILTERS.get(spec.kind)
    rngs = streams(cfg.seed, list(runs), stream_purpose(spec, source_id)) if cls.particle else None
    params = cfg.filter_parameters(spec.kind)
    P0, N = (setup.P0 if P0 is None else P0), cfg.particles
    modes = setup.modes
    if modes is None:
        return cls.build(setup.motion, x0_hat, P0, particles=N, rngs=rngs, params=params)
    if cls.particle:
        try:
            return cls.build(modes.models[0], x0_hat, P0, particles=N, rngs=rngs, params=params,
                             modes=modes)  # fmt: skip
        except TypeError:
            raise ValueError(f"filter kind {spec.kind} takes no motion_modes") from None
    each = [cls.build(m, x0_hat, P0, particles=N, rngs=None, params=params) for m in modes.models]
    if not all(isinstance(f, GaussianFilter) for f in each):
        raise ValueError(
            f"filter kind {spec.kind} takes no motion_modes: an interacting multiple-model filter "
            "mixes Gaussian filters (with m, P and loglik)"
        )
    return InteractingMultipleModel(each, modes.transition, modes.initial)
