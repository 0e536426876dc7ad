"""
Bring your own sensor
=====================

A sensor the package does not know, in one file of your own, named in a configuration by its
import path: every filter, role, the PCRLB, the config files, the command line and the live
services then take it. This one is a range-only transponder, :math:`z = \\lVert p - s \\rVert + w`,
from ``examples/range_only/``.

The class
---------

A sensor declares its ``kind``, its ``components`` (each name ending in its unit), its
``parameters`` (:class:`~tltrack.declare.Parameter`: unit, default, bounds) and writes
:math:`h`, its Jacobian :math:`H`, its noise covariance :math:`R` and how a miscalibration shifts
it. Subclassing :class:`~tltrack.models.gaussian_sensor.GaussianSensor` gives the rest
(:doc:`/models`):

.. literalinclude:: /../examples/range_only/range_only.py
   :language: python
   :caption: examples/range_only/range_only.py

The configuration
-----------------

The primary operator gets the new sensor, by its import path; the source keeps the paper's
radar:

.. literalinclude:: /../examples/range_only/primary.toml
   :language: toml
   :caption: examples/range_only/primary.toml
"""

# %%
# Load it
# -------
#
# The folder holding ``range_only.py`` must be importable: ``PYTHONPATH=examples/range_only`` on
# the command line, the same here. :func:`~tltrack.config.load_config` reads the file as the
# user's own, so its kinds may be named by import path (a received message can never make a
# receiver import anything: :mod:`tltrack.declare`).
import sys
from pathlib import Path

# sphinx_gallery_start_ignore
# sphinx-gallery runs this file from its own folder, without defining __file__
if "__file__" not in globals():
    __file__ = str(Path.cwd() / "plot_own_sensor.py")
# sphinx_gallery_end_ignore

FOLDER = Path(__file__).resolve().parents[1] / "range_only"
sys.path.insert(0, str(FOLDER))

from tltrack.config import load_config
from tltrack.models.kinds import SENSORS

cfg = load_config(FOLDER / "primary.toml", particles=1000, runs=20, seed=1)
print("the primary's sensor:", cfg.primary_sensor)
print("registered now:", SENSORS.names())

# %%
# Run it
# ------
#
# A range alone leaves the cross-range direction to the prior; the radar's transfer fixes it.
# The range-only sensor has no compiled kernel, so the particle filters take their generic NumPy
# path: the same numbers, only slower.
from tltrack.engine.montecarlo import run_experiment

results = run_experiment(cfg, ["rpf", "tl-rpf"], workers=1)
for name, r in results.items():
    print(f"{name:10s} RMSE {r.rmse_overall:8.2f} m")
assert results["tl-rpf"].rmse_overall < 0.5 * results["rpf"].rmse_overall

# %%
# Against the bound
# -----------------
#
# The PCRLB takes the new sensor through its ``H``, like any other.
import matplotlib.pyplot as plt
import numpy as np
from tltrack.engine.results import assemble

doc = assemble(cfg, results)
k = np.arange(1, cfg.K + 1)
fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(k, results["rpf"].rmse_per_step, label="rpf: the range-only primary alone")
ax.plot(k, results["tl-rpf"].rmse_per_step, label="tl-rpf: with the radar's transfers")
ax.plot(k, doc["pcrlb"]["primary"], "k--", lw=1, label="PCRLB, range only")
ax.plot(k, doc["pcrlb"]["with_source"], "k:", lw=1, label="PCRLB, with the radar's data")
ax.set(xlabel="step k", ylabel="position RMSE [m]", yscale="log")
ax.legend()
fig.tight_layout()

# %%
# The same from the command line, and live
# ----------------------------------------
#
# .. code-block:: sh
#
#    PYTHONPATH=examples/range_only tltrack experiment --config examples/range_only/primary.toml \
#        --filters rpf,tl-rpf --particles 2000 --runs 20 --out /tmp/range-only
#    PYTHONPATH=examples/range_only tltrack demo --config examples/range_only/source.toml
#
# In the second, the range-only sensor is the *source's*: its transfers cross the wire described
# by its own sensor (kind, position, parameters), and the primary, which has the class
# registered, uses them without being configured for it.
