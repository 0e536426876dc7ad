"""Quantiles of the chi-square distribution: the gates and bands of every consistency test.

The PDA's validation gate, the lost-track test, the robust policy's tests and the NIS monitor's
band all read chi2_n^{-1}(p) for a few (p, n); cached, each costs a dictionary lookup after its
first use. SciPy's ``stats`` (about a third of a second to import) then loads only in a process
that tests something, not in every sensor, scorer and CLI call that imports the filters.
"""

from __future__ import annotations

import functools


@functools.cache
def quantile(p: float, dof: int) -> float:
    """x with P(chi2_dof <= x) = p."""
    from scipy.stats import chi2

    return float(chi2.ppf(p, dof))
