"""The registry of filter kinds: the posterior approximations a role may run.

A filter kind is a class with the :class:`~tltrack.filters.base.Filter` interface that declares
``kind`` (its name in ``--filters``, e.g. ``pf`` in ``tl-pf``), ``particle`` (it draws particles:
it takes N and one random stream per run, and the particle-only options, centralized fusion and
lost-track recovery, apply), ``parameters`` (:class:`~tltrack.declare.Parameter`; their values
come from the config) and ``build``. Plugins register through the entry-point group
``tltrack.filters``.
"""

from __future__ import annotations

from typing import Any

from tltrack.declare import Registry


def _check(cls: Any) -> None:
    missing = [n for n in ("kind", "particle", "parameters", "build") if not hasattr(cls, n)]
    if missing:
        raise ValueError(f"{cls!r} is not a filter kind: it does not declare {', '.join(missing)}")
    if "-" in cls.kind and cls.kind.split("-")[0] in ("tl", "source", "fusion", "robust"):
        raise ValueError(f"filter kind {cls.kind!r} must not start with a role's prefix")


def _builtins() -> list[Any]:
    """The package's filter kinds, imported when a kind is first asked for: the config names
    filters, so every service imports this registry, and most of them never filter."""
    from tltrack.filters.auxiliary import AuxiliaryParticleFilter
    from tltrack.filters.particle import ParticleFilter
    from tltrack.filters.sigma_point import (
        CubatureKalmanFilter3,
        CubatureKalmanFilter5,
        UnscentedKalmanFilter,
    )

    return [
        ParticleFilter,
        AuxiliaryParticleFilter,
        UnscentedKalmanFilter,
        CubatureKalmanFilter3,
        CubatureKalmanFilter5,
    ]


#: filter kind -> its class
FILTERS: Registry[Any] = Registry(
    "filter",
    "tltrack.filters",
    _builtins,
    name_of=lambda cls: cls.kind,
    check=_check,
)
