"""Numba kernels of the particle filter's fast path, one topic per module:

- :mod:`~.fastmath`: the compile options, and sin/cos, exp, log, atan2 as vectorisable polynomials;
- :mod:`~.gaussians`: standard normals by Box-Muller from each run's own uniforms;
- :mod:`~.propagation`: coordinated-turn and constant-velocity propagation, fused with the
  resampling's gather;
- :mod:`~.range_bearing`: range-bearing log-likelihoods and predicted-observation moments;
- :mod:`~.moments`: the mean and covariance of a cloud (weighted by offspring counts or not);
- :mod:`~.resample`: normalising log-weights and resampling systematically, run by run;
- :mod:`~.auxiliary`: the auxiliary particle filter's look-ahead and its two weighting stages;
- :mod:`~.scan`: a dense scan's likelihood, each detection added to the particles near it,
  found through a grid of the particles.

Which model takes which kernel is decided in one place, :mod:`tltrack.filters.fastpath`.

Why hand-written elementary functions: numba turns ``math.sin`` and friends into scalar libm calls,
which LLVM cannot vectorise without Intel's SVML (and this numba's LLVM is not patched for SVML at
all). sin/cos, atan2, exp and log are therefore written as branch-free polynomials (the
fdlibm/Cephes kernels, with Cody-Waite argument reduction), so every per-particle loop compiles to
SIMD code. Their accuracy is a few ulp at most (tested against NumPy), and NaN propagates through
each of them: no ``fastmath`` flag that could assume away NaN or infinity is used anywhere. Only
``contract`` (fused multiply-adds) and, in loops that accumulate sums, ``reassoc`` are allowed.

What keeps a loop vectorised here (each was measured: a loop that loses SIMD runs 5-10x slower):

- the loop calls only small leaf functions, never a helper that itself calls several of them
  (LLVM's inliner then gives up, and the loop stays scalar): see
  :func:`~.gaussians.box_muller`;
- every array in it is 1-D or C-ordered and indexed by the loop counter itself (not ``i0 + t``,
  not a strided 2-D view); a gather (``x[anc[i]]``) goes into a small scratch block first;
- no data-dependent branch: selects only (a pointer-by-pointer resampler mispredicts a branch
  per particle on real weights; see :func:`tltrack.filters.resampling.systematic_walk`).

Randomness stays NumPy's: the caller fills ``U`` with ``Generator.random(out=...)`` from each run's
own generator (53-bit uniforms, one per Gaussian, as NumPy's own ziggurat uses one 64-bit draw per
Gaussian), and the Gaussians are made by Box-Muller from those uniforms. A run's numbers depend
only on its generator and N, never on the batch around it (no loop mixes runs, and a reduction's
order depends only on N).

Array layouts: particles ``x`` are ``(n_x, B, N)`` as in
:class:`~tltrack.filters.particle.ParticleFilter`; per-run buffers are ``(B, ...)`` rows.
"""
