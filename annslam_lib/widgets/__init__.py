"""Interactive explorers for the notebooks (ipywidgets), one module per chapter.

- ``data`` (00): ``scan_scrubber`` through the raw laser scans
- ``kinematics`` (01): ``kinematics_explorer``, exact arc against Euler steps
- ``offset`` (02): ``offset_explorer``, the laser offset a, b against GPS on a real turn
- ``observation`` (03): ``measurement_explorer``, a predicted measurement and its covariance
- ``landmarks`` (04): ``beacon_scrubber`` and ``gate_explorer``

Each explorer is built from a pure function (testable without a browser) plus a
drawing callback; the widget keeps the latest result in ``widget.holder["summary"]``
so a headless test can move the slider and check what a student would see.
"""
from . import data, kinematics, landmarks, observation, offset
from .data import scan_scrubber, scan_summary

__all__ = ["data", "kinematics", "landmarks", "observation", "offset", "scan_scrubber", "scan_summary"]
