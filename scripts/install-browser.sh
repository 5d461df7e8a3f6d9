#!/usr/bin/env bash
# Install Debian's headless Chromium, which the browser tests (JupyterLab UI, --report page) drive
# through Playwright with executable_path=/usr/bin/chromium. Playwright never downloads a browser.
# Idempotent: when chromium is already there it prints so and exits. Needs root (or sudo).
set -euo pipefail

if command -v chromium >/dev/null 2>&1; then
    echo "install-browser: chromium already installed at $(command -v chromium); nothing to do."
    exit 0
fi

# shellcheck source=apt-wait.sh
source "$(dirname "$0")/apt-wait.sh"   # waits for another apt-get instead of failing
apt_sudo install-browser
apt_install_missing install-browser chromium
command -v chromium >/dev/null 2>&1 || { echo "install-browser: chromium still missing after apt-get" >&2; exit 1; }
echo "install-browser: done; chromium at $(command -v chromium)"
