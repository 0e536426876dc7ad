# Sourced by the build scripts: sets PY, the host Python that builds wheels ($TLTRACK_PYTHON, else
# the project's .venv/bin/python, else python3), and dies (the caller's `die`) if it has no pip.
if [[ -n "${TLTRACK_PYTHON:-}" ]]; then
    PY="$TLTRACK_PYTHON"
elif [[ -x "$ROOT/.venv/bin/python" ]]; then
    PY="$ROOT/.venv/bin/python"
else
    PY="python3"
fi
"$PY" -m pip --version >/dev/null 2>&1 || die "$PY has no pip"
