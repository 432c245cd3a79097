#!/usr/bin/env bash
# annslam course: one entry point for students, instructors and CI.
#
#   ./course.sh lab       set up (venv, packages, data) and open JupyterLab on the course
#   ./course.sh test      set up and run the whole test suite (unit tests + every notebook, strict nbval)
#   ./course.sh refresh   re-execute every notebook in place (or the ones named after it)
#   ./course.sh release   write the student versions (no solutions, no hidden tests) into ./student
#   ./course.sh grade NB  run notebooks and score their autograded exercises
#   ./course.sh setup     only set up
#
# `test` also installs environment-instructor.txt (nbgrader, playwright for the browser test).
#
# Environment: PYTHON (interpreter for the venv, default python3, must be >= 3.11),
# ANNSLAM_VENV (venv folder, default .venv), ANNSLAM_DATA (data folder; default: per-user cache).
set -euo pipefail
cd "$(dirname "$0")"

PY=${PYTHON:-python3}
VENV=${ANNSLAM_VENV:-.venv}
VPY="$VENV/bin/python"

# Fixed BLAS threads: last digits of floats depend on the thread count, and the
# stored notebook outputs are compared digit for digit.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0

setup() {  # setup [extra requirement files...]
    local t0=$SECONDS
    "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || {
        echo "annslam needs Python >= 3.11; $("$PY" --version 2>&1) found. Set PYTHON=/path/to/python3.11." >&2
        exit 1
    }
    [ -x "$VPY" ] || "$PY" -m venv "$VENV"
    # Install each requirements file only when it (or pyproject.toml) changed: a stamp of its hash.
    local req want stamp
    for req in environment.txt "$@"; do
        stamp="$VENV/.annslam-installed-${req%.txt}"
        want=$("$VPY" -c 'import hashlib,sys; print(hashlib.sha256(b"".join(open(f,"rb").read() for f in sys.argv[1:])).hexdigest())' pyproject.toml "$req")
        if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
            echo "== installing $req into $VENV"
            "$VPY" -m pip install --disable-pip-version-check -q -r "$req"
            echo "$want" > "$stamp"
        fi
    done
    "$VPY" scripts/check_env.py
    "$VPY" -m annslam_lib data fetch
    echo "== set-up done in $((SECONDS - t0)) s"
}

cmd=${1:-lab}
[ $# -gt 0 ] && shift
case "$cmd" in
    setup) setup ;;
    lab)
        setup
        extra=()
        [ "$(id -u)" = 0 ] && extra+=(--allow-root)  # containers often run as root; Jupyter refuses without it
        exec "$VENV/bin/jupyter" lab --ServerApp.root_dir=notebooks "${extra[@]}" "$@" "$PWD/notebooks/00_course_map.ipynb"
        ;;
    test)
        setup environment-instructor.txt
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
    grade)
        setup
        "$VPY" -m annslam_lib grade "$@"
        ;;
    *)
        echo "usage: ./course.sh [lab|test|refresh|release|grade|setup]" >&2
        exit 2
        ;;
esac
