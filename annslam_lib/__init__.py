"""annslam_lib: the library behind the annslam course on EKF-SLAM for a car-like vehicle
with an ANN landmark model. Folders are layers, bottom to top (:data:`LAYERS`); a module
imports only from its own layer and the layers below it:

- ``models``: geometry, the vehicle, motion and observation models, uncertainty
- ``data``: records, the registry of real runs, download, loaders, the simulator
- ``perception``: beacons and trees from sensor data, data association
- ``slam``: the EKF (efficient and dense), its configuration, the run loop, dead reckoning
- ``evaluation``: trajectory and map errors, consistency, the run summary, timing
- ``ann``: the landmark network (training set, network, save/load, evaluation)
- ``plots``: one style module and the shared figures
- ``smoothing``: the same run as a factor graph, and the EKF compared with it
- ``paper``: the paper's printed equations, the errata, the study, its figures and report
- ``chapters``: one companion module per notebook (explorers, chapter-only figures)
- ``grading``: the exercises' checks
- ``course``: release, grading, the student workspace, the command line

Below every layer: ``_checks`` (input validation), ``_settings`` (every ``ANNSLAM_*``
environment variable), ``_lazy`` and ``_cache`` (the study cache). Importing this package imports nothing heavy: each layer loads when it is used.
"""

#: The layers, bottom to top: the one statement of the order (README.md, MAINTAINING.md and
#: tests/test_layout.py read it).
LAYERS = ("models", "data", "perception", "slam", "evaluation", "ann", "plots", "smoothing",
          "paper", "chapters", "grading", "course")


def __getattr__(name: str):
    """``__version__``: the installed distribution's version, read from its metadata the first
    time it is asked for. Its one source is ``version`` in pyproject.toml's ``[project]``
    (CITATION.cff and CHANGELOG.md repeat it; tests/test_version.py checks they agree)."""
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("annslam")
        except PackageNotFoundError:      # the folder put on sys.path, never installed
            value = "0+unknown"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
