#!/usr/bin/env bash
# The README's two set-up-free commands on a fresh machine (Python 3.10+ and pip):
#   ./run.sh demo   a chamber run by an agent, recorded to bags/
#   ./run.sh test   the test suite
# The first call builds .venv from the pinned requirements; later calls reuse it until the
# requirement files change. Other subcommands: bench, eval, and test-compat (the core tests on
# numpy 1.26, as Jazzy ships it, in .venv-compat).
set -euo pipefail
cd "$(dirname "$0")"

VENV=${GROWSPACE_VENV:-.venv}
PY="$VENV/bin/python"
# Cyclone DDS stays on loopback with multicast off unless the user chose otherwise.
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$PWD/config/cyclonedds.xml}

# setup VENV REQUIREMENTS: build VENV once per content of the requirement files.
setup() {
  local venv=$1 requirements=$2 stamp
  stamp="$venv/.installed-$(cat "$requirements" requirements-nodeps.txt src/*/setup.py \
    | sha256sum | cut -c1-16)"
  [ -f "$stamp" ] && return
  echo "Setting up $venv (first run only) ..." >&2
  python3 -m venv "$venv"
  local pip=("$venv/bin/python" -m pip install -q --disable-pip-version-check)
  "${pip[@]}" -r "$requirements"
  "${pip[@]}" --no-deps -r requirements-nodeps.txt
  "${pip[@]}" --no-deps -e src/growspace_sim -e src/growspace_gym_bridge
  touch "$stamp"
}

cmd=${1:-help}
[ $# -gt 0 ] && shift
case "$cmd" in
  demo) setup "$VENV" requirements.txt; exec "$PY" -m growspace_sim.demo "$@" ;;
  test) setup "$VENV" requirements.txt; exec "$PY" -m pytest -q tests "$@" ;;
  bench) setup "$VENV" requirements.txt; exec "$PY" -m growspace_sim.bench "$@" ;;
  eval) setup "$VENV" requirements.txt; exec "$PY" -m growspace_sim.evaluate "$@" ;;
  test-compat)
    setup .venv-compat requirements-compat.txt
    exec .venv-compat/bin/python -m pytest -q tests/test_core.py tests/test_envs.py \
      tests/test_digits.py tests/test_agents.py "$@" ;;
  *) sed -n '2,8p' "$0"; exit 2 ;;
esac
