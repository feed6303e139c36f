#!/usr/bin/env bash
# The README's two set-up-free commands on a fresh machine (Python 3.10+ and pip):
#   ./run.sh demo   a chamber run by an agent, recorded to bags/
#   ./run.sh test   the test suite
# The first call builds .venv from the pinned requirements; later calls reuse it until the
# requirement files change. Other subcommands: bench, eval, shell.
set -euo pipefail
cd "$(dirname "$0")"

VENV=${GROWSPACE_VENV:-.venv}
PY="$VENV/bin/python"
# Cyclone DDS stays on loopback with multicast off unless the user chose otherwise.
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$PWD/config/cyclonedds.xml}

setup() {
  local stamp
  stamp="$VENV/.installed-$(cat requirements.txt requirements-nodeps.txt src/*/setup.py \
    | sha256sum | cut -c1-16)"
  [ -f "$stamp" ] && return
  echo "Setting up $VENV (first run only) ..." >&2
  python3 -m venv "$VENV"
  "$PY" -m pip install -q --disable-pip-version-check -r requirements.txt
  "$PY" -m pip install -q --disable-pip-version-check --no-deps -r requirements-nodeps.txt
  "$PY" -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation \
    -e src/growspace_sim -e src/growspace_gym_bridge
  touch "$stamp"
}

cmd=${1:-help}
[ $# -gt 0 ] && shift
case "$cmd" in
  demo) setup; exec "$PY" -m growspace_sim.demo "$@" ;;
  test) setup; exec "$PY" -m pytest -q tests "$@" ;;
  bench) setup; exec "$PY" -m growspace_sim.bench "$@" ;;
  eval) setup; exec "$PY" -m growspace_sim.evaluate "$@" ;;
  shell) setup; exec "$VENV/bin/bash" -c "source $VENV/bin/activate && exec bash" ;;
  *) sed -n '2,6p' "$0"; exit 2 ;;
esac
