"""The primary operator's tracker: TL-PF on its own noisy sensor plus the sources' transfers, and
an isolated twin on the same data for comparison. It never sees a source's raw data."""
