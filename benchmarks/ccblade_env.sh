#!/usr/bin/env bash
# Create (or reuse) the separate benchmark environment with WISDEM's CCBlade.
#
#   benchmarks/ccblade_env.sh            # -> <repo>/.bench-venv
#
# CCBlade is a reference for `make bench` only, never a dependency of calib.
# By default only what wisdem.ccblade.ccblade needs is installed: the pinned WISDEM
# binary wheel WITHOUT its dependencies (its package __init__ pulls in OpenMDAO and
# the whole WISDEM glue code, about 140 packages / 1.3 GB; CCBlade itself needs only
# numpy and scipy), plus pinned numpy and scipy.  ccblade_runner.py imports
# wisdem.ccblade.ccblade without running wisdem/__init__.py.  ~260 MB, ~15 s.
#
# Environment:
#   PYTHON=python3                    interpreter used to create the venv
#   CALIB_BENCH_VENV=<repo>/.bench-venv
#   CALIB_BENCH_FULL_WISDEM=1         install WISDEM with all its dependencies instead
#
# The pinned WISDEM wheel exists for CPython 3.11-3.14 on x86_64 glibc >= 2.28 Linux, so
# no compiler is needed; elsewhere the script stops with a clear message (the PyPI sdist
# of wisdem 4.2.9 does not build, so there is no source fallback).
# Idempotent: a stamp file records the pinned set; a second run only checks the import.
set -euo pipefail

WISDEM_VERSION=4.2.9
NUMPY_VERSION=2.4.6
SCIPY_VERSION=1.17.1

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/.." && pwd)"
VENV="${CALIB_BENCH_VENV:-$ROOT/.bench-venv}"
PYTHON="${PYTHON:-python3}"
MODE=minimal
[ "${CALIB_BENCH_FULL_WISDEM:-0}" = 1 ] && MODE=full
WANT="wisdem==$WISDEM_VERSION numpy==$NUMPY_VERSION scipy==$SCIPY_VERSION mode=$MODE"
STAMP="$VENV/.ccblade-installed"
PY="$VENV/bin/python"

log() { echo "[ccblade_env] $*" >&2; }
die() { echo "[ccblade_env] ERROR: $*" >&2; exit 1; }

check_import() {
    "$PY" "$HERE/ccblade_runner.py" --check >/dev/null 2>&1
}

# --- already there? -----------------------------------------------------------
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ] && [ -x "$PY" ] && check_import; then
    log "CCBlade environment ready: $VENV ($WANT)"
    exit 0
fi

# one installer at a time
mkdir -p "$VENV"
if command -v flock >/dev/null 2>&1; then
    exec 9>"$VENV/.install.lock"
    flock 9
    if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ] && [ -x "$PY" ] && check_import; then
        log "CCBlade environment ready: $VENV ($WANT)"
        exit 0
    fi
fi

command -v "$PYTHON" >/dev/null 2>&1 || die "no '$PYTHON' on PATH (set PYTHON=...)"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
    || die "$PYTHON is $("$PYTHON" -V 2>&1); WISDEM $WISDEM_VERSION needs Python >= 3.11"

start=$(date +%s)
log "creating $VENV with $("$PYTHON" -V 2>&1) and installing WISDEM $WISDEM_VERSION ($MODE) ..."
rm -f "$STAMP"
if [ ! -x "$PY" ]; then
    "$PYTHON" -m venv "$VENV" || die "python -m venv failed (on Debian: apt-get install python3-venv)"
fi
PIP=("$PY" -m pip install --quiet --disable-pip-version-check)

wheel_expected() {  # PyPI has wisdem 4.2.9 wheels for CPython 3.11-3.14, manylinux_2_28 x86_64
    "$PY" - <<'PYEOF'
import platform, sys
libc, ver = platform.libc_ver()
try:
    glibc = tuple(int(x) for x in ver.split(".")[:2])
except ValueError:
    glibc = (0, 0)
ok = (sys.implementation.name == "cpython" and (3, 11) <= sys.version_info[:2] <= (3, 14)
      and platform.machine() == "x86_64" and libc == "glibc" and glibc >= (2, 28))
sys.exit(0 if ok else 1)
PYEOF
}

install_wisdem() {  # $1: extra pip flags (e.g. --no-deps)
    if wheel_expected; then
        # a wheel exists for this platform: a failure here is a network / index problem
        "${PIP[@]}" $1 --only-binary=wisdem "wisdem==$WISDEM_VERSION" \
            || die "pip could not install the wisdem==$WISDEM_VERSION wheel (is PyPI reachable?)"
        return 0
    fi
    # No wheel for this platform. The wisdem 4.2.9 sdist on PyPI does not build (its
    # setup.py runs `meson setup` but the sdist has no top-level meson.build), so there is
    # no source fallback, and no Fortran compiler is needed or installed.
    die "no wisdem==$WISDEM_VERSION wheel for this platform ($("$PY" -c 'import platform,sys; print(sys.implementation.name, platform.python_version(), platform.machine(), *platform.libc_ver())')).
PyPI has wheels only for CPython 3.11-3.14 on x86_64 Linux with glibc >= 2.28, and its sdist does not build.
Rerun with such an interpreter, e.g. PYTHON=python3.12 $0"
}

if [ "$MODE" = full ]; then
    install_wisdem ""
else
    "${PIP[@]}" "numpy==$NUMPY_VERSION" "scipy==$SCIPY_VERSION" \
        || die "pip could not install numpy==$NUMPY_VERSION scipy==$SCIPY_VERSION"
    install_wisdem "--no-deps"
fi

"$PY" "$HERE/ccblade_runner.py" --check >&2 \
    || die "WISDEM installed but 'wisdem.ccblade.ccblade' does not import (see above)"
echo "$WANT" >"$STAMP"
end=$(date +%s)
log "done in $((end - start)) s; $VENV is $(du -sh "$VENV" | cut -f1)"
