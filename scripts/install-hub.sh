#!/usr/bin/env bash
# JupyterHub's proxy for the hub test (tests/test_hub.py): configurable-http-proxy from npm, into the
# project-local .hub/node_modules (never global). JupyterHub and nbgitpuller come from PyPI (the [test]
# extra). Idempotent; called by scripts/setup.sh --test. Needs Node.js >= 18 (Debian's nodejs).
set -euo pipefail
cd "$(dirname "$0")/.."
CHP_VERSION="5.3.0"
if [ -x .hub/node_modules/.bin/configurable-http-proxy ]; then
  echo "install-hub: configurable-http-proxy already in .hub/node_modules; nothing to do" >&2
  exit 0
fi
if ! command -v npm >/dev/null 2>&1; then
  echo "install-hub: npm not found; installing Debian's nodejs and npm" >&2
  source scripts/apt-wait.sh
  apt_sudo install-hub
  apt_install_missing install-hub nodejs npm
fi
mkdir -p .hub
echo "install-hub: npm install configurable-http-proxy@$CHP_VERSION into .hub/node_modules" >&2
npm install --prefix .hub --no-audit --no-fund --loglevel=error "configurable-http-proxy@$CHP_VERSION"
.hub/node_modules/.bin/configurable-http-proxy --version >&2
