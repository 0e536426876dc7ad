"""The dual tracker as independent processes that talk only through Zenoh.

Each service is ``python -m tltrack.services.<name>``, configured by environment variables and
flags:

- ``sensor_sim``: the world's clock, the truth and (in the single-router topology) every
  sensor's measurements;
- ``sensor``: one operator's own sensor, measuring on sensor_sim's ticks (the federated
  topology, where no raw data passes through the referee);
- ``source_tracker``: Algorithm 1, one per source operator;
- ``primary_tracker``: Algorithm 2 and its isolated twin;
- ``scorer``: the referee, scoring every estimate against the truth in SQLite;
- ``dashboard``: the live page and its Prometheus metrics.
"""
