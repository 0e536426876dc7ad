# One image for every tltrack service; compose chooses the command of each container
# (`python -m tltrack.services.<name>` or `tltrack <subcommand>`).
#
# The build needs no network: scripts/build_image.sh builds the wheels on the host into build/wheels/
# (deps/ = pinned dependencies, app/ = tltrack itself) and this file installs them with --no-index.
#
#   scripts/build_image.sh                      # wheels, base image if needed, then this build
#   docker build -t tltrack:latest .            # with a registry: FROM python:3.11-slim
#   docker build -t tltrack:latest --build-arg BASE=tltrack-base:bookworm .   # no registry
#
# Both bases are Debian bookworm with Python 3.11 (python3 in /usr/local/bin on python:3.11-slim,
# in /usr/bin on the debootstrap base), so the venv at /opt/venv is made with whichever python3
# the base has, and the build stage and the final stage share it.
ARG BASE=python:3.11-slim

# ---- build stage: a venv with the dependencies; the wheels stay out of the final image ----------
FROM ${BASE} AS deps
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INDEX=1 PIP_FIND_LINKS=
COPY build/wheels/requirements.txt /wheels/requirements.txt
COPY build/wheels/deps/ /wheels/deps/
# Then trim what no service runs: setuptools, and the test suites of numpy, scipy and matplotlib
# (about 55 MB; numpy.testing and scipy's own helpers are not in them).
RUN python3 -m venv /opt/venv \
 && /opt/venv/bin/pip install --no-index --find-links /wheels/deps -r /wheels/requirements.txt \
 && /opt/venv/bin/pip uninstall --yes --quiet setuptools \
 && cd /opt/venv/lib/python3.*/site-packages \
 && find numpy scipy matplotlib mpl_toolkits -depth -type d -name tests -exec rm -rf {} + \
 && /opt/venv/bin/python -c "import numpy, scipy.optimize, scipy.stats, scipy.linalg, zenoh, pydantic, pydantic_settings, matplotlib.pyplot, msgpack, typer, rich"

# ---- final image ------------------------------------------------------------------------------
FROM ${BASE}
ARG UID=10001
ARG GID=10001
ENV VIRTUAL_ENV=/opt/venv \
    PATH=/opt/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    LANG=C.UTF-8 \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg \
    MPLCONFIGDIR=/tmp/matplotlib \
    NUMBA_CACHE_DIR=/opt/numba-cache

# --no-log-init: no sparse lastlog/faillog entry for a high uid in the layer.
RUN groupadd --gid "${GID}" tltrack \
 && useradd --uid "${UID}" --gid tltrack --home-dir /data --no-create-home --no-log-init \
        --shell /usr/sbin/nologin tltrack \
 && mkdir -p /data \
 && chown tltrack:tltrack /data \
 && chmod 0750 /data

COPY --from=deps /opt/venv /opt/venv

# tltrack itself last: a code change rebuilds only this small layer.
COPY build/wheels/app/ /tmp/app/
# Compiling the particle-filter kernels here puts numba's cache beside them in the image, so the
# trackers start in seconds instead of compiling at every start.
RUN pip install --no-index --no-deps /tmp/app/*.whl \
 && rm -rf /tmp/app \
 && python -c "import tltrack.services; from tltrack.filters.warm import warm_up; warm_up()"

# /data holds the scorer's SQLite database; mount a named volume there (a new named volume
# inherits the owner tltrack from this directory).
WORKDIR /data
# numba uses a cache directory only if the user that loads it may write there (it ignores the
# kernels compiled above otherwise, and compiles them again at every start): give it to tltrack.
# A host of another CPU model compiles its own kernels once into it (docs/howto/dask.md).
RUN chown -R "${UID}:${GID}" /opt/numba-cache
USER ${UID}:${GID}
CMD ["tltrack", "--help"]
