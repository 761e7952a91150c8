#!/usr/bin/env bash
# The aarch64 route of the stack (the EDU's Jetsons): which pins come as aarch64 wheels, which are
# built from source, and those builds (docs/setup.md, "aarch64").
#
#   scripts/setup_aarch64.sh check [--role ROLE]... [FILE]...
#       A resolver dry run for aarch64 that installs nothing and runs on any computer that reaches
#       the package registry: every pin of the requirement files (default: those of the robot and
#       vision roles, the Jetsons') must be an aarch64 wheel for CPython 3.11, or have a route in
#       requirements/aarch64.txt (an sdist route's source distribution must be on the registry).
#   scripts/setup_aarch64.sh build [--role ROLE]
#       On the aarch64 computer itself, as root, before scripts/setup.sh: the Debian packages the
#       sdist routes build against, and ROS 2 Jazzy from source with colcon into $TLT_ROS_PREFIX
#       (default /opt/tlt/ros-jazzy) for the Python of $TLT_VENV (default .venv). Then
#       `TLT_ROS_PREFIX=... bash scripts/setup.sh --role ROLE` installs the rest from wheels.
#
# $TLT_AARCH64_GLIBC is the target's glibc minor version (default 35: Ubuntu 22.04, JetPack 6); the
# dry run accepts manylinux wheels up to it. It keeps the aarch64 wheels it fetched in
# $TLT_AARCH64_CACHE (default ~/.cache/tlt/aarch64-wheels), so a second run downloads nothing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ROUTES="$ROOT/requirements/aarch64.txt"
PYTHON="${TLT_PYTHON:-python3.11}"
GLIBC_MINOR="${TLT_AARCH64_GLIBC:-35}"
CACHE="${TLT_AARCH64_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/tlt/aarch64-wheels}"

say() { printf '[aarch64] %s\n' "$*"; }
fail() { printf '[aarch64] FAILED: %s\n' "$*" >&2; exit 1; }

# normalise NAME : a requirement name as the registry compares them (PEP 503).
normalise() { printf '%s' "$1" | tr '[:upper:]' '[:lower:]' | sed -E 's/[-_.]+/-/g'; }

# requirement_lines FILE... : the requirement lines of the files and of those they include (-r).
requirement_lines() {
    local f line
    for f in "$@"; do
        [ -f "$f" ] || fail "no requirement file $f"
        while read -r line; do
            line=$(printf '%s' "$line" | sed -E 's/[[:space:]]+#.*//; s/^#.*//; s/^[[:space:]]+//; s/[[:space:]]+$//')
            [ -z "$line" ] && continue
            if [[ $line == -r* ]]; then
                line=${line#-r}
                requirement_lines "$(dirname "$f")/${line#"${line%%[![:space:]]*}"}"
            else
                printf '%s\n' "$line"
            fi
        done <"$f"
    done
}

# route NAME : "KIND WHAT..." from requirements/aarch64.txt, or nothing.
route() {
    local name kind rest
    while read -r name kind rest; do
        [ -z "$name" ] && continue
        if [ "$(normalise "$name")" = "$1" ]; then
            printf '%s %s\n' "$kind" "$rest"
            return 0
        fi
    done < <(sed -e 's/#.*//' "$ROUTES")
}

# role_files ROLE : the role's requirement files, as scripts/setup.sh names them.
role_files() {
    local f
    while read -r f; do printf '%s\n' "$ROOT/$f"; done < <(bash "$ROOT/scripts/setup.sh" --role "$1" --print-requirements)
}

# parse_args ARGS... : fills FILES and ROLES_GIVEN from --role ROLE and FILE arguments.
parse_args() {
    FILES=()
    ROLES_GIVEN=()
    while [ $# -gt 0 ]; do
        case "$1" in
            --role) [ $# -ge 2 ] || fail "--role needs a value"; ROLES_GIVEN+=("$2"); shift 2 ;;
            --role=*) ROLES_GIVEN+=("${1#--role=}"); shift ;;
            -*) fail "unknown option $1" ;;
            *) FILES+=("$1"); shift ;;
        esac
    done
    [ ${#FILES[@]} -gt 0 ] || [ ${#ROLES_GIVEN[@]} -gt 0 ] || ROLES_GIVEN=(robot vision)
    local role f
    for role in "${ROLES_GIVEN[@]}"; do
        while read -r f; do FILES+=("$f"); done < <(role_files "$role")
    done
    return 0
}

# classify : sorts the requirement lines of FILES into WHEELS, SDISTS and COLCON (ROS packages).
classify() {
    WHEELS=()
    SDISTS=()
    SDIST_DEBS=()
    COLCON=()
    local line name kind what seen=" "
    while read -r line; do
        name=$(normalise "${line%%[[=<>!~;@ ]*}")
        [[ $seen == *" $line "* ]] && continue
        seen="$seen$line "
        read -r kind what < <(route "$name") || true
        case "${kind:-}" in
            "")
                # The ros-jazzy-* wheels are pure-Python packages over ros-* wheels, none of which
                # is built for aarch64: a dry run of the pin alone would pass and mislead.
                [[ $name == ros-* ]] && fail "$line: the ROS wheels have no aarch64 builds; give $name a colcon route in ${ROUTES#"$ROOT"/}"
                WHEELS+=("$line")
                ;;
            sdist) SDISTS+=("$line"); read -r -a debs <<<"$what"; SDIST_DEBS+=("${debs[@]}") ;;
            colcon) read -r -a pkgs <<<"$what"; COLCON+=("${pkgs[@]}"); say "colcon  $line (ROS 2 Jazzy from source: $what)" ;;
            *) fail "${ROUTES#"$ROOT"/}: unknown route $kind for $name" ;;
        esac
    done < <(requirement_lines "${FILES[@]}")
}

check() {
    parse_args "$@"
    classify
    TMP=$(mktemp -d)
    trap 'rm -rf "$TMP"' EXIT
    local platforms=(--platform manylinux2014_aarch64) minor
    for minor in $(seq 17 "$GLIBC_MINOR"); do platforms+=(--platform "manylinux_2_${minor}_aarch64"); done
    if [ ${#WHEELS[@]} -gt 0 ]; then
        printf '%s\n' "${WHEELS[@]}" >"$TMP/wheels.txt"
        mkdir -p "$CACHE"
        # One resolution of every wheel pin, each on its own (--no-deps: the pins are the stack's
        # direct dependencies). The wheels stay in $CACHE, where pip finds them the next time and
        # downloads nothing (torch's alone is over 400 MB).
        if ! "$PYTHON" -m pip download --disable-pip-version-check --no-deps --only-binary=:all: \
            "${platforms[@]}" --python-version 3.11 --implementation cp --abi cp311 -d "$CACHE" \
            -r "$TMP/wheels.txt" >"$TMP/pip.log" 2>&1; then
            grep -E '^ERROR' "$TMP/pip.log" | cut -c1-300 >&2
            local missing
            missing=$(sed -n -E 's/.*No matching distribution found for (.*)$/\1/p' "$TMP/pip.log" | head -1)
            fail "${missing:-a pin} has no aarch64 wheel for CPython 3.11 (manylinux up to glibc 2.$GLIBC_MINOR): change the pin or give it a route in ${ROUTES#"$ROOT"/}"
        fi
        sed -n -E 's#^[[:space:]]*(Saved|File was already downloaded) .*/([^/]+)$#[aarch64] wheel   \2#p' "$TMP/pip.log"
    fi
    local pin
    for pin in "${SDISTS[@]}"; do
        "$PYTHON" -m pip download --disable-pip-version-check --no-deps --no-binary=:all: -d "$TMP/sdist" \
            "$pin" >"$TMP/pip.log" 2>&1 || {
            tail -5 "$TMP/pip.log" >&2
            fail "$pin: routed sdist in ${ROUTES#"$ROOT"/}, but the registry has no source distribution of it"
        }
        say "sdist   $(basename "$(ls "$TMP"/sdist/*)") (built on the target against: ${SDIST_DEBS[*]})"
        rm -rf "$TMP/sdist"
    done
    say "ok: ${#WHEELS[@]} pins as aarch64 wheels, ${#SDISTS[@]} from source distributions, the ROS wheels' share from a colcon build of ${#COLCON[@]} ROS packages"
}

# The Debian packages a ROS 2 Jazzy source build of the packages in requirements/aarch64.txt needs on
# Ubuntu 22.04 (Fast DDS and its vendored libraries, rcl's YAML parser, logging), and the Python
# tools of the build, installed into the venv whose interpreter rclpy is built for.
ROS_BUILD_DEBS=(cmake build-essential git python3.11-dev python3.11-venv libasio-dev libtinyxml2-dev
    libssl-dev libyaml-dev libspdlog-dev libacl1-dev liblttng-ust-dev)
# empy and lark-parser at the versions the ROS wheels run rosidl with.
ROS_BUILD_PIP=(colcon-common-extensions vcstool "empy==4.2.1" "lark-parser==0.12.0" catkin-pkg numpy pyyaml setuptools)
ROS_REPOS_URL="${TLT_ROS_REPOS_URL:-https://raw.githubusercontent.com/ros2/ros2/jazzy/ros2.repos}"

build() {
    parse_args "$@"
    [ "$(uname -m)" = aarch64 ] || fail "build runs on the aarch64 computer itself (this one is $(uname -m)); check runs anywhere"
    [ "$(id -u)" -eq 0 ] || fail "build installs Debian packages: run it as root"
    classify
    local venv="${TLT_VENV:-$ROOT/.venv}" prefix="${TLT_ROS_PREFIX:-/opt/tlt/ros-jazzy}"
    local src="${TLT_ROS_SRC:-$ROOT/build/ros-jazzy-src}"
    local debs=("${SDIST_DEBS[@]}")
    [ ${#COLCON[@]} -gt 0 ] && debs+=("${ROS_BUILD_DEBS[@]}")
    if [ ${#debs[@]} -gt 0 ]; then
        say "installing Debian packages: ${debs[*]}"
        DEBIAN_FRONTEND=noninteractive apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${debs[@]}"
    fi
    [ ${#COLCON[@]} -gt 0 ] || { say "ready: nothing of ROS to build; pip builds ${SDISTS[*]:-nothing} from source in scripts/setup.sh"; return 0; }
    [ -x "$venv/bin/python" ] || "$PYTHON" -m venv "$venv"
    "$venv/bin/python" -m pip install --disable-pip-version-check -q "${ROS_BUILD_PIP[@]}"
    mkdir -p "$src/src"
    if [ ! -f "$src/ros2.repos" ]; then
        say "fetching the ROS 2 Jazzy sources ($ROS_REPOS_URL)"
        curl -fsSL "$ROS_REPOS_URL" -o "$src/ros2.repos.part" && mv "$src/ros2.repos.part" "$src/ros2.repos"
    fi
    (cd "$src" && "$venv/bin/vcs" import --skip-existing src <ros2.repos)
    say "building ROS 2 Jazzy (${COLCON[*]} and what they depend on) into $prefix"
    (
        cd "$src"
        export PATH="$venv/bin:$PATH"
        colcon build --merge-install --install-base "$prefix" --packages-up-to "${COLCON[@]}" \
            --cmake-args -DBUILD_TESTING=OFF -DCMAKE_BUILD_TYPE=Release \
            -DPython3_EXECUTABLE="$venv/bin/python" -DPYTHON_EXECUTABLE="$venv/bin/python"
    )
    say "ready: $prefix; next: TLT_ROS_PREFIX=$prefix TLT_VENV=$venv bash scripts/setup.sh --role ${ROLES_GIVEN[0]:-robot}"
}

case "${1:-}" in
    check) shift; check "$@" ;;
    build) shift; build "$@" ;;
    -h | --help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed -e '$d' -e 's/^# \{0,1\}//' ;;
    *) fail "usage: scripts/setup_aarch64.sh check|build [--role ROLE]... [FILE]..." ;;
esac
