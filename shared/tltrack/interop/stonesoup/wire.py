"""Transfers over Zenoh for a Stone Soup tracker: a writer for a source, a reader for a primary.

Both run on a session the caller opens under its operator's identity (the routers' access control
then decides what it may send and read), as tltrack's services do::

    from tltrack.wire.transport import ZenohSettings, open_session

    with open_session(ZenohSettings(username="primary", password=...)) as session:
        for when, detections in TransferReader(session, ndim_state=4, mapping=(0, 2)):
            ...

The reader validates each payload as tltrack's primary tracker does (the message, then
:func:`tltrack.wire.admission.refusal`: its sender must be the key's source), and skips, counts
and logs what it refuses.
"""

from __future__ import annotations

import datetime
import logging
import time
from collections.abc import Iterator, Sequence
from typing import Any

import zenoh
from stonesoup.base import Property
from stonesoup.buffered_generator import BufferedGenerator
from stonesoup.reader.base import DetectionReader

from tltrack.interop.stonesoup.models import Sensor
from tltrack.interop.stonesoup.transfer import TransferDetection, detection, transfer_message
from tltrack.wire import admission, keys
from tltrack.wire.messages import RejectCounter, Transfer
from tltrack.wire.transport import Publisher, Received, Subscriber, decode_received

log = logging.getLogger(__name__)


class TransferWriter:
    """Publishes a Stone Soup source's transfers on ``tltrack/source/<source>/transfer/<episode>``,
    as tltrack's source tracker does."""

    def __init__(self, session: zenoh.Session, *, source: str, episode: str) -> None:
        self.source = source
        self.episode = episode
        self._pub = Publisher(session, keys.transfer(source, episode))

    def write(self, prediction: Any, sensor: Sensor, *, k: int, t_sensor: float) -> Transfer:
        """Send the transfer of ``prediction`` (the source's density for step k + 1) after its
        step ``k``; returns the message sent."""
        msg = transfer_message(
            prediction, sensor, episode=self.episode, source=self.source, k=k, t_sensor=t_sensor
        )
        self._pub.put(msg)
        return msg

    def close(self) -> None:
        self._pub.close()

    def __enter__(self) -> TransferWriter:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


#: the (episode, source) pairs whose last step a reader keeps
_KEPT_LINKS = 1024


class TransferReader(DetectionReader):
    """A Stone Soup detection feeder of the transfers a session receives: each as a
    :class:`~tltrack.interop.stonesoup.transfer.TransferDetection`, dated at the step it is for
    given the primary's ``steps`` (else at its source's time; see
    :func:`~tltrack.interop.stonesoup.transfer.detection`).

    It subscribes when made (what arrives before it is read waits in a bounded queue), and stops
    after ``count`` transfers, or when none has come for ``idle_s`` seconds. Close it, or use it
    in a ``with`` block.
    """

    session: zenoh.Session = Property(doc="An open Zenoh session, under the primary's identity.")
    ndim_state: int = Property(doc="The dimension of the tracker's state.")
    mapping: Sequence[int] = Property(doc="The state's (x, y) indices.")
    velocity_mapping: Sequence[int] | None = Property(
        default=None, doc="The state's (vx, vy) indices; default: each position index + 1."
    )
    steps: tuple[datetime.datetime, datetime.timedelta] | None = Property(
        default=None,
        doc="The primary's step 0's time and period: date each transfer at the step it is for.",
    )
    key: str = Property(default=keys.TRANSFERS, doc="The key expression to subscribe to.")
    count: int | None = Property(default=None, doc="Stop after this many transfers.")
    idle_s: float | None = Property(default=None, doc="Stop after this long without one.")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.rejects = RejectCounter()  #: what it refused, per key and reason
        self._sub = Subscriber(self.session, [self.key], rejects=self.rejects)
        self._closed = False  #: closed (by another thread, at shutdown): the generator ends
        #: (episode, source) -> the last step a transfer of it was for: one for that step again
        #: would be a second update on the same statement, one for an earlier step a prediction
        #: backwards
        self._last: dict[tuple[str, str], int] = {}

    def close(self) -> None:
        self._closed = True
        self._sub.close()

    def __enter__(self) -> TransferReader:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def _accepted(self, item: Received) -> Transfer | None:
        """The transfer in ``item``, or None if tltrack's primary would refuse it."""
        msg = decode_received(item, Transfer, self.rejects)
        if msg is None:
            return None
        try:
            info = keys.parse(item.key)
        except ValueError:
            info = None
        if info is None or info.kind != "transfer":
            refused: tuple[str, str] | None = ("wrong_key", f"{item.key} is not a transfer key")
        else:
            refused = admission.refusal(info, msg)
        last = self._last.get((msg.episode, msg.sender))
        if refused is None and last is not None and msg.k_apply <= last:
            why = "a second" if msg.k_apply == last else f"after the one for step {last}"
            reason = "duplicate" if msg.k_apply == last else "late_transfer"
            refused = (reason, f"{why} transfer for step {msg.k_apply} from {msg.sender}")
        if refused is not None:
            self.rejects.add(item.key, refused[0])
            log.warning("refused a transfer on %s: %s", item.key, refused[1])
            return None
        return msg

    @BufferedGenerator.generator_method
    def detections_gen(self) -> Iterator[tuple[datetime.datetime, set[TransferDetection]]]:
        taken = 0
        last = time.monotonic()
        while (self.count is None or taken < self.count) and not self._closed:
            item = self._sub.recv(timeout=0.1)
            if item is None:
                if self.idle_s is not None and time.monotonic() - last > self.idle_s:
                    return
                continue
            last = time.monotonic()
            msg = self._accepted(item)
            if msg is None:
                continue
            try:
                det = detection(
                    msg,
                    ndim_state=self.ndim_state,
                    mapping=self.mapping,
                    velocity_mapping=self.velocity_mapping,
                    steps=self.steps,
                )
            except ValueError as err:  # a sensor this state cannot express
                self.rejects.add(item.key, "invalid")
                log.warning("refused a transfer on %s: %s", item.key, err)
                continue
            self._last[(msg.episode, msg.sender)] = msg.k_apply  # delivered: its step is taken
            if len(self._last) > _KEPT_LINKS:
                self._last.pop(next(iter(self._last)))  # the oldest episode's
            taken += 1
            yield det.timestamp, {det}
