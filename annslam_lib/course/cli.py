"""Command line of the course library.

    python -m annslam_lib data fetch  [name ...]   download + verify (default: the course's datasets)
    python -m annslam_lib data verify [name ...]   check the sha256 of every file; exit 1 on a problem
    python -m annslam_lib data where  [name ...]   print the data directory (or dataset folders)
    python -m annslam_lib data list   [name ...]   print the datasets and how to cite them
    python -m annslam_lib errata                   the paper's errata as a Markdown table
    python -m annslam_lib reproduce --out DIR [--fast] [--seeds N]   the paper's figures 5-8 and results table
    python -m annslam_lib release [--out student] [NOTEBOOK ...]   student versions (no solutions)
    python -m annslam_lib publish --repo R --branch B              the release as a git branch
    python -m annslam_lib launch --hub URL --repo R --branch B [CH] nbgitpuller links for a hub
    python -m annslam_lib grade SUBMISSION ... [--json FILE]        grade submissions (sandboxed)
    python -m annslam_lib exercises                                the graded exercises per notebook
    python -m annslam_lib pacing                                   estimated student time per chapter
    python -m annslam_lib workspace                                write/refresh your student copy
    python -m annslam_lib running --root DIR                       is a course server open on DIR?
    python -m annslam_lib hub --class FILE [--port P]              a JupyterHub for a class (root)
    python -m annslam_lib class release|collect|grade|feedback CH  the instructor's steps on it
    python -m annslam_lib class export [CH]                        the gradebook for the LMS
    python -m annslam_lib class add|drop NAME                      a student joins or leaves
    python -m annslam_lib --version                                the course's version

Each command is a sub-parser added by an ``_add_<command>`` function that sets ``func``;
``main`` returns the exit code.
"""
from __future__ import annotations

import argparse
import json
import sys

from .. import __version__
from ..data import fetch
from ..data import registry
from ..data.fetch import DataError

_DATA_ACTIONS = {
    "fetch": "download missing or corrupt files and verify them",
    "verify": "check every file's sha256 (no download); exit code 1 on any problem",
    "where": "print the data directory (or, given names, the dataset folders)",
    "list": "print the datasets with their citation and licence",
}


def _data(args: argparse.Namespace) -> int:
    try:
        default = registry.core() if args.action in ("fetch", "verify") else registry.DATASETS
        entries = [registry.get(n) for n in args.names or default]
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.action == "where":
        print("\n".join(str(fetch.data_dir() / e.folder) for e in entries) if args.names
              else fetch.data_dir())
        return 0
    if args.action == "list":
        for e in entries:
            size = sum(f.size for f in e.files) / 1e6
            print(f"{e.name}  ({e.folder}/, {len(e.files)} files, {size:.1f} MB)\n"
                  f"    cite:    {e.citation}\n    licence: {e.licence}\n    source:  {e.source}")
        return 0
    status = 0
    for e in entries:
        try:
            folder = fetch.ensure(e.name, repair=True) if args.action == "fetch" else fetch.verify(e.name)
            print(f"{e.name}: OK, {len(e.files)} files verified in {folder}")
        except DataError as err:
            print(f"{e.name}: FAILED\n{err}", file=sys.stderr)
            status = 1
    return status


def _add_data(sub) -> None:
    p = sub.add_parser("data", help="download, verify and locate the course data",
                       description="\n".join(f"{k:7s} {v}" for k, v in _DATA_ACTIONS.items())
                       + f"\n\nData directory: ${fetch.ENV_DIR}, else the per-user cache. "
                       f"Download mirror: ${fetch.ENV_URL}/<folder>/<file>.",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=list(_DATA_ACTIONS))
    p.add_argument("names", nargs="*", metavar="name",
                   help=f"dataset(s) among {', '.join(registry.DATASETS)} (default for fetch "
                        f"and verify: {', '.join(registry.core())}; for where and list: all)")
    p.set_defaults(func=_data)


def _errata(args: argparse.Namespace) -> int:
    from ..paper import errata_markdown

    print(errata_markdown())
    return 0


def _add_errata(sub) -> None:
    p = sub.add_parser("errata", help="print the paper's errata with their numerical proofs")
    p.set_defaults(func=_errata)


def _cache(args: argparse.Namespace) -> int:
    from .. import _cache as cache

    folder = cache.cache_dir()
    if folder is None:
        print("the study cache is off (ANNSLAM_CACHE=off)")
        return 0
    if args.action == "clear":
        print(f"removed {cache.clear()} entries from {folder}")
        return 0
    if args.action == "warm":
        from pathlib import Path

        from .warm import warm_studies

        course = Path(__file__).resolve().parents[2] / "notebooks"     # in a checkout
        where = Path(args.notebooks) if args.notebooks else course
        notebooks = sorted(where.glob("*.ipynb"))
        if not notebooks:
            print(f"cache warm: no notebooks in {where} (name them with --notebooks DIR)",
                  file=sys.stderr)
            return 2
        out = warm_studies(notebooks)
        print(f"{folder}: {out['entries']} entries ({out['new']} new) after Run All of "
              f"{out['notebooks']} notebooks")
        return 0
    entries = sorted(folder.glob("*.pkl")) if folder.is_dir() else []
    size = sum(p.stat().st_size for p in entries)
    print(f"{folder}: {len(entries)} entries, {size / 1e6:.1f} MB")
    return 0


def _add_cache(sub) -> None:
    p = sub.add_parser("cache", help="where the study cache is and how large; clear it; "
                       "fill it (warm)",
                       description="Heavy studies of the notebooks are computed once per "
                       "machine and kept here (ANNSLAM_CACHE, else the per-user cache; "
                       "ANNSLAM_CACHE=off turns it off). An entry is used only for the same "
                       "library code and arguments. 'warm' runs every notebook once to fill "
                       "it (a class's shared folder: ANNSLAM_CLASS_CACHE, read-only).")
    p.add_argument("action", choices=["where", "clear", "warm"])
    p.add_argument("--notebooks", metavar="DIR",
                   help="warm: the notebooks to run (default: the course's notebooks/)")
    p.set_defaults(func=_cache)


def _reproduce(args: argparse.Namespace) -> int:
    from ..paper.report import reproduce

    reproduce(args.out, fast=args.fast, seeds=args.seeds)
    return 0


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return n


def _compare(args: argparse.Namespace) -> int:
    from ..smoothing.compare import write_comparison
    from ..smoothing.solve import SolverError

    try:
        path = write_comparison(args.out, args.datasets, every=args.every)
    except (SolverError, ValueError) as e:
        print(f"compare: {e}", file=sys.stderr)
        return 1
    rows = json.loads(path.read_text())
    print("| dataset | estimator | path RMSE (m) | aligned (m) | map aligned (m) | CPU (s) | CPU with its inputs (s) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        m = "-" if r["map_rmse_aligned_m"] is None else f"{r['map_rmse_aligned_m']:.3f}"
        print(f"| {r['dataset']} | {r['estimator']} | {r['traj_rmse_m']:.2f} | "
              f"{r['traj_rmse_aligned_m']:.2f} | {m} | {r['cpu_s']:.1f} | {r['cpu_total_s']:.1f} |")
    print(f"wrote {path} and {path.with_suffix('.png')}")
    return 0


def _add_compare(sub) -> None:
    p = sub.add_parser("compare", help="EKF-SLAM against iSAM2 and batch smoothing (GTSAM) on "
                       "the Car Park and Victoria Park",
                       description="Writes DIR/comparison.json (one row per dataset and "
                       "estimator: path RMSE against the valid GPS fixes, absolute and aligned, "
                       "map RMSE against the surveyed beacons, CPU seconds) and "
                       "DIR/comparison.png (chapter 10).")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--datasets", nargs="+", default=["car_park", "victoria_park"],
                   choices=["car_park", "victoria_park"], help="default: both")
    p.add_argument("--every", type=_positive_int, default=1, metavar="N",
                   help="iSAM2 updates every N poses (default 1: every scan)")
    p.set_defaults(func=_compare)


def _add_reproduce(sub) -> None:
    p = sub.add_parser("reproduce", help="run the paper's Car Park experiment end to end: "
                       "Figures 5-8 and the results table",
                       description="EKF-SLAM beacons only -> training set -> ANN training -> "
                       "ANN-enhanced EKF-SLAM -> natural-feature EKF-SLAM; writes "
                       "fig5_map.png .. fig8_regression.png, results.csv and results.md.")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--fast", action="store_true",
                   help="a short simulated run instead of the Car Park (seconds; for CI)")
    p.add_argument("--seeds", type=_positive_int, default=5, metavar="N",
                   help="training seeds of the ANN (default 5)")
    p.set_defaults(func=_reproduce)


def _course_notebooks() -> list:
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "notebooks"  # the repository (editable install)
    found = sorted(folder.glob("*.ipynb"))
    if not found:
        raise SystemExit(f"no notebooks found in {folder}: name the instructor notebooks to release")
    return found


def _release(args: argparse.Namespace) -> int:
    from .release import ReleaseError, exercises, release

    try:
        written = release(args.notebooks or _course_notebooks(), args.out)
    except ReleaseError as e:
        print(f"release: {e}", file=sys.stderr)
        return 1
    for path in written:
        n = len(exercises(path, instructor=False))
        print(f"{path}  ({n} autograded exercise{'s' if n != 1 else ''})")
    return 0


def _add_release(sub) -> None:
    p = sub.add_parser("release", help="write student versions of the notebooks (solutions "
                       "replaced by a NotImplementedError stub, hidden tests removed)",
                       description="The same transformation as nbgrader's generate_assignment "
                       "on the cell sources; outputs are cleared.")
    p.add_argument("notebooks", nargs="*", metavar="NOTEBOOK",
                   help="instructor notebooks (default: every notebook of the course)")
    p.add_argument("--out", default="student", metavar="DIR",
                   help="output folder (default ./student; never the notebooks' own folder)")
    p.set_defaults(func=_release)


def _publish(args: argparse.Namespace) -> int:
    from .publish import PublishError, publish
    from .release import ReleaseError

    try:
        done = publish(args.repo, args.branch, args.notebooks or _course_notebooks(),
                       message=args.message, course_repo=args.course_repo,
                       course_ref=args.course_ref)
    except (PublishError, ReleaseError, ValueError) as e:
        print(f"publish: {e}", file=sys.stderr)
        return 2
    print(f"== {done.summary()}")
    return 0


def _add_publish(sub) -> None:
    p = sub.add_parser("publish", help="publish the student release as a branch of a git "
                       "repository (for nbgitpuller, Binder and Colab)")
    p.add_argument("notebooks", nargs="*", metavar="NOTEBOOK",
                   help="instructor notebooks (default: every notebook of the course)")
    p.add_argument("--repo", required=True, help="the release's git repository (a folder, "
                   "file:// or a remote address you can push to)")
    p.add_argument("--branch", required=True, help="the branch to publish to, e.g. fall-2027")
    p.add_argument("--message", help="the commit's message")
    p.add_argument("--course-repo", help="the course's own repository (https): each chapter "
                   "Colab can run then starts with the cell that installs the library there")
    p.add_argument("--course-ref", default="main", help="its branch or tag (default main)")
    p.set_defaults(func=_publish)


def _launch(args: argparse.Namespace) -> int:
    from .launch import nbgitpuller_link

    names = [c if c.endswith(".ipynb") else f"{c}.ipynb" for c in args.chapters] or [None]
    try:
        for name in names:
            print(nbgitpuller_link(args.hub, args.repo, args.branch, name))
    except ValueError as e:
        print(f"launch: {e}", file=sys.stderr)
        return 2
    return 0


def _add_launch(sub) -> None:
    p = sub.add_parser("launch", help="print the nbgitpuller link that puts the student "
                       "release (a chapter, or the whole course) into every student's home "
                       "on a JupyterHub with nbgitpuller")
    p.add_argument("chapters", nargs="*", metavar="CHAPTER",
                   help="chapters to open, e.g. 05_ekf_slam (none: the course's folder)")
    p.add_argument("--hub", required=True, help="the hub's address, e.g. https://hub.example.edu")
    p.add_argument("--repo", required=True, help="the published release's repository (https)")
    p.add_argument("--branch", required=True, help="its branch or tag")
    p.set_defaults(func=_launch)


def _site(args: argparse.Namespace) -> int:
    from .launch import LaunchTargets
    from .site import build

    try:
        targets = LaunchTargets(release_repo=args.release_repo, release_ref=args.release_ref,
                                hub=args.hub, course_repo=args.course_repo,
                                course_ref=args.course_ref)
        if targets.release_repo is None and (targets.hub or targets.course_repo):
            raise ValueError("the launch links open the student release: name it with "
                             "--release-repo")
        report = build(args.out, targets=targets, quiet=not args.verbose)
    except (ValueError, RuntimeError) as e:
        print(f"annslam site: {e}", file=sys.stderr)
        return 2
    print(f"== {report.summary()}; open {report.out / 'index.html'}")
    return 0


def _add_site(sub) -> None:
    p = sub.add_parser("site", help="build the course's static website (every chapter from its "
                       "stored outputs, the guides, search, math; no request to another host)",
                       description="Launch links are added for what is named: the student "
                       "release (a git repository or branch of `release`'s output) with the "
                       "class hub (nbgitpuller), Binder (built from the course repository's "
                       "binder/) and Colab.")
    p.add_argument("--out", default="site", metavar="DIR", help="output folder (default ./site)")
    p.add_argument("--release-repo", metavar="URL", help="the published student release (https)")
    p.add_argument("--release-ref", default="main", metavar="REF", help="its branch or tag")
    p.add_argument("--hub", metavar="URL", help="the class hub's address (nbgitpuller links)")
    p.add_argument("--course-repo", metavar="URL",
                   help="this course's repository (Binder's environment, Colab's library)")
    p.add_argument("--course-ref", default="main", metavar="REF", help="its branch or tag")
    p.add_argument("--verbose", action="store_true", help="show Sphinx's progress")
    p.set_defaults(func=_site)


def _grade(args: argparse.Namespace) -> int:
    from .grader import GradingEnvironmentError, grade_batch
    from .sandbox import NO_SANDBOX_WARNING, Limits

    limits = Limits(cpu_seconds=int(args.cpu), memory_bytes=int(args.memory * (1 << 30)),
                    cell_timeout=float(args.timeout), call_timeout=float(args.call_timeout),
                    deadline=float(args.deadline))
    if args.isolation == "none":
        print(f"annslam grade: WARNING: {NO_SANDBOX_WARNING}", file=sys.stderr)
    try:
        results = grade_batch(args.submissions, instructor_dir=args.instructor,
                              json_path=args.json, limits=limits, isolation=args.isolation)
    except GradingEnvironmentError as e:
        from .integrity import inert
        print(f"annslam grade: the grading environment is broken, so no submission was "
              f"scored from here on: {inert(str(e))}", file=sys.stderr)
        return 3
    bad = [r for r in results if not r.graded]
    total = len(results)
    print(f"graded {total - len(bad)} of {total} submission(s)"
          + (f"; {len(bad)} could not be graded (reasons above)" if bad else "")
          + (f"; scores in {args.json}" if args.json else ""))
    return 1 if bad else 0


def _positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        x = 0.0
    if not x > 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return x


def _add_grade(sub) -> None:
    from .sandbox import ISOLATIONS, Limits

    d = Limits()
    p = sub.add_parser("grade", help="grade submitted notebooks (sandboxed; scores decided "
                       "outside the student's code)",
                       description="Each submission is graded against the instructor notebook "
                       "of the same file name: only its solution cells are taken, run in a "
                       "sandboxed kernel with limits, and every test cell (hidden tests "
                       "included) is run by the grader with the student's functions behind "
                       "proxies. A submission that cannot be graded is reported with its "
                       "reason and the others go on. Exit code 1 if any could not be graded, 3 if the "
                       "grading environment itself is broken (named; no score given).")
    p.add_argument("submissions", nargs="+", metavar="SUBMISSION",
                   help="notebooks, or folders to search (e.g. an nbgrader submitted/ folder: "
                        "submitted/<student>/<assignment>/<notebook>.ipynb)")
    p.add_argument("--json", metavar="FILE", help="write every submission's result as JSON "
                   "(rewritten after each one)")
    p.add_argument("--instructor", metavar="DIR", help="folder of the instructor notebooks "
                   "(default: the course's notebooks/)")
    p.add_argument("--isolation", choices=ISOLATIONS, default="auto",
                   help="auto or bwrap (default): the bubblewrap sandbox, student code without "
                        "privilege; grading stops, naming the fix, where it cannot be made. "
                        "none: student code with your own rights, only for a trusted notebook")
    p.add_argument("--timeout", type=_positive_float, default=d.cell_timeout, metavar="S",
                   help=f"per-cell time-out (default {d.cell_timeout:g} s)")
    p.add_argument("--call-timeout", type=_positive_float, default=d.call_timeout, metavar="S",
                   help=f"per call of a student's function (default {d.call_timeout:g} s)")
    p.add_argument("--deadline", type=_positive_float, default=d.deadline, metavar="S",
                   help=f"wall-clock deadline per notebook (default {d.deadline:g} s)")
    p.add_argument("--cpu", type=_positive_float, default=d.cpu_seconds, metavar="S",
                   help=f"CPU seconds per kernel (default {d.cpu_seconds})")
    p.add_argument("--memory", type=_positive_float, default=d.memory_bytes / (1 << 30),
                   metavar="GB", help=f"address space per kernel (default "
                   f"{d.memory_bytes / (1 << 30):g} GB)")
    p.set_defaults(func=_grade)


def _exercises(args: argparse.Namespace) -> int:
    from .release import exercise_table

    print(exercise_table(args.notebooks or _course_notebooks()))
    return 0


def _pacing(args: argparse.Namespace) -> int:
    from .pacing import pacing_table

    print(pacing_table(args.notebooks or _course_notebooks()))
    return 0


def _add_pacing(sub) -> None:
    p = sub.add_parser("pacing", help="print the estimated student time per chapter (Markdown)")
    p.add_argument("notebooks", nargs="*", metavar="NOTEBOOK")
    p.set_defaults(func=_pacing)


def _add_exercises(sub) -> None:
    p = sub.add_parser("exercises", help="print the autograded exercises per notebook (Markdown)")
    p.add_argument("notebooks", nargs="*", metavar="NOTEBOOK")
    p.set_defaults(func=_exercises)


def _workspace(args: argparse.Namespace) -> int:
    from .workspace import sync, work_dir

    try:
        report = sync(args.dir or work_dir())
    except ValueError as e:
        print(f"workspace: {e}", file=sys.stderr)
        return 2
    print(f"== {report.summary()}", file=sys.stderr)
    for name in report.kept:
        print(f"   {name}: you have changed it, so it is left as it is (the course's current "
              f"version: ./course.sh release --out DIR notebooks/{name})", file=sys.stderr)
    print(report.folder)
    return 0


def _add_workspace(sub) -> None:
    p = sub.add_parser("workspace", help="write the student versions into your own course "
                       "folder (new chapters added; notebooks you changed are never overwritten)")
    p.add_argument("--dir", metavar="DIR", help="the folder (default $ANNSLAM_WORK, else "
                   "work/<user> in the course checkout)")
    p.set_defaults(func=_workspace)


def _running(args: argparse.Namespace) -> int:
    from .workspace import running_servers

    servers = running_servers(args.root)
    for s in servers:
        token = f"?token={s['token']}" if s.get("token") else ""
        print(f"== the course is already open on {args.root}: {s['url'].rstrip('/')}/lab{token} "
              f"(server pid {s.get('pid')}); open that address, or stop that server first "
              f"(Ctrl-C in its terminal, or kill {s.get('pid')})")
    return 0 if servers else 1


def _add_running(sub) -> None:
    p = sub.add_parser("running", help="exit 0 and print the address if a Jupyter server of "
                       "this user already serves DIR, else exit 1")
    p.add_argument("--root", required=True, metavar="DIR")
    p.set_defaults(func=_running)


def _hub(args: argparse.Namespace) -> int:
    from .hub import HubError, HubLayout, check_name
    from .hub.setup import prepare, start

    try:
        check_name(args.instructor)
        if args.image_files:
            from pathlib import Path

            from .hub.setup import image_files

            image_files(HubLayout(Path(args.image_files).resolve()))
            return 0
        if args.prepare_only:
            prepare(HubLayout.from_env(), args.class_file, args.instructor,
                    studies=not args.no_studies)
            return 0
        if args.class_file is None:
            raise HubError("name the class: --class FILE (the students' user names, one a line)")
        start(HubLayout.from_env(), args.class_file, port=args.port, instructor=args.instructor,
              studies=not args.no_studies, lti_file=args.lti)
    except HubError as e:
        print(f"hub: {e}", file=sys.stderr)
        return 2
    return 0                                   # not reached: start() becomes JupyterHub


def _add_hub(sub) -> None:
    p = sub.add_parser("hub", help="a JupyterHub for a class on 127.0.0.1 (as root; the hub "
                       "folder is $ANNSLAM_HUB_DIR, default /srv/annslam-hub)")
    p.add_argument("--class", dest="class_file", metavar="FILE",
                   help="the students' user names, one a line")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--instructor", default="instructor", metavar="NAME",
                   help="the instructor's account (default instructor)")
    p.add_argument("--lti", metavar="FILE", help="students log in from the LMS with LTI 1.3, "
                   "with the settings of FILE (INSTRUCTOR.md); without it, a shared password")
    p.add_argument("--prepare-only", action="store_true",
                   help="set up the hub folder (students' environment, release, data, class "
                   "studies, proxy) and stop")
    p.add_argument("--no-studies", action="store_true",
                   help="skip computing the class's studies (each student's first Run All "
                   "of chapters 05-08 then computes them; the tests' hub does this)")
    p.add_argument("--image-files", metavar="DIR",
                   help="write what a single-user image holds (student versions, role "
                   "configurations) into DIR, for hub/z2jh/Dockerfile and binder/, and stop")
    p.set_defaults(func=_hub)


def _class(args: argparse.Namespace) -> int:
    from .grader import GradingEnvironmentError
    from .hub import HubError, HubLayout, give_course
    from .hub.classroom import ACTIONS

    try:
        layout = HubLayout.from_env()
        if args.action in ("add", "drop"):
            from .hub import roster

            if args.chapter is None:
                raise HubError(f"name the student: class {args.action} NAME")
            print(getattr(roster, args.action)(layout, args.chapter, args.instructor))
            return 0
        if args.chapter is None and args.action != "export":
            raise HubError("name the chapter, e.g. 03_observation")
        try:
            ACTIONS[args.action](layout, args.chapter)
        finally:                     # what root wrote there, back to the instructor's account
            give_course(layout, args.instructor)
    except GradingEnvironmentError as e:
        from .integrity import inert
        print(f"class grade: the grading environment is broken, so no submission was scored "
              f"from here on: {inert(str(e))}", file=sys.stderr)
        return 3
    except HubError as e:
        print(f"class {args.action}: {e}", file=sys.stderr)
        return 2
    return 0


def _add_class(sub) -> None:
    p = sub.add_parser("class", help="the instructor's steps on the class hub (as root): "
                       "release, collect, grade, feedback of one chapter; export the "
                       "gradebook for the LMS; add or drop a student")
    p.add_argument("action", choices=["release", "collect", "grade", "feedback", "export",
                                      "add", "drop"])
    p.add_argument("chapter", nargs="?", help="a notebook's name without .ipynb, e.g. "
                   "03_observation (export: every graded chapter when left out); add, "
                   "drop: the student's user name")
    p.add_argument("--instructor", default="instructor", metavar="NAME",
                   help="the instructor's account, owner of the course folder (default "
                   "instructor)")
    p.set_defaults(func=_class)


def _singleuser(args: argparse.Namespace) -> int:
    import os
    from pathlib import Path

    from .workspace import sync

    rest = args.rest[1:] if args.rest[:1] == ["--"] else args.rest
    try:
        report = sync(Path.home() / "course", sorted(Path(args.release).glob("*.ipynb")),
                      released=True)
    except (OSError, ValueError) as e:
        print(f"singleuser: your course folder could not be written: {e}", file=sys.stderr)
        return 2
    print(f"== {report.summary()}", file=sys.stderr, flush=True)
    # nbgrader's Assignments panel fetches into the process's working folder, not the
    # server's root: start in ~/course. JupyterLab keeps user settings and workspaces under
    # JUPYTER_CONFIG_DIR, the role's read-only folder here: give them the student's own.
    os.chdir(Path.home() / "course")
    for var, sub in (("JUPYTERLAB_SETTINGS_DIR", "user-settings"),
                     ("JUPYTERLAB_WORKSPACES_DIR", "workspaces")):
        os.environ.setdefault(var, str(Path.home() / ".jupyter" / "lab" / sub))
    exe = Path(sys.executable).parent / "jupyterhub-singleuser"
    os.execv(exe, [str(exe), *rest])
    return 0                                   # not reached


def _add_singleuser(sub) -> None:
    p = sub.add_parser("singleuser", help="(run by the class hub as the student) copy the "
                       "student versions into ~/course, then start jupyterhub-singleuser")
    p.add_argument("--release", required=True, metavar="DIR")
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=_singleuser)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m annslam_lib",
                                     description="annslam course library: data and tools.")
    parser.add_argument("--version", action="version", version=f"annslam {__version__}",
                        help="print the course's version (pyproject.toml, CHANGELOG.md) and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="command")
    _add_data(sub)
    _add_errata(sub)
    _add_cache(sub)
    _add_reproduce(sub)
    _add_compare(sub)
    _add_release(sub)
    _add_publish(sub)
    _add_launch(sub)
    _add_site(sub)
    _add_grade(sub)
    _add_exercises(sub)
    _add_pacing(sub)
    _add_workspace(sub)
    _add_running(sub)
    _add_hub(sub)
    _add_class(sub)
    _add_singleuser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
