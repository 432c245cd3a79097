"""Interactive explorers for the notebooks (ipywidgets), one module per chapter.

- ``data`` (00): ``scan_scrubber`` through the raw laser scans
- ``kinematics`` (01): ``kinematics_explorer``, exact arc against Euler steps
- ``offset`` (02): ``offset_explorer``, the laser offset a, b against GPS on a real turn
- ``observation`` (03): ``measurement_explorer``, a predicted measurement and its covariance
- ``landmarks`` (04): ``beacon_scrubber`` and ``gate_explorer``
- ``slam`` (05): ``slam_explorer``, the Car Park filter up to a time, with its noise settings
- ``victoria`` (06): a time slider over the stored Victoria Park run
- ``ann`` (07): hidden size and seed over precomputed trainings
- ``verdict`` (08): ``r_scale_explorer``, the noise R declared to the beacons-only filter against
  the ANN run's variance and map error (the control experiment of the verdict)

Each explorer is built from a pure function (testable without a browser) plus a
drawing callback; the widget keeps the latest result in ``widget.holder["summary"]``
so a headless test can move the slider and check what a student would see.
"""
from . import ann, data, kinematics, landmarks, observation, offset, slam, verdict, victoria
from .data import scan_scrubber, scan_summary

__all__ = ["ann", "data", "kinematics", "landmarks", "observation", "offset", "slam", "verdict", "victoria",
           "scan_scrubber", "scan_summary"]
