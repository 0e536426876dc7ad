"""The Stone Soup plugin: tltrack's transfer in a Stone Soup tracker.

Installed with ``pip install 'tltrack[stonesoup]'``, it registers under Stone Soup's
``stonesoup.plugins`` entry-point group, so that::

    from stonesoup.plugins.tltrack import Sensor, predicted_observation, detection, stacked

works beside ``from tltrack.interop.stonesoup import ...``. What it gives:

- models (:mod:`.models`): any tltrack sensor as a Stone Soup measurement model
  (:class:`Sensor`), any tltrack motion model as a transition model (:class:`Motion`);
- the transfer (:mod:`.transfer`): a source's (eta_hat, P_eta_eta) from a Stone Soup prediction
  (:func:`predicted_observation`, :func:`transfer_message`); a received transfer as a detection
  (:func:`detection`) that Stone Soup's updaters take as a second likelihood, alone or stacked with
  the primary's own detection into one update (:func:`stacked`);
- the wire (:mod:`.wire`): :class:`TransferWriter` publishes a source's transfers over Zenoh,
  :class:`TransferReader` feeds a tracker the transfers its session receives;
- tracks (:mod:`.tracks`): tltrack's estimates as Stone Soup tracks, and back to the CSV of
  ``tltrack track``.

The how-to page "Transfer learning in your Stone Soup tracker" walks through it.
"""

from tltrack.interop.stonesoup.models import Angle, Motion, Sensor, Stacked
from tltrack.interop.stonesoup.tracks import from_tracks, to_tracks, write_csv
from tltrack.interop.stonesoup.transfer import (
    UKF_POINTS,
    TransferDetection,
    detection,
    predicted_observation,
    stacked,
    timestamp,
    transfer_message,
)
from tltrack.interop.stonesoup.wire import TransferReader, TransferWriter

__all__ = [
    "UKF_POINTS",
    "Angle",
    "Motion",
    "Sensor",
    "Stacked",
    "TransferDetection",
    "TransferReader",
    "TransferWriter",
    "detection",
    "from_tracks",
    "predicted_observation",
    "stacked",
    "timestamp",
    "to_tracks",
    "transfer_message",
    "write_csv",
]
