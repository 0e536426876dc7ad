"""tltrack: Bayesian transfer learning between tracking operators.

The TL-PF of Alotaibi, Mark & Fasihi, as a library, a Monte-Carlo engine and live services.

Layers, bottom to top; each folder is one, and an import never runs back up:

1. :mod:`tltrack.declare`: how components declare their kind, parameters and units;
2. :mod:`tltrack.models`: motion and measurement models, and their registries;
3. :mod:`tltrack.filters`: particle filters, UKF and CKFs, the source and primary roles, and the
   registry of filter kinds;
4. :mod:`tltrack.config`: the configuration's schema (derived from the registries), its loading
   from the user's files and recorded truths, and plugin kinds;
5. :mod:`tltrack.engine`: the models of a config, the step driver, the Monte-Carlo engine, the
   PCRLB, results and figures;
6. :mod:`tltrack.studies`: the paper's reproduction and the studies beyond it;
   :mod:`tltrack.wire`: the messages, the key expressions and the Zenoh transport;
7. :mod:`tltrack.live`: a live service's base, its episodes, process supervision and signals;
8. :mod:`tltrack.perf`: the step and live benchmarks;
9. :mod:`tltrack.app`: the ``tltrack`` command; ``services/`` (``tltrack.services``), the
   processes;
10. :mod:`tltrack.interop`: where tracking people work, beside them: the Stone Soup plugin and the
    zenoh-cli decoder (optional extras).
"""

__version__ = "0.1.0"
