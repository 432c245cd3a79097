#!/usr/bin/env bash
# annslam course: one entry point for students, instructors and CI.
#
#   ./course.sh lab [--instructor]  set up, then open JupyterLab on YOUR copy of the course
#                                   (student versions in work/<user>/; --instructor: notebooks/)
#   ./course.sh test                set up and run the whole test suite
#   ./course.sh setup               only set up (venv, CPU torch, packages, data)
#   ./course.sh refresh [NB...]     re-execute notebooks in place (instructors)
#   ./course.sh release [...]       write the student versions (no solutions, no hidden tests)
#   ./course.sh site [--out DIR ...]  build the course's website (instructors; INSTRUCTOR.md)
#   ./course.sh grade SUB...        grade submitted notebooks (instructors)
#   ./course.sh hub --class FILE [--lti F]   a JupyterHub for a class, as root (INSTRUCTOR.md)
#   ./course.sh class ACTION CHAPTER          release|collect|grade|feedback on that hub;
#                                             class add|drop NAME: a student joins or leaves
#
# `test` also installs environment-instructor.txt (nbgrader, playwright, ...).
#
# Environment: PYTHON (interpreter for the venv, default python3: 3.11, 3.12 or 3.13),
# ANNSLAM_VENV (venv folder, default .venv), ANNSLAM_DATA (data folder; default: per-user
# cache), ANNSLAM_TORCH_INDEX (PyTorch CPU wheel index; default PyTorch's own),
# ANNSLAM_WORK (the student's working folder; default work/<user>).
set -euo pipefail
cd "$(dirname "$0")"

# Linux and macOS only (a Windows shell such as Git Bash or MSYS2 has no POSIX venv layout):
# say so in one line and where to go instead. ANNSLAM_UNAME overrides uname (tests).
case "${ANNSLAM_UNAME:-$(uname -s)}" in
    Linux|Darwin) ;;
    *) echo "annslam: ./course.sh runs on Linux and macOS, not on ${ANNSLAM_UNAME:-$(uname -s)}: use WSL 2, the class hub or the container (README, 'Windows and other laptops')" >&2
       exit 2 ;;
esac

PY=${PYTHON:-python3}
VENV=${ANNSLAM_VENV:-.venv}
VPY="$VENV/bin/python"
export ANNSLAM_VENV="$VENV"

# Fixed BLAS threads: last digits of floats depend on the thread count, and the
# stored notebook outputs are compared digit for digit.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0

setup() {  # setup [extra requirement files...]
    local t0=$SECONDS
    command -v "$PY" >/dev/null 2>&1 || {
        echo "annslam: no Python interpreter '$PY'. Install Python 3.11 and run: PYTHON=/path/to/python3.11 ./course.sh setup" >&2
        exit 1
    }
    "$PY" scripts/install.py --venv "$VENV" "$@"
    echo "== data: checking (and on first use downloading) the course's datasets"
    "$VPY" -m annslam_lib data fetch
    echo "== set-up done in $((SECONDS - t0)) s"
}

# The grader's own bytecode, from its first import on, in a folder of this user's that no
# submission can write: never the __pycache__ next to the library's sources.
grader_bytecode() {
    local d="${XDG_CACHE_HOME:-$HOME/.cache}/annslam/grader-bytecode"
    mkdir -p "$d" && chmod 700 "$d" && export PYTHONPYCACHEPREFIX="$d"
}

lab() {
    local root instructor=0 args=()
    for a in "$@"; do
        if [ "$a" = "--instructor" ]; then instructor=1; else args+=("$a"); fi
    done
    setup
    if [ "$instructor" = 1 ]; then
        root="$PWD/notebooks"
    else
        root=$("$VPY" -m annslam_lib workspace)   # writes what is new, prints the folder
    fi
    # One course server per folder: a second `lab` says where the first one is.
    if "$VPY" -m annslam_lib running --root "$root"; then
        exit 0
    fi
    [ "$(id -u)" = 0 ] && args+=(--allow-root)  # containers often run as root; Jupyter refuses without it
    echo "== opening JupyterLab on $root"
    exec "$VENV/bin/jupyter" lab --ServerApp.root_dir="$root" "${args[@]}" "$root/00_course_map.ipynb"
}

cmd=${1:-lab}
[ $# -gt 0 ] && shift
case "$cmd" in
    setup) setup ;;
    lab) lab "$@" ;;
    test)
        setup environment-instructor.txt environment-hub.txt
        if [ "$(id -u)" = 0 ]; then
            # the class hub's folder for tests/test_hub.py (students' environment, release,
            # data, proxy), outside the checkout: students' accounts must reach it
            ANNSLAM_HUB_DIR=${ANNSLAM_HUB_TEST_DIR:-/tmp/annslam-hub-test} \
                "$VPY" -m annslam_lib hub --prepare-only --no-studies ||
                echo "== the class hub could not be prepared (above): tests/test_hub.py says why"
        fi
        t0=$SECONDS
        "$VENV/bin/ruff" check .
        "$VPY" -m pytest "$@"
        echo "== tests done in $((SECONDS - t0)) s"
        ;;
    refresh)
        setup
        "$VPY" scripts/refresh_notebooks.py "$@"
        ;;
    release)
        setup
        "$VPY" -m annslam_lib release "$@"
        ;;
    site)
        setup environment-instructor.txt
        "$VPY" -m annslam_lib site "$@"
        ;;
    grade)
        setup
        grader_bytecode
        "$VPY" -m annslam_lib grade "$@"
        ;;
    hub)
        setup environment-hub.txt
        exec "$VPY" -m annslam_lib hub "$@"
        ;;
    class)
        setup environment-hub.txt
        grader_bytecode
        exec "$VPY" -m annslam_lib class "$@"
        ;;
    *)
        echo "usage: ./course.sh [lab [--instructor]|test|setup|refresh|release|site|grade|hub|class]" >&2
        exit 2
        ;;
esac
