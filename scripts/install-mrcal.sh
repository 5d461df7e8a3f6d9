#!/usr/bin/env bash
# Install mrcal from Debian (bookworm: python3-mrcal 2.2), the peer the kit's calibration and
# uncertainty are measured against (benchmarks/bench_mrcal.py, tests/test_mrcal_peer.py).
#
# Idempotent: when /usr/bin/python3 can already import mrcal it prints so and exits without touching apt.
# Waits for another apt/dpkg run to release its lock (saying so, scripts/apt-wait.sh) instead of failing.
# Needs root (or sudo). Usage:  scripts/install-mrcal.sh
# mrcal runs on Debian's /usr/bin/python3, not on the project's venv (it is not on PyPI for this
# Python); the kit talks to it through a subprocess exchanging JSON (benchmarks/mrcal_helper.py).
set -euo pipefail

PACKAGES=(python3-mrcal)

have_all() {
    /usr/bin/python3 -c 'import mrcal, numpy; mrcal.optimize; mrcal.projection_uncertainty' >/dev/null 2>&1
}

if have_all; then
    echo "install-mrcal: mrcal already installed ($(/usr/bin/python3 -c 'import mrcal; print(mrcal.__file__)')); nothing to do."
    exit 0
fi

# shellcheck source=apt-wait.sh
source "$(dirname "$0")/apt-wait.sh"   # waits for another apt-get instead of failing
apt_sudo install-mrcal
apt_install_missing install-mrcal "${PACKAGES[@]}"

if have_all; then
    echo "install-mrcal: done; mrcal $(/usr/bin/python3 -c 'import mrcal; print(mrcal.__file__)')"
else
    echo "install-mrcal: python3-mrcal installed but /usr/bin/python3 cannot import mrcal" >&2
    exit 1
fi
