"""
Transfer learning in your Stone Soup tracker
============================================

You track with `Stone Soup <https://stonesoup.readthedocs.io>`_, and a partner with a better
sensor will send you what tltrack's sources send: its predicted observation of the target for
your next step, (eta_hat, P_eta_eta), never its raw data. The plugin (``pip install
'tltrack[stonesoup]'``) makes that a detection that Stone Soup's own updaters take.

Here everything is Stone Soup's own: its constant-velocity model drives the truth and both
trackers, its unscented Kalman predictor and updater run them. From the plugin come the sensors
(tltrack's range-bearing radar as a Stone Soup measurement model), the source's transfer, and the
primary's detection of it.
"""

# %%
# The world: a target, a poor radar and a good one
# -------------------------------------------------
# The primary's radar sits at the origin with 50 m and 20 mrad of noise; the source's, 3 km
# away, has 5 m and 2 mrad. A state is Stone Soup's [x, vx, y, vy].
import datetime

import numpy as np
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.plugins.tltrack import Sensor
from stonesoup.types.array import StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
from tltrack.config import SensorSpec

np.random.seed(2)
motion = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.5), ConstantVelocity(0.5)])
layout = {"ndim_state": 4, "mapping": (0, 2), "velocity_mapping": (1, 3)}
primary_radar = Sensor(
    spec=SensorSpec(kind="range-bearing", position=(0.0, 0.0), sigma_r=50.0, sigma_bearing=0.02),
    **layout,
)
source_radar = Sensor(
    spec=SensorSpec(kind="range-bearing", position=(3000.0, 0.0), sigma_r=5.0, sigma_bearing=0.002),
    **layout,
)

start, T = datetime.datetime(2026, 12, 1, 12, 0), datetime.timedelta(seconds=1)
truth = GroundTruthPath([GroundTruthState([1000.0, 10.0, 2000.0, -5.0], timestamp=start)])
for k in range(1, 100):
    x = motion.function(truth[-1], noise=True, time_interval=T)
    truth.append(GroundTruthState(x, timestamp=start + k * T))


def measure(radar: Sensor, k: int) -> Detection:
    """The radar's noisy detection of the target at step k."""
    z = radar.function(truth[k], noise=True)
    return Detection(StateVector(np.asarray(z, dtype=float)), truth[k].timestamp, radar)


# %%
# The source: a Stone Soup UKF that sends transfers
# -------------------------------------------------
# After its update at k, the source predicts k + 1 and summarises that prediction through its own
# radar: ``transfer_message`` gives tltrack's Transfer, the message its writer
# (``TransferWriter``) would publish over Zenoh. Here it goes through the wire format and back,
# as a primary would receive it.
from stonesoup.plugins.tltrack import UKF_POINTS, detection, stacked, transfer_message
from stonesoup.predictor.kalman import UnscentedKalmanPredictor
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState
from stonesoup.updater.kalman import UnscentedKalmanUpdater
from tltrack.wire.messages import Transfer, decode, encode

predictor = UnscentedKalmanPredictor(motion, **UKF_POINTS)
updater = UnscentedKalmanUpdater(None, **UKF_POINTS)
prior = GaussianState([900.0, 0.0, 2100.0, 0.0], np.diag([200.0, 20.0, 200.0, 20.0]) ** 2, start)

source = prior
sent: dict[int, bytes] = {}  # k_apply -> the message on the wire
for k in range(1, len(truth)):
    prediction = predictor.predict(source, timestamp=truth[k].timestamp)
    source = updater.update(SingleHypothesis(prediction, measure(source_radar, k)))
    ahead = predictor.predict(source, timestamp=truth[k].timestamp + T)
    msg = transfer_message(ahead, source_radar, episode="harbour", source="s1", k=k, t_sensor=k)
    sent[msg.k_apply] = encode(msg)
print(f"{len(sent)} transfers of {len(sent[2])} bytes each")
print(decode(sent[2], Transfer).model_dump(include={"k_apply", "eta", "P_eta"}))

# %%
# The primary: the transfer as a second detection
# -----------------------------------------------
# A received transfer becomes a detection whose measurement model is the source's radar with noise
# P_eta_eta. ``stacked`` joins it to the primary's own detection, so one unscented update takes
# both: tltrack's TL-UKF. Without a transfer, the same tracker is the isolated one.
from stonesoup.types.track import Track

isolated, tl = Track([prior]), Track([prior])
for k in range(1, len(truth)):
    z = measure(primary_radar, k)
    eta = [detection(decode(sent[k], Transfer), **layout)] if k in sent else []
    for track, d in ((isolated, z), (tl, stacked([z, *eta], when=z.timestamp))):
        prediction = predictor.predict(track[-1], timestamp=z.timestamp)
        track.append(updater.update(SingleHypothesis(prediction, d)))


def rmse(track: Track) -> float:
    """Position RMSE against the truth, over steps 1..K."""
    err = [
        np.hypot(*(np.asarray(s.state_vector, dtype=float)[[0, 2], 0] - t.state_vector[[0, 2], 0]))
        for s, t in zip(track[1:], truth[1:], strict=True)
    ]
    return float(np.sqrt(np.mean(np.square(err))))


print(f"isolated {rmse(isolated):6.1f} m   with the transfer {rmse(tl):6.1f} m")
assert rmse(tl) < 0.5 * rmse(isolated)

# %%
# Over the track
# --------------
import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(7, 5))
ax.plot(*np.array([t.state_vector[[0, 2], 0] for t in truth]).T, "k", lw=2, label="truth")
for track, label in ((isolated, "isolated UKF"), (tl, "TL-UKF (Stone Soup + transfer)")):
    ax.plot(*np.array([np.asarray(s.state_vector, float)[[0, 2], 0] for s in track]).T, label=label)
ax.plot(0, 0, "k^", ms=8, label="primary's radar")
ax.plot(3000, 0, "ks", ms=8, label="source's radar")
ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
ax.legend()
fig.tight_layout()

# %%
# Live, over Zenoh
# ----------------
# In a deployment the source publishes with ``TransferWriter(session, source="s1",
# episode=...)`` and the primary reads with ``TransferReader``, a Stone Soup detection feeder, on
# a session opened under its own identity (the routers' access control then lets it read the
# sources' transfers and nothing else of theirs)::
#
#     from tltrack.wire.transport import ZenohSettings, open_session
#
#     with (
#         open_session(ZenohSettings(username="primary", password=...)) as session,
#         TransferReader(session=session, **layout) as reader,
#     ):
#         for when, (eta,) in reader:
#             ...  # stack eta with the primary's detection of step eta.k_apply
#
# ``tests/test_stonesoup_live.py`` runs exactly that against a live tltrack source and finds the
# engine's TL-UKF to 1e-6. Estimates go back to tltrack's CSV with
# :func:`tltrack.interop.stonesoup.write_csv`.
