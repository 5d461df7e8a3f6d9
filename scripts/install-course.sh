#!/usr/bin/env bash
# The course's first install, one for the hand-out's start.sh and the kit's course command (sourced by both;
# the hand-out carries this file). Never quiet for long: a line per step, every 5 s a line while a step goes on,
# and the installer's own list of packages.
#   WHO=start.sh; source scripts/install-course.sh; install_course [SPEC]     (SPEC: what to install, default -e .)
# The install is uv's (from PyPI, with pip's resolver rules and pip's configured indexes, many times faster than
# pip); if uv cannot be had or fails, pip's. DTSCAL_INSTALLER=pip uses pip alone.
WHO="${WHO:-install-course}"
PYTHON="${PYTHON:-python3}"
say() { echo "$WHO: $*" >&2; }
ticking() {  # ticking WHAT COMMAND...: run COMMAND, saying every 5 s that WHAT goes on (never silent for long)
  local what=$1 rc=0 tick
  shift
  (n=0; while sleep 5; do n=$((n + 5)); say "... $what ($n s)"; done) &
  tick=$!
  trap 'kill "$tick" 2>/dev/null' EXIT
  "$@" || rc=$?
  kill "$tick" 2>/dev/null || true
  wait "$tick" 2>/dev/null || true
  trap - EXIT
  return "$rc"
}
uv_env() {  # run uv with pip's own settings (index, extra indexes, find-links, constraints, certificate)
  eval "$(.venv/bin/python - <<'PY'
import shlex, subprocess, sys
out = subprocess.run([sys.executable, "-m", "pip", "config", "list"], capture_output=True, text=True).stdout
conf = {}
for line in out.splitlines():  # section.key='value'; the environment (:env:) and install.* win over global.*
    key, _, value = line.partition("=")
    section, _, name = key.rpartition(".")
    rank = {":env:": 3, "install": 2}.get(section, 1)
    if value and rank >= conf.get(name, (0, ""))[0]:
        conf[name] = (rank, value.strip("'\""))
uv = {"index-url": "UV_INDEX_URL", "extra-index-url": "UV_EXTRA_INDEX_URL", "find-links": "UV_FIND_LINKS",
      "constraint": "UV_CONSTRAINT", "cert": "SSL_CERT_FILE", "trusted-host": "UV_INSECURE_HOST",
      "timeout": "UV_HTTP_TIMEOUT", "default-timeout": "UV_HTTP_TIMEOUT"}
for name, (_rank, value) in conf.items():
    if name == "no-index" and value.lower() in ("1", "true", "yes", "on"):
        print('set -- "$@" --no-index')  # uv has no variable for it: the flag, after uv's other arguments
    elif name in uv:
        value = ",".join(value.split()) if name == "find-links" else value
        print(f"export {uv[name]}={shlex.quote(value)}")
print("export UV_INDEX_STRATEGY=unsafe-best-match")  # pip's rule: the best version over every index
PY
)"
  .venv/bin/uv "$@"
}
course_installed() { .venv/bin/python -c 'import dtscal_lib, jupyterlab' 2>/dev/null; }
install_course() {  # install_course [SPEC]: make .venv if needed and install SPEC (default: the course, editable)
  local spec=${1:-.} installed=""
  if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    say "needs Python 3.11 or newer; install it, or run: PYTHON=/path/to/python3.11 bash $WHO"
    return 2
  fi
  say "first run: installing the course into .venv (3 steps; under a minute with the packages cached)"
  if [ ! -x .venv/bin/python ]; then
    say "[1/3] making the course's Python environment in .venv"
    ticking "making .venv" "$PYTHON" -m venv .venv
  else
    say "[1/3] .venv is there; completing it"
  fi
  if [ "${DTSCAL_INSTALLER:-uv}" = uv ]; then
    say "[2/3] getting the uv installer from PyPI into .venv (pip)"
    if ticking "getting uv" .venv/bin/python -m pip install --disable-pip-version-check --progress-bar on uv; then
      say "[3/3] installing the course, JupyterLab and OpenCV with uv (it lists each package)"
      # --compile-bytecode: as pip does by default (uv does not): else the first `import numpy, cv2, jupyterlab`
      # compiles them, a silence of 10 s at load 10 after "installed" (benchmarks/bench_start.py)
      if ticking "installing with uv" uv_env pip install --compile-bytecode --python .venv/bin/python -e "$spec"; then
        installed=uv
      else
        say "uv could not install the course; trying pip instead"
      fi
    else
      say "uv is not available for this computer; installing with pip instead"
    fi
  fi
  if [ -z "$installed" ]; then
    say "[2/3] updating pip"
    ticking "updating pip" .venv/bin/python -m pip install --disable-pip-version-check --progress-bar on --upgrade pip
    say "[3/3] installing the course, JupyterLab and OpenCV with pip (pip lists each package)"
    ticking "installing with pip" .venv/bin/python -m pip install --disable-pip-version-check --progress-bar on -e "$spec"
  fi
  say "installed"
}
