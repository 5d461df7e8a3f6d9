#!/usr/bin/env bash
# Install Debian's headless Chromium, which the browser tests (JupyterLab UI, --report page) drive
# through Playwright with executable_path=/usr/bin/chromium. Playwright never downloads a browser.
# Idempotent: when chromium is already there it prints so and exits. Needs root (or sudo).
set -euo pipefail

if command -v chromium >/dev/null 2>&1; then
    echo "install-browser: chromium already installed at $(command -v chromium); nothing to do."
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
        SUDO="sudo"
    else
        echo "install-browser: need root (or sudo) to run apt-get; re-run as root." >&2
        exit 1
    fi
fi
export DEBIAN_FRONTEND=noninteractive
# shellcheck source=apt-wait.sh
source "$(dirname "$0")/apt-wait.sh"   # wait for another apt-get instead of failing
if ! apt-cache policy chromium 2>/dev/null | grep -q 'Candidate: [0-9]'; then
    apt_get install-browser update
fi
apt_get install-browser install -y --no-install-recommends chromium
command -v chromium >/dev/null 2>&1 || { echo "install-browser: chromium still missing after apt-get" >&2; exit 1; }
echo "install-browser: done; chromium at $(command -v chromium)"
