"""Filters over a batch of B independent runs, all with one interface (:class:`Filter`).

- :mod:`~tltrack.filters.particle`: the SIR particle filter (isolated, TL and fusion alike), with
  its compiled fast paths (:mod:`~tltrack.filters.fastpath`, :mod:`~tltrack.filters.kernels`),
  :mod:`~tltrack.filters.resampling` and lost-track :mod:`~tltrack.filters.recovery`;
- :mod:`~tltrack.filters.sigma_point`: UKF and CKFs (3rd, 5th degree) with the stacked TL update;
- :mod:`~tltrack.filters.transfer`: the source (Algorithm 1) and primary (Algorithm 2) roles;
- :mod:`~tltrack.filters.decision`: which transfers a robust primary uses.
"""

from tltrack.filters.base import Estimate, Filter

__all__ = ["Estimate", "Filter"]
