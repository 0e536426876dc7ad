#!/usr/bin/env bash
# Build the tltrack image (one image for every service) with no network inside the build.
#
#   scripts/build_image.sh
#
# 1. Builds wheels on the host with scripts/build_wheels.sh and the host's Python (which must be the
#    base image's minor version): build/wheels/deps/, the pinned dependencies (skipped when the pins
#    and the Python are unchanged), and build/wheels/app/, tltrack itself from the working tree.
# 2. Picks the base image: $TLTRACK_BASE if set; else python:3.11-slim if the engine has it; else the
#    local base tltrack-base:bookworm, built by scripts/build_base_image.sh when missing.
# 3. docker build -t $TLTRACK_IMAGE (tltrack:latest) --build-arg BASE=<base> .
#
# Settings: TLTRACK_BASE, TLTRACK_IMAGE, TLTRACK_PYTHON (the host Python; default .venv/bin/python,
# else python3), TLTRACK_REBUILD_WHEELS=1 (rebuild the dependency wheels).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

LOCAL_BASE="${TLTRACK_BASE_IMAGE:-tltrack-base:bookworm}"
IMAGE="${TLTRACK_IMAGE:-tltrack:latest}"
WHEELS="build/wheels"

log() { printf '[build_image] %s\n' "$*" >&2; }
die() { log "error: $*"; exit 1; }
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

command -v docker >/dev/null 2>&1 || die "docker is not installed"
docker info >/dev/null 2>&1 || die "cannot reach the Docker Engine"

source "$ROOT/scripts/host_python.sh"
HOST_PY="$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"

# --- base image --------------------------------------------------------------------------------
T_BASE=0
if [[ -n "${TLTRACK_BASE:-}" ]]; then
    BASE="$TLTRACK_BASE"
elif docker image inspect python:3.11-slim >/dev/null 2>&1; then
    BASE="python:3.11-slim"
else
    BASE="$LOCAL_BASE"
fi
if [[ "$BASE" == "$LOCAL_BASE" ]]; then
    t=$(now)
    "$ROOT/scripts/build_base_image.sh" "$BASE"
    T_BASE=$(since "$t")
fi
log "base image: $BASE"

if docker image inspect "$BASE" >/dev/null 2>&1; then
    BASE_PY="$(docker run --rm --entrypoint python3 "$BASE" \
        -c 'import sys; print("%d.%d" % sys.version_info[:2])')" \
        || die "cannot run python3 in $BASE"
    [[ "$BASE_PY" == "$HOST_PY" ]] \
        || die "host Python $HOST_PY ($PY) differs from $BASE's Python $BASE_PY: the wheels would not fit"
else
    log "$BASE is not in the engine yet (docker build will pull it); Python versions not compared"
fi

# --- wheels ------------------------------------------------------------------------------------
t=$(now)
TLTRACK_PYTHON="$PY" "$ROOT/scripts/build_wheels.sh" "$WHEELS"
T_WHEELS=$(since "$t")

# --- image -------------------------------------------------------------------------------------
# Without the buildx plugin, a recent docker CLI refuses DOCKER_BUILDKIT=1; use the classic builder.
if ! docker buildx version >/dev/null 2>&1; then
    export DOCKER_BUILDKIT=0
fi
log "docker build -t $IMAGE --build-arg BASE=$BASE ."
t=$(now)
docker build -t "$IMAGE" --build-arg BASE="$BASE" .
T_IMAGE=$(since "$t")

SIZE="$(docker image inspect -f '{{.Size}}' "$IMAGE")"
log "done: $IMAGE, $((SIZE / 1000000)) MB; base ${T_BASE}s, wheels ${T_WHEELS}s, docker build ${T_IMAGE}s"
