#!/usr/bin/env bash
# Build a stock zenohd (the Rust router) matching the pinned eclipse-zenoh, for the
# interoperability test. About 7.5 minutes on these machines; kept out of the test run.
set -euo pipefail
VERSION="${ZENOHD_VERSION:-1.10.2}"
if command -v zenohd >/dev/null && zenohd --version 2>/dev/null | grep -q "$VERSION"; then
    echo "zenohd $VERSION already on PATH: $(command -v zenohd)"
    exit 0
fi
command -v cargo >/dev/null || { echo "cargo is needed (rustup)" >&2; exit 1; }
cargo install zenohd --version "$VERSION" --locked
echo "installed: $(command -v zenohd || echo "~/.cargo/bin/zenohd (add it to PATH)")"
