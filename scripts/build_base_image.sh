#!/usr/bin/env bash
# Build a local Debian base image for tltrack without any container registry.
#
#   scripts/build_base_image.sh [IMAGE]
#
# IMAGE defaults to $TLTRACK_BASE_IMAGE, else tltrack-base:bookworm. The image is a minimal Debian
# root made by debootstrap (python3, python3-venv, ca-certificates) and loaded with `docker import`.
# If IMAGE already exists the script does nothing; set TLTRACK_REBUILD_BASE=1 to rebuild it.
#
# Other settings: TLTRACK_DEBIAN_SUITE (bookworm), TLTRACK_DEBIAN_MIRROR (http://deb.debian.org/debian).
# Needs root (debootstrap) and a Docker Engine; installs debootstrap with apt-get if it is missing.
set -euo pipefail

IMAGE="${1:-${TLTRACK_BASE_IMAGE:-tltrack-base:bookworm}}"
SUITE="${TLTRACK_DEBIAN_SUITE:-bookworm}"
MIRROR="${TLTRACK_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
INCLUDE="python3,python3-venv,ca-certificates"

log() { printf '[build_base_image] %s\n' "$*" >&2; }
die() { log "error: $*"; exit 1; }

command -v docker >/dev/null 2>&1 || die "docker is not installed"
docker info >/dev/null 2>&1 || die "cannot reach the Docker Engine (is the daemon running, may you use it?)"

# One build at a time: `make test` starts one in the background while it installs the venv, and
# the image's build (scripts/build_image.sh) then waits here for it instead of starting another.
LOCK_DIR="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/build"
mkdir -p "$LOCK_DIR"
exec 9>"$LOCK_DIR/.base.lock"
flock 9

if [[ "${TLTRACK_REBUILD_BASE:-0}" != 1 ]] && docker image inspect "$IMAGE" >/dev/null 2>&1; then
    log "image $IMAGE already exists; skipping (TLTRACK_REBUILD_BASE=1 rebuilds it)"
    exit 0
fi

SUDO=()
if [[ "$(id -u)" != 0 ]]; then
    command -v sudo >/dev/null 2>&1 || die "debootstrap needs root; run as root or install sudo"
    SUDO=(sudo)
fi

if ! command -v debootstrap >/dev/null 2>&1 && [[ ! -x /usr/sbin/debootstrap ]]; then
    log "installing debootstrap with apt-get"
    "${SUDO[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends debootstrap >/dev/null
fi
DEBOOTSTRAP="$(command -v debootstrap || echo /usr/sbin/debootstrap)"

WORK="$(mktemp -d "${TMPDIR:-/tmp}/tltrack-base.XXXXXX")"
ROOTFS="$WORK/rootfs"
cleanup() {
    set +e  # a cleanup step that fails must not skip the others
    # debootstrap mounts /proc and /sys inside the target if it fails half way; never let rm walk
    # into a mount.
    if command -v findmnt >/dev/null 2>&1; then
        findmnt -rn -o TARGET | grep -F "$WORK/" | sort -r | while read -r m; do
            "${SUDO[@]}" umount -l "$m"
        done
    fi
    "${SUDO[@]}" rm -rf --one-file-system "$WORK"
}
trap cleanup EXIT

log "debootstrap --variant=minbase $SUITE from $MIRROR (include: $INCLUDE) into $ROOTFS"
start=$SECONDS
"${SUDO[@]}" "$DEBOOTSTRAP" --variant=minbase --include="$INCLUDE" "$SUITE" "$ROOTFS" "$MIRROR" \
    >"$WORK/debootstrap.log" 2>&1 || { tail -n 30 "$WORK/debootstrap.log" >&2; die "debootstrap failed"; }
log "debootstrap done in $((SECONDS - start)) s"

log "trimming the root (apt lists and caches, docs, man pages, host files)"
"${SUDO[@]}" sh -eu -c '
    cd "$1"
    rm -rf var/lib/apt/lists/* var/cache/apt/*.bin var/cache/apt/archives/*.deb \
           var/cache/debconf/*-old var/lib/dpkg/*-old var/log/* \
           usr/share/doc/* usr/share/man/* usr/share/info/*
    # debootstrap copies these from the host; Docker provides its own at run time.
    : > etc/resolv.conf
    echo localhost > etc/hostname
    # Same apt settings as the official Debian images: keep the image small when extended.
    printf "%s\n" "APT::Install-Recommends \"false\";" > etc/apt/apt.conf.d/90-docker-no-recommends
    printf "%s\n" "DPkg::Post-Invoke { \"rm -f /var/cache/apt/archives/*.deb || true\"; };" \
        "Dir::Cache::pkgcache \"\"; Dir::Cache::srcpkgcache \"\";" > etc/apt/apt.conf.d/docker-clean
' sh "$ROOTFS"

log "importing into Docker as $IMAGE"
start=$SECONDS
# /dev, /proc, /sys, /run and /tmp are provided by the runtime; ship them empty.
"${SUDO[@]}" tar -C "$ROOTFS" --numeric-owner \
    --exclude='./dev/*' --exclude='./proc/*' --exclude='./sys/*' --exclude='./run/*' --exclude='./tmp/*' \
    -cf - . \
  | docker import \
      --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
      --change 'ENV LANG=C.UTF-8' \
      --change 'CMD ["/bin/bash"]' \
      --change "LABEL org.opencontainers.image.description=debootstrap-minbase-$SUITE-python3" \
      --message "debootstrap --variant=minbase --include=$INCLUDE $SUITE" \
      - "$IMAGE" >/dev/null
log "import done in $((SECONDS - start)) s"

py="$(docker run --rm "$IMAGE" python3 --version 2>&1)" || die "the new image cannot run python3: $py"
size="$(docker image inspect -f '{{.Size}}' "$IMAGE")"
log "built $IMAGE: $py, $((size / 1000000)) MB"
