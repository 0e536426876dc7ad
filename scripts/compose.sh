#!/usr/bin/env bash
# Run Docker Compose on the project's compose.yaml with whichever tool answers here:
# the `docker compose` plugin (v2) or the standalone `docker-compose` (v1, e.g. Debian's 1.29).
#
#   scripts/compose.sh up                 # builds tltrack:latest first if the engine lacks it
#   scripts/compose.sh logs -f scorer
#   scripts/compose.sh down               # keeps the volume with the scorer's database
#   scripts/compose.sh down -v            # ... and removes it too
#
# Settings: TLTRACK_COMPOSE (the command to use, e.g. "docker-compose"), TLTRACK_IMAGE
# (tltrack:latest), and every TLTRACK_* default of compose.yaml.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

log() { printf '[compose] %s\n' "$*" >&2; }
die() { log "error: $*"; exit 1; }

if [[ -n "${TLTRACK_COMPOSE:-}" ]]; then
    read -r -a COMPOSE <<<"$TLTRACK_COMPOSE"
elif docker compose version >/dev/null 2>&1; then
    COMPOSE=(docker compose)
elif command -v docker-compose >/dev/null 2>&1 && docker-compose version >/dev/null 2>&1; then
    COMPOSE=(docker-compose)
else
    die "neither 'docker compose' nor 'docker-compose' answers; install one of them"
fi

# Commands that create containers need the image; there is no registry to pull it from.
case "${1:-}" in
    up|run|create)
        image="${TLTRACK_IMAGE:-tltrack:latest}"
        if ! docker image inspect "$image" >/dev/null 2>&1; then
            log "$image is not in the engine; building it with scripts/build_image.sh"
            "$ROOT/scripts/build_image.sh"
        fi
        ;;
esac

exec "${COMPOSE[@]}" -f "$ROOT/compose.yaml" --project-directory "$ROOT" "$@"
