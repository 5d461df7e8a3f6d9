# Sourced by scripts/install-*.sh: wait for the apt/dpkg locks instead of failing.
#
# Another apt-get (an unattended upgrade, a second install script, a parallel job) holds the dpkg lock
# for minutes; apt-get then stops at once with "Could not get lock /var/lib/dpkg/lock-frontend" (exit 100).
# apt_wait polls the locks (in /proc/locks, so no root is needed to look) every 5 s, saying every 30 s who
# holds them, for up to APT_LOCK_WAIT seconds (default 1200); apt_get runs apt-get after apt_wait, with
# DPkg::Lock::Timeout so that apt-get itself also waits if another one takes the lock in between.

APT_LOCK_FILES=${APT_LOCK_FILES:-"/var/lib/dpkg/lock-frontend /var/lib/dpkg/lock /var/lib/apt/lists/lock /var/cache/apt/archives/lock"}

apt_lock_holders() {  # "PID (command)" of every process holding one of the locks, or nothing
    local f ino pid
    for f in $APT_LOCK_FILES; do
        [ -e "$f" ] || continue
        ino=$(stat -c %i "$f" 2>/dev/null) || continue
        for pid in $(awk -v ino="$ino" '$2 != "->" { n = split($6, a, ":"); if (a[n] == ino) print $5 }' /proc/locks); do
            echo "$pid ($(tr '\0\n' '  ' < "/proc/$pid/cmdline" 2>/dev/null | cut -c1-60))"
        done
    done | sort -u | tr '\n' ' '
}

apt_wait() {  # apt_wait WHO
    local who=${1:-apt} limit=${APT_LOCK_WAIT:-1200} waited=0 holders
    while holders=$(apt_lock_holders); [ -n "$holders" ]; do
        if [ "$waited" -ge "$limit" ]; then
            echo "$who: the apt/dpkg lock is still held after ${limit} s by: $holders; giving up" >&2
            return 1
        fi
        if [ $((waited % 30)) -eq 0 ]; then
            echo "$who: waiting for another package manager to finish (lock held by: $holders; ${waited} s so far, up to ${limit} s)" >&2
        fi
        sleep 5
        waited=$((waited + 5))
    done
}

apt_get() {  # apt_get WHO ARGS...: apt-get ARGS (with $SUDO), after the locks are free
    local who=$1
    shift
    apt_wait "$who"
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout="${APT_LOCK_WAIT:-1200}" "$@"
}

apt_sudo() {  # apt_sudo WHO: set SUDO for apt-get (empty as root), or say how to re-run and fail
    SUDO=""
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1; then
            SUDO="sudo"
        else
            echo "$1: need root (or sudo) to run apt-get; re-run as root." >&2
            return 1
        fi
    fi
    export DEBIAN_FRONTEND=noninteractive
}

apt_install_missing() {  # apt_install_missing WHO PACKAGE...: refresh the lists if apt does not know the
    # first package yet, then install those of the packages that are not installed (waiting for the locks)
    local who=$1 p
    shift
    if ! apt-cache policy "$1" 2>/dev/null | grep -q 'Candidate: [0-9]'; then
        echo "$who: apt does not know $1 yet; running apt-get update"
        apt_get "$who" update
    fi
    local missing=()
    for p in "$@"; do
        if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
            missing+=("$p")
        fi
    done
    if [ "${#missing[@]}" -gt 0 ]; then
        echo "$who: installing ${missing[*]}"
        apt_get "$who" install -y --no-install-recommends "${missing[@]}"
    fi
}
