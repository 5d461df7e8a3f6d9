#!/usr/bin/env bash
# Install mrcal from Debian (bookworm: python3-mrcal 2.2), the peer the kit's calibration and
# uncertainty are measured against (benchmarks/bench_mrcal.py, tests/test_mrcal_peer.py).
#
# Idempotent: when /usr/bin/python3 can already import mrcal it prints so and exits without touching apt.
# Waits up to 10 minutes for another apt/dpkg run to release its lock (saying so) instead of failing.
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

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
        SUDO="sudo"
    else
        echo "install-mrcal: need root (or sudo) to run apt-get; re-run as root." >&2
        exit 1
    fi
fi

export DEBIAN_FRONTEND=noninteractive
# Another apt/dpkg (unattended upgrades, a parallel setup) may hold a lock: wait, saying so, never fail
# at once. apt-get install waits by itself with DPkg::Lock::Timeout (printing "Waiting for cache lock");
# apt-get update does not honour it for the lists lock, so it is retried here.
WAIT=600
APT=(apt-get -o DPkg::Lock::Timeout=$WAIT)

apt_update_waiting() {
    local start=$SECONDS err
    while true; do
        if err=$($SUDO "${APT[@]}" update 2>&1 >/dev/null); then
            return 0
        fi
        if ! grep -q 'Could not get lock\|Unable to lock' <<<"$err" || [ $((SECONDS - start)) -ge $WAIT ]; then
            echo "$err" >&2
            return 1
        fi
        echo "install-mrcal: another apt/dpkg holds the package-list lock; waiting ($((SECONDS - start)) s of at most $WAIT s)"
        sleep 5
    done
}

# refresh the package lists only when apt does not know the package yet
if ! apt-cache policy python3-mrcal 2>/dev/null | grep -q 'Candidate: [0-9]'; then
    echo "install-mrcal: apt does not know python3-mrcal yet; running apt-get update"
    apt_update_waiting
fi

missing=()
for p in "${PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
        missing+=("$p")
    fi
done

if [ "${#missing[@]}" -gt 0 ]; then
    echo "install-mrcal: installing ${missing[*]} (if another apt/dpkg holds the lock, apt waits up to $WAIT s and says so)"
    $SUDO env DEBIAN_FRONTEND=noninteractive "${APT[@]}" install -y --no-install-recommends "${missing[@]}"
fi

if have_all; then
    echo "install-mrcal: done; mrcal $(/usr/bin/python3 -c 'import mrcal; print(mrcal.__file__)')"
else
    echo "install-mrcal: python3-mrcal installed but /usr/bin/python3 cannot import mrcal" >&2
    exit 1
fi
