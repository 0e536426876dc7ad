"""tltrack: Bayesian transfer learning between tracking operators.

The TL-PF of Alotaibi, Mark & Fasihi, as a library, a Monte-Carlo engine and live services.

Layers, bottom to top (an import never runs back up):

1. :mod:`tltrack.config` and :mod:`tltrack.models`: parameters, motion and measurement models;
2. :mod:`tltrack.filters`: SIR/TL particle filters, UKF and CKFs with their TL variants;
3. :mod:`tltrack.engine`: scenarios, random streams, the Monte-Carlo engine, the PCRLB;
4. :mod:`tltrack.messages` and :mod:`tltrack.transport`: the wire format and Zenoh plumbing;
5. ``services/`` and :mod:`tltrack.cli` on top.
"""

__version__ = "0.1.0"
