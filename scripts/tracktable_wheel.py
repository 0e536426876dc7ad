"""The tracktable-data wheel both extraction scripts read (``extract_ais_track.py``,
``extract_flights.py``): checked by its digest before anything is taken from it, so the shipped
tracks can only have come from this exact file.

    pip download tracktable-data==1.7.3.1 --no-deps -d /tmp/ttd
"""

from __future__ import annotations

import hashlib
import io
import sys
import zipfile
from pathlib import Path

WHEEL_SHA256 = "949cd19954baaf98fd2610c282c1c1265514bc4675cb0ea2ff59250136a3c0a1"


def read_member(wheel: Path, member: str) -> str:
    """The text of ``member`` of ``wheel``; exits with status 1 naming both digests when the wheel
    is not the one the tracks were made from."""
    blob = wheel.read_bytes()
    digest = hashlib.sha256(blob).hexdigest()
    if digest != WHEEL_SHA256:
        print(f"{wheel}: sha256 {digest}, expected {WHEEL_SHA256}", file=sys.stderr)
        raise SystemExit(1)
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        return z.read(member).decode("utf-8")
