"""tltrack where tracking people already work: the top layer, beside the services.

- :mod:`tltrack.interop.stonesoup`: the Stone Soup plugin (``stonesoup.plugins.tltrack``), with
  which a Stone Soup tracker sends and takes transfers;
- :mod:`tltrack.interop.zenoh_cli`: the zenoh-cli decoder (``zenoh subscribe --decoder tltrack``).

Both are optional extras (``tltrack[stonesoup]``, ``tltrack[cli]``); nothing else imports them.
"""
