"""
Operators with different sensors
================================

A passive, bearing-only primary at the origin, helped by a range-bearing radar elsewhere. Alone,
a bearing-only sensor at a fixed position cannot observe range: its filter keeps the bearing and
drifts along it. The radar's transfer, expressed in the radar's own coordinates (range and
bearing from the radar), gives the primary what it lacks. The pair comes from
``examples/bearing-only-primary.toml``:

.. literalinclude:: /../examples/bearing-only-primary.toml
   :language: toml
   :caption: examples/bearing-only-primary.toml
"""

# %%
# Load and run
# ------------
#
# ``fusion-rpf`` is centralised fusion: the primary given the radar's *raw* measurements too, what
# the transfer trades away for privacy.
from pathlib import Path

# sphinx_gallery_start_ignore
# sphinx-gallery runs this file from its own folder, without defining __file__
if "__file__" not in globals():
    __file__ = str(Path.cwd() / "plot_different_sensors.py")
# sphinx_gallery_end_ignore

from tltrack.config import load_config
from tltrack.engine.montecarlo import run_experiment

EXAMPLE = Path(__file__).resolve().parents[1] / "bearing-only-primary.toml"
cfg = load_config(
    EXAMPLE, preset="arasaratnam-haykin", truth="noise-free", particles=1000, runs=20, seed=1
)
results = run_experiment(cfg, ["rpf", "tl-rpf", "fusion-rpf"], workers=1)
for name, r in results.items():
    print(f"{name:12s} RMSE {r.rmse_overall:8.2f} m   lost {r.lost_fraction:5.1%}")
assert results["tl-rpf"].rmse_overall < 0.1 * results["rpf"].rmse_overall

# %%
# Over time, against the bound
# ----------------------------
import matplotlib.pyplot as plt
import numpy as np
from tltrack.engine.results import assemble

doc = assemble(cfg, results)
k = np.arange(1, cfg.K + 1)
fig, ax = plt.subplots(figsize=(7, 4))
for name in ("rpf", "tl-rpf", "fusion-rpf"):
    ax.plot(k, results[name].rmse_per_step, label=name)
ax.plot(k, doc["pcrlb"]["primary"], "k--", lw=1, label="PCRLB, bearing only")
ax.plot(k, doc["pcrlb"]["with_source"], "k:", lw=1, label="PCRLB, with the radar's data")
ax.set(xlabel="step k", ylabel="position RMSE [m]", yscale="log")
ax.legend()
fig.tight_layout()

# %%
# The noise-free truth is one deterministic trajectory: a filter facing it is not held to the
# PCRLB, which averages over trajectories drawn with the process noise, so fusion may dip below.
#
# Where the sensors are
# ---------------------
from tltrack.config import position_of
from tltrack.engine.montecarlo import trace_run
from tltrack.engine.scenario import truth
from tltrack.engine.setup import Setup

setup = Setup(cfg)
pos = setup.layout.position
tracks = trace_run(cfg, ["rpf", "tl-rpf"], run=0)
fig, ax = plt.subplots(figsize=(6, 5))
ax.plot(*pos(truth(setup, 0).T), "k", lw=2, label="truth")
for name, est in tracks.items():
    ax.plot(*pos(est.T), lw=1, label=name)
for sid, marker in zip(cfg.sensor_ids, ("^", "s"), strict=True):
    ax.plot(*position_of(cfg, sid), "k" + marker, ms=8, label=f"{sid}'s sensor")
ax.set(xlabel="x [m]", ylabel="y [m]", title="run 0")
ax.legend()
fig.tight_layout()

# %%
# Robust transfer needs a position
# --------------------------------
#
# ``robust-tl-rpf`` compares each transfer with the primary's own measurement as positions, so it
# needs a sensor whose single measurement fixes one: with a bearing-only primary it is refused at
# start, saying why. Plain ``tl-rpf`` works with any pair.
from tltrack.engine.montecarlo import check_filters

try:
    check_filters(cfg, ["robust-tl-rpf"])
except ValueError as err:
    print("refused:", err)
