"""The dual tracker as independent processes that talk only through Zenoh.

Each service is ``python -m tltrack.services.<name>``, configured by environment variables and
flags:
``sensor_sim`` (truth and measurements), ``source_tracker`` (Algorithm 1, one per source operator),
``primary_tracker`` (Algorithm 2 and an isolated twin) and ``scorer`` (the referee).
"""
