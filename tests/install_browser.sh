#!/usr/bin/env bash
# Set-up step of `make test` (target test-browser): Debian's chromium and chromium-driver for
# tests/test_browser_report.py. Quick when both are on PATH; installs them with apt-get when
# run as root or with passwordless sudo; otherwise prints the command to run and leaves the
# machine alone (the browser tests then skip, or fail under CI=true).
set -euo pipefail
if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then
    exit 0
fi
packages="chromium chromium-driver"
if [ "$(id -u)" = 0 ]; then
    sudo=""
elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
    sudo="sudo -n"
else
    echo "test-browser: chromium/chromedriver not found and no root: run 'sudo apt-get install $packages'" >&2
    exit 0
fi
echo "test-browser: installing $packages (Debian packages) ..."
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get -o DPkg::Lock::Timeout=300 update -q >/dev/null
$sudo apt-get -o DPkg::Lock::Timeout=300 install -y -q --no-install-recommends $packages >/dev/null
echo "test-browser: installed $(chromium --version 2>/dev/null | head -1)"
