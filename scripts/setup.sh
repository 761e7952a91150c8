#!/usr/bin/env bash
# Sets up whatever is missing for the TLT stack, from this repository's own files only:
#   1. Debian packages listed in requirements/apt.txt (those of the role)
#   2. a virtual environment (.venv, or $TLT_VENV) with the role's pinned Python dependencies
#   3. the wheels' CMake include paths rewritten for this interpreter (see docs/setup.md)
#   4. msgs/ generated with rosidl and installed into the venv: the standard interface packages no
#      wheel provides (msgs/standard/: tf2_msgs), then tlt_interfaces
#   5. this project installed into the venv in editable mode
#   6. the live viewer's three.js, from the npm registry with npm ci (src/tlt_common/live_viewer/web)
# Stages 3 and 4 belong to the roles that run ROS nodes; the ground role skips them. Stage 6
# belongs to the roles that serve the live view (twin, dev).
# Each stage records a stamp (a hash of its inputs) only after it succeeded, and is skipped when
# its stamp matches, so a second run that finds everything in place takes seconds and a run that
# failed half-way is redone, never trusted.
#
#   scripts/setup.sh [--role ROLE] [--print-requirements]
#
# ROLE (or $TLT_ROLE) is what this computer runs (docs/setup.md, "Roles"): ground (the GSW, CLI and
# GUI), robot (driver nodes and agents), vision, twin, or dev (everything and the test tools, the
# default). --print-requirements names the role's requirement files, one a line, and installs nothing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${TLT_VENV:-$ROOT/.venv}"
PYTHON="${TLT_PYTHON:-python3.11}"
STAMPS="$VENV/.tlt-stamps"
BUILD="$ROOT/build"
ROLE="${TLT_ROLE:-dev}"
ROS_PREFIX="${TLT_ROS_PREFIX:-}"
PRINT_REQUIREMENTS=0

say() { printf '[setup] %s\n' "$*"; }
fail() { printf '[setup] FAILED: %s\n' "$*" >&2; exit 1; }
# Any command that fails without its own message still says where.
arm_err_trap() { trap 'fail "command at scripts/setup.sh line $LINENO exited with $?"' ERR; }
arm_err_trap

# hash_of FILE... : one hash over the named files' contents and names.
hash_of() { (cd "$ROOT" && sha256sum "$@" | sha256sum | cut -c1-16); }
stamp_ok() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS" && printf '%s' "$2" >"$STAMPS/$1"; }

# pip_install ARGS... : pip install into the venv; on failure show the end of pip's log.
pip_install() {
    local log="$VENV/.pip-install.log"
    "$VENV/bin/python" -m pip install --disable-pip-version-check "$@" >"$log" 2>&1 || {
        grep -v "^WARNING: Location 'file:" "$log" | tail -30 >&2
        fail "pip install $* (full log: $log)"
    }
}

# --- roles -----------------------------------------------------------------------------------
while [ $# -gt 0 ]; do
    case "$1" in
        --role) [ $# -ge 2 ] || fail "--role needs a value"; ROLE=$2; shift 2 ;;
        --role=*) ROLE=${1#--role=}; shift ;;
        --print-requirements) PRINT_REQUIREMENTS=1; shift ;;
        -h | --help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
        *) fail "unknown argument $1 (usage: scripts/setup.sh [--role ROLE] [--print-requirements])" ;;
    esac
done

# role_requirements ROLE : the requirement files pip installs for ROLE, one a line. Each pin lives
# in exactly one file under requirements/; requirements/runtime.txt names them all.
role_requirements() {
    case "$1" in
        ground) printf '%s\n' requirements/base.txt requirements/ground.txt ;;
        robot) printf '%s\n' requirements/base.txt requirements/ros.txt requirements/robot.txt ;;
        vision) printf '%s\n' requirements/base.txt requirements/ros.txt requirements/images.txt \
            requirements/vision.txt ;;
        twin) printf '%s\n' requirements/base.txt requirements/ros.txt requirements/images.txt \
            requirements/twin.txt ;;
        dev) printf '%s\n' requirements/runtime.txt requirements/dev.txt ;;
        *) return 1 ;;
    esac
}
# The modules each role's import check loads: one a pinned dependency stands for.
role_imports() {
    case "$1" in
        ground) echo 'PySide6, pyqtgraph, matplotlib, py_trees, spacepackets, yaml' ;;
        robot) echo 'rclpy, py_trees, serial, dynamixel_sdk, rtde_control, ompl, pinocchio, coal, scipy, spacepackets, mcap, foxglove' ;;
        vision) echo 'rclpy, torch, cv2, scipy, spacepackets, mcap, foxglove' ;;
        twin) echo 'rclpy, mujoco, cv2, scipy, spacepackets, mcap, foxglove' ;;
        dev) echo 'rclpy, py_trees, serial, dynamixel_sdk, rtde_control, cv2, torch, ompl, pinocchio, mujoco, spacepackets, PySide6, foxglove, pytest' ;;
    esac
}
# Whether ROLE runs ROS nodes, so needs msgs/ built into its venv.
role_runs_ros() { [ "$1" != ground ]; }
# The free space (GiB) the role's first pip install asks for: what it installs plus pip's unpacking.
role_min_free_gib() {
    case "$1" in
        ground) echo 2 ;;
        *) echo 5 ;;
    esac
}

role_requirements "$ROLE" >/dev/null || fail "unknown role $ROLE (ground, robot, vision, twin or dev)"
if [ "$PRINT_REQUIREMENTS" = 1 ]; then
    role_requirements "$ROLE"
    exit 0
fi
mapfile -t REQUIREMENTS < <(role_requirements "$ROLE")
# ROS 2 Jazzy built from source into $TLT_ROS_PREFIX (scripts/setup_aarch64.sh build, on the
# Jetsons, where the ros-jazzy-* wheels have no aarch64 builds): its environment stands in for
# the pins that requirements/aarch64.txt routes through colcon.
if [ -n "$ROS_PREFIX" ]; then
    [ -f "$ROS_PREFIX/setup.bash" ] || fail "TLT_ROS_PREFIX=$ROS_PREFIX has no setup.bash \
(scripts/setup_aarch64.sh build makes one)"
    trap - ERR
    set +eu
    # shellcheck disable=SC1091
    . "$ROS_PREFIX/setup.bash"
    set -eu
    arm_err_trap
fi
# The files pip reads: the role's and those they include (-r).
requirement_files() {
    local f inc
    for f in "$@"; do
        echo "$f"
        while read -r inc; do
            requirement_files "$(dirname "$f")/$inc"
        done < <(sed -n -e 's/^[[:space:]]*-r[[:space:]]*//p' "$ROOT/$f")
    done
}

# pip_input : the requirement lines pip installs with a ROS prefix: those of the role's files less
# the pins requirements/aarch64.txt routes through colcon.
pip_input() {
    local routed f line name
    routed=" $(sed -e 's/#.*//' "$ROOT/requirements/aarch64.txt" | awk '$2 == "colcon" {printf "%s ", tolower($1)}')"
    for f in $(requirement_files "${REQUIREMENTS[@]}"); do
        while read -r line; do
            name=$(printf '%s' "${line%%[[=<>!~;@ ]*}" | tr '[:upper:]_.' '[:lower:]--')
            [[ $routed == *" $name "* ]] || printf '%s\n' "$line"
        done < <(sed -e 's/[[:space:]]*#.*//' -e '/^[[:space:]]*-r/d' -e '/^[[:space:]]*$/d' "$ROOT/$f")
    done
}

# --- 1. Debian packages ----------------------------------------------------------------------
apt_stage() {
    local missing=()
    local pkg roles
    # A line is a package, then the roles that need it; none named: every role. Dev takes them all.
    while read -r pkg roles; do
        [ -z "$pkg" ] && continue
        if [ -n "$roles" ] && [ "$ROLE" != dev ] && [[ " $roles " != *" $ROLE "* ]]; then
            continue
        fi
        if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
            missing+=("$pkg")
        fi
    done < <(sed -e 's/#.*//' "$ROOT/requirements/apt.txt")
    [ ${#missing[@]} -eq 0 ] && return 0
    # Where packages cannot be installed here, say so and go on: the later stages fail with their
    # own message if they need one, and the rest (a GUI on an X display, MuJoCo offscreen, ...)
    # fails where it is used. requirements/apt.txt says what needs each package.
    local why=""
    if ! command -v apt-get >/dev/null 2>&1; then
        why="apt-get is not available on this system"
    elif [ "$(id -u)" -ne 0 ]; then
        why="not root"
    else
        say "installing Debian packages: ${missing[*]}"
        if ! DEBIAN_FRONTEND=noninteractive apt-get update -qq >/dev/null; then
            why="apt-get update failed"
        elif ! DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
            "${missing[@]}" >/dev/null; then
            why="apt-get install failed"
        fi
    fi
    [ -z "$why" ] && return 0
    APT_MISSING="${missing[*]}"
    printf '[setup] WARNING: Debian packages NOT installed (%s): %s\n' "$why" "$APT_MISSING" >&2
    printf '[setup] WARNING: install them with the system package manager; requirements/apt.txt says what needs each\n' >&2
}
APT_MISSING=""

# --- 2. virtual environment and pinned dependencies ------------------------------------------
venv_stage() {
    if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import sys' 2>/dev/null; then
        command -v "$PYTHON" >/dev/null || fail "$PYTHON not found (set TLT_PYTHON to a Python 3.11)"
        "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
            || fail "$PYTHON is not Python 3.11"
        say "creating virtual environment $VENV"
        rm -rf "$VENV"
        "$PYTHON" -m venv "$VENV" || fail "python -m venv $VENV"
    fi
    local h
    # The role is part of the stamp: another role on the same venv installs what it lacks (pip
    # removes nothing, so a venv that held dev keeps it all; a lean role wants a fresh venv).
    h=$ROLE-$(hash_of $(requirement_files "${REQUIREMENTS[@]}"))
    [ -z "$ROS_PREFIX" ] || h="$h-ros-$(hash_of requirements/aarch64.txt)-$(printf '%s' "$ROS_PREFIX" | sha256sum | cut -c1-8)"
    stamp_ok pip "$h" && return 0
    rm -f "$STAMPS/pip" "$STAMPS/cmake-paths" "$STAMPS/msgs" "$STAMPS/project"
    # Fail before pip does: it runs out of room half-way through with only "No space left on device".
    local free_kib need_gib=${TLT_MIN_FREE_GIB:-$(role_min_free_gib "$ROLE")}
    free_kib=$(df -Pk "$VENV" | awk 'NR == 2 {print $4}')
    [ "$free_kib" -ge $(( need_gib * 1024 * 1024 )) ] || fail "the pinned Python dependencies of the \
$ROLE role need about ${need_gib} GiB free for $VENV (docs/setup.md, \"Roles\": what each installs, and \
pip's unpacking); $(( free_kib / 1024 )) MiB free there"
    say "installing the pinned Python dependencies of the $ROLE role (first run: minutes)"
    local args=() f
    if [ -n "$ROS_PREFIX" ]; then
        mkdir -p "$STAMPS"
        pip_input >"$STAMPS/requirements-without-ros.txt"
        args=(-r "$STAMPS/requirements-without-ros.txt")
    else
        for f in "${REQUIREMENTS[@]}"; do args+=(-r "$ROOT/$f"); done
    fi
    pip_install "${args[@]}"
    "$VENV/bin/python" -m pip check >/dev/null 2>&1 || {
        "$VENV/bin/python" -m pip check | head -20 >&2
        fail "pip install ${args[*]} left broken dependencies"
    }
    "$VENV/bin/python" -c "import $(role_imports "$ROLE")" || fail "a pinned dependency does not import"
    stamp_set pip "$h"
}

# --- 3. include-path rewrite -----------------------------------------------------------------
cmake_paths_stage() {
    local h
    h=$(cat "$STAMPS/pip")
    stamp_ok cmake-paths "$h" && return 0
    local py_inc np_inc
    py_inc=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
    np_inc=$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')
    say "rewriting the wheels' CMake include paths for $py_inc"
    # The wheels were built on another machine; their exported CMake files name its paths.
    # Nothing left to rewrite (a venv updated in place) is fine: grep's "no match" is not an error.
    { grep -rlE '/opt/python/cp311-cp311/' "$VENV/share" --include='*.cmake' 2>/dev/null || true; } \
        | while read -r f; do
            sed -i \
                -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_inc#g" \
                -e "s#/opt/python/cp311-cp311/include/python3.11#$py_inc#g" "$f"
        done
    stamp_set cmake-paths "$h"
}

# --- 4. interface packages -------------------------------------------------------------------
# build_interfaces NAME SOURCE : generate and install one rosidl package into the venv.
build_interfaces() {
    local name=$1 src=$2
    local log="$BUILD/msgs/$name/build.log"
    mkdir -p "$BUILD/msgs/$name"
    # The ROS packages are in the venv (the wheels), or also under a ROS prefix and the paths its
    # setup.bash set.
    local prefixes=$VENV ament=$VENV
    if [ -n "$ROS_PREFIX" ]; then
        prefixes="$VENV:$ROS_PREFIX${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
        ament="$VENV:$ROS_PREFIX${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    fi
    (
        export PATH="$VENV/bin:$PATH"
        export AMENT_PREFIX_PATH="$ament" CMAKE_PREFIX_PATH="$prefixes"
        cd "$BUILD/msgs/$name"
        cmake "$src" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
            -DCMAKE_PREFIX_PATH="${prefixes//:/;}" -DCMAKE_INSTALL_PREFIX="$VENV" \
            -DPython3_EXECUTABLE="$VENV/bin/python" \
            && make -j"$(nproc)" install
    ) >"$log" 2>&1 || { tail -30 "$log" >&2; fail "building $name from ${src#"$ROOT"/} (full log: $log)"; }
}

msgs_stage() {
    local h
    h=$(cd "$ROOT" && { cat "$STAMPS/pip"; find msgs -type f | sort | xargs sha256sum; } \
        | sha256sum | cut -c1-16)
    stamp_ok msgs "$h" && return 0
    rm -f "$STAMPS/msgs"
    rm -rf "$BUILD/msgs"
    local pkg
    for pkg in "$ROOT"/msgs/standard/*/; do
        pkg=${pkg%/}
        say "building ${pkg#"$ROOT"/} into the venv"
        build_interfaces "$(basename "$pkg")" "$pkg"
    done
    say "building msgs/ (tlt_interfaces) into the venv"
    build_interfaces tlt_interfaces "$ROOT/msgs"
    "$VENV/bin/python" -c 'import tf2_msgs.msg, tlt_interfaces.msg, tlt_interfaces.srv, tlt_interfaces.action' \
        || fail "the interface packages were built but do not import"
    stamp_set msgs "$h"
}

# --- 5. this project --------------------------------------------------------------------------
project_stage() {
    local h
    # The checkout is part of the stamp: a venv shared with another checkout ($TLT_VENV) must
    # point its editable install at this one's sources.
    h=$(hash_of pyproject.toml)-$(printf '%s' "$ROOT" | sha256sum | cut -c1-8)
    stamp_ok project "$h" && return 0
    say "installing the tlt project (editable)"
    pip_install --no-deps --no-build-isolation -e "$ROOT"
    "$VENV/bin/python" -c 'import tlt_common' || fail "pip install -e . (the tlt project)"
    stamp_set project "$h"
}

# --- 6. the live viewer's browser dependencies ------------------------------------------------
# three.js for tlt-live-viewer's page, at the version and hash its package-lock.json pins, installed
# beside the page (web/node_modules, not committed). Where npm is missing or the registry cannot be
# reached, set-up warns and goes on: only the viewer needs it, and it says so when started.
web_stage() {
    local web="$ROOT/src/tlt_common/live_viewer/web"
    local h
    # node_modules lies in the checkout, so the checkout is part of the stamp (as for the project).
    h=$(hash_of src/tlt_common/live_viewer/web/package.json src/tlt_common/live_viewer/web/package-lock.json)
    h="$h-$(printf '%s' "$ROOT" | sha256sum | cut -c1-8)"
    stamp_ok web "$h" && [ -f "$web/node_modules/three/build/three.module.js" ] && return 0
    rm -f "$STAMPS/web"
    local log="$BUILD/live-viewer-npm.log"
    if ! command -v npm >/dev/null 2>&1; then
        WEB_MISSING="three.js for tlt-live-viewer: npm not found"
    else
        say "installing the live viewer's three.js (npm ci)"
        mkdir -p "$BUILD"
        if (cd "$web" && npm ci --ignore-scripts --no-audit --no-fund) >"$log" 2>&1; then
            stamp_set web "$h"
            return 0
        fi
        tail -20 "$log" >&2
        WEB_MISSING="three.js for tlt-live-viewer: npm ci failed (full log: $log)"
    fi
    printf '[setup] WARNING: %s; the rest of the stack does not need it (docs/live-view.md)\n' "$WEB_MISSING" >&2
}
WEB_MISSING=""

# One set-up at a time (a main job and a test run started together share the venv).
mkdir -p "$(dirname "$VENV")"
exec 9>"$VENV.setup-lock"
flock 9

apt_stage
venv_stage
if role_runs_ros "$ROLE"; then
    cmake_paths_stage
    msgs_stage
fi
project_stage
case "$ROLE" in
    dev | twin) web_stage ;;
esac
missing=""
if [ -n "$APT_MISSING" ]; then
    missing="Debian packages missing: $APT_MISSING${WEB_MISSING:+; $WEB_MISSING}"
elif [ -n "$WEB_MISSING" ]; then
    missing="$WEB_MISSING"
fi
READY="ready: $VENV"
[ "$ROLE" = dev ] || READY="$READY (role $ROLE)"
if [ -n "$missing" ]; then
    say "$READY (but $missing)"
else
    say "$READY"
fi
