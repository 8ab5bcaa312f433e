#!/usr/bin/env bash
# Quick start entry point: sets up .venv (first run only) and runs the main job or the tests.
#   ./run.sh main [args]   the main job (see README)
#   ./run.sh test [args]   the test suite; with args, one pytest run with them (e.g. -m slow, a file)
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
VENV=.venv
STAMP="$VENV/.installed-$(sha1sum pyproject.toml | cut -c1-12)"
WEB=mrguide/annotation/web
# The annotation page's JavaScript (three.js, urdf-loader, iwer) from npm, exactly as the lockfile says.
WEB_STAMP="$WEB/node_modules/.installed-$(sha1sum "$WEB/package-lock.json" | cut -c1-12)"

# apt_install WHAT PACKAGE...: Debian's packages, when root; otherwise say which to install (and fail).
apt_install() {
  local what=$1
  shift
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "[run.sh] installing Debian's $* for $what..." >&2
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$@" >/dev/null
  else
    echo "[run.sh] $what: 'sudo apt-get install $*'" >&2
    return 1
  fi
}

# missing_debs PACKAGE...: those of the Debian packages that are not installed, one per line.
missing_debs() {
  local p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || echo "$p"
  done
}

if [ ! -f "$STAMP" ]; then
  echo "[run.sh] setting up $VENV (first run takes a few minutes)..." >&2
  "$PY" -m venv "$VENV"
  # torch is pinned to the CPU build; pip installs it first (from the machine's wheel directory where it has one, as
  # pip is configured) so nothing pulls a CUDA build. uv (the dev extra's pin), from PyPI, then installs the rest: it
  # fetches the ~100 packages in parallel, 2.7x faster than pip here, to the same versions (benchmarks/install.py).
  UV=$("$PY" -c 'import tomllib
print(next(r for r in tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["dev"] if r.startswith("uv")))')
  "$VENV/bin/python" -m pip install --quiet --no-compile "torch==2.13.0" "$UV"
  # The workstation profile and the test tools (docs/install.md; a robot PC installs '.[robot]' instead).
  UV_LINK_MODE=copy "$VENV/bin/uv" pip install --quiet --python "$VENV/bin/python" -e ".[train,dev]"
  # The bytecode on every core at once (pip compiles file by file: ~40 s; left to the first imports, every process
  # started before the files are written compiles them again: about a minute of the first test pass). A file that
  # does not compile (a package's Python 2 example) is one nothing imports.
  "$VENV/bin/python" -m compileall -q -j 0 "$VENV"/lib/python3*/site-packages >/dev/null || true
  rm -f "$VENV"/.installed-*
  touch "$STAMP"
fi

if [ ! -f "$WEB_STAMP" ]; then
  if ! command -v npm >/dev/null; then
    apt_install "the annotation page's packages" nodejs npm || exit 1
  fi
  echo "[run.sh] installing the annotation page's npm packages (npm ci)..." >&2
  (cd "$WEB" && npm ci --no-audit --no-fund --loglevel=error)
  touch "$WEB_STAMP"
fi

# TorchInductor compiles the DDPG update with the C++ compiler; without one it runs uncompiled, about twice as slow.
if ! command -v g++ >/dev/null && ! command -v c++ >/dev/null; then
  apt_install "the compiled training update" g++ || true
fi

cmd=${1:-main}
shift || true
case "$cmd" in
  main) exec "$VENV/bin/mrguide" main "$@" ;;
  test)
    # The annotation page's browser tests drive Debian's chromium (never a browser a test tool downloads).
    if [ ! -x /usr/bin/chromium ] && [ -z "${MRGUIDE_CHROMIUM:-}" ]; then
      apt_install "the browser tests (or set MRGUIDE_CHROMIUM)" chromium || true
    fi
    # MuJoCo's offscreen renderer (the MuJoCo cell's HMD) draws through EGL with Mesa's software rasterizer.
    if command -v dpkg-query >/dev/null; then
      mapfile -t EGL < <(missing_debs libegl1 libegl-mesa0 libgl1-mesa-dri)
      if [ ${#EGL[@]} -gt 0 ]; then apt_install "MuJoCo's offscreen renderer" "${EGL[@]}" || true; fi
    fi
    if [ $# -gt 0 ]; then exec "$VENV/bin/python" -m pytest -q "$@"; fi
    # The suite in two passes (pytest-xdist), each on two workers (one per core): first the tests that compute,
    # then those that keep time with threads (simulated CAN bus, dry runs; marked `realtime` by tests/conftest.py),
    # which then share the machine only with each other. A dry run keeps most of a core busy (the simulated
    # devices answer every 4 ms SYNC in Python): on three workers they starved each other into correct safety
    # stops (`loadscope`: each module's tests on one worker, so a module fixture such as the robot venv is built
    # once). When every test the second pass failed had a simulated cell run behind the clock (a machine too busy for
    # real-time dry runs; tests/conftest.py lists the failures), those run again, alone; a failure on time fails.
    # Each pass lists its 15 slowest tests: where the CI's time goes.
    rc=0
    "$VENV/bin/python" -m pytest -q -n 2 --durations=15 -m "not slow and not realtime" || rc=$?
    failed=$(mktemp)
    rt=0
    MRGUIDE_FAILED_REALTIME=$failed "$VENV/bin/python" -m pytest -q -n 2 --dist loadscope --durations=15 -m "not slow and realtime" || rt=$?
    if [ "$rt" = 1 ] && [ -s "$failed" ] && ! grep -qv '^behind ' "$failed"; then
      mapfile -t again < <(cut -d' ' -f2- "$failed" | sort -u)
      echo "[run.sh] ${#again[@]} realtime test(s) failed while a simulated cell ran behind the clock; again, alone:" >&2
      printf '  %s\n' "${again[@]}" >&2
      rt=0
      "$VENV/bin/python" -m pytest -q -p no:cacheprovider "${again[@]}" || rt=$?
    fi
    rm -f "$failed"
    exit "$((rc ? rc : rt))" ;;
  *) echo "usage: ./run.sh {main|test} [args]" >&2; exit 2 ;;
esac
