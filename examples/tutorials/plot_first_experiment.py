"""
Your first experiment
=====================

One Monte-Carlo experiment from Python: the paper's dual tracker in Scenario 2 (a target in a
coordinated turn), a primary radar four times noisier than the source's, and the same filters with
and without the source's transfer. The command line does the same with
``tltrack experiment`` (:doc:`/reference/cli`); this page runs it small (1000 particles, 20 runs)
so that it takes seconds, where the paper's figures take 6000 particles and thousands of runs.
"""

# %%
# A configuration
# ---------------
#
# :func:`~tltrack.config.make_config` builds a validated :class:`~tltrack.config.Config` from any
# of its fields (:doc:`/reference/config`); the scenario and the preset fill in the rest. The
# ``arasaratnam-haykin`` preset is the cubature-KF benchmark the paper says it copies
# (:doc:`/background`), and ``truth = "fixed"`` draws one trajectory shared by every run.
from tltrack.config import make_config

cfg = make_config(
    preset="arasaratnam-haykin",
    truth="fixed",
    primary_intensity=4.0,  # the primary's noise intensity I_w; the source's is 1
    particles=1000,
    runs=20,
    seed=2,
)
print(f"scenario {cfg.scenario}, K = {cfg.K} steps of {cfg.Ts} s, {cfg.runs} runs")
print(f"source {cfg.source.id}: intensity {cfg.source.intensity}, primary {cfg.primary_intensity}")

# %%
# Run it
# ------
#
# A filter name is ``[role-]kind`` (:doc:`/concepts`): ``rpf`` is a particle filter alone,
# ``tl-rpf`` the same filter fed the source's transfers, and the source's own ``source-rpf`` runs
# with them; ``ukf`` and ``tl-ukf`` are the unscented Kalman filter's pair. (``rpf`` is the
# auxiliary particle filter the services use; the paper's bootstrap filter, ``pf``, loses the
# track in a share of runs of this scenario, and its TL filter with it: see the ``rpf`` study among
# the :doc:`/results`.) :func:`~tltrack.engine.montecarlo.run_experiment` runs every run of every
# filter on the same measurements; each run draws from its own random streams, so the result does
# not depend on the batch size or the number of workers.
from tltrack.engine.montecarlo import run_experiment

results = run_experiment(cfg, ["rpf", "tl-rpf", "ukf", "tl-ukf"], workers=1)
for name, r in results.items():
    print(f"{name:10s} RMSE {r.rmse_overall:7.2f} m   lost {r.lost_fraction:5.1%}")

# %%
# The transfer helps the primary: ``tl-rpf`` is below ``rpf``, and ``tl-ukf`` below ``ukf``, though
# both stay above the source's own filters, which have the better sensor.
assert results["tl-rpf"].rmse_overall < results["rpf"].rmse_overall

# %%
# RMSE over time
# --------------
#
# Each result holds the RMSE at every step over the runs (``rmse_per_step``).
# :func:`~tltrack.engine.results.assemble` adds the posterior Cramér-Rao lower bound of the
# primary alone and with the source's data, the same document ``tltrack experiment`` writes as
# ``results.json``.
import matplotlib.pyplot as plt
import numpy as np
from tltrack.engine.results import assemble

doc = assemble(cfg, results)
k = np.arange(1, cfg.K + 1)
fig, ax = plt.subplots(figsize=(7, 4))
for name in ("rpf", "tl-rpf", "source-rpf"):
    ax.plot(k, results[name].rmse_per_step, label=name)
ax.plot(k, doc["pcrlb"]["primary"], "k--", lw=1, label="PCRLB, primary alone")
ax.plot(k, doc["pcrlb"]["with_source"], "k:", lw=1, label="PCRLB, with the source's data")
ax.set(xlabel="step k", ylabel="position RMSE [m]", yscale="log", title="Scenario 2, I_p = 4")
ax.legend(fontsize="small", ncols=2, loc="upper center", bbox_to_anchor=(0.5, -0.15))
fig.tight_layout()

# %%
# One run's tracks
# ----------------
#
# :func:`~tltrack.engine.montecarlo.trace_run` steps the filters through one run and keeps their
# estimates; :func:`~tltrack.engine.scenario.truth` gives that run's true states.
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import truth
from tltrack.engine.setup import Setup

setup = Setup(cfg)
tracks = trace_run(cfg, ["rpf", "tl-rpf"], run=0)
x = truth(setup, 0)
pos = setup.layout.position
fig, ax = plt.subplots(figsize=(6, 5))
ax.plot(*pos(x.T), "k", lw=2, label="truth")
for name, est in tracks.items():
    ax.plot(*pos(est.T), lw=1, label=name)
ax.plot(0, 0, "k^", label="both sensors")
ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="run 0")
ax.legend()
fig.tight_layout()

# %%
# The same from the command line
# ------------------------------
#
# .. code-block:: sh
#
#    tltrack experiment --preset arasaratnam-haykin --truth fixed --particles 1000 --runs 20 \
#        --seed 1 --filters rpf,tl-rpf,ukf,tl-ukf --out /tmp/first
#
# writes ``/tmp/first/results.json``, ``rmse.png`` and ``trajectory.png``. With ``--runs 500``
# and 6000 particles, ``tltrack reproduce`` redraws every figure of the paper.
