"""What a receiver refuses in a well-formed message before it looks at any state of its own.

:func:`tltrack.wire.messages.decode` says whether a payload *is* a message; the key says whose it
must be. The access control lets only a source publish on its own transfer key, but a message also
names its ``sender``, and the two must agree, so that no operator speaks for another whatever the
routers let through:

- the primary refuses a transfer whose sender is not its key's source (any source may help, none
  may speak for another);
- the scorer refuses a truth that sensor_sim did not send, an estimate that is not its key's
  owner's, and either when it is about another episode than its key's.

The primary's tracker and the scorer make these checks with :func:`refusal`, and so does the
zenoh-cli decoder (``tltrack.interop.zenoh_cli``), which therefore prints the reason they give.
"""

from __future__ import annotations

from tltrack.wire import keys
from tltrack.wire.messages import Message

TRUTH_SENDER = "sensor_sim"  #: the only sender of the truth

#: the keys whose message must be about the key's own episode (the scorer's, the schedule)
_OF_ITS_EPISODE = ("truth", "source_estimate", "primary_estimate", "schedule")


def sender(info: keys.KeyInfo) -> str | None:
    """The sender a message on a key of ``info`` must name; None where no receiver checks."""
    if info.kind in ("transfer", "source_estimate"):
        return info.source
    if info.kind in ("primary_estimate", "schedule"):
        return keys.PRIMARY
    if info.kind == "truth":
        return TRUTH_SENDER
    return None


def refusal(info: keys.KeyInfo, msg: Message) -> tuple[str, str] | None:
    """``(reason, detail)`` when a receiver refuses ``msg`` on a key of ``info`` whatever it
    holds (``wrong_sender``, ``unknown_episode``); None when only its state can say."""
    want = sender(info)
    if want is not None and msg.sender != want:
        return "wrong_sender", f"sender {msg.sender!r} on a key of {want!r}"
    if info.kind in _OF_ITS_EPISODE and msg.episode != info.episode:
        return "unknown_episode", f"episode {msg.episode!r} on a key of {info.episode!r}"
    return None
