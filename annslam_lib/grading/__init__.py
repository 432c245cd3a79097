"""Automatic feedback for the course's graded exercises (nbgrader test cells call these).

``core`` holds the generic machinery (:func:`check_function`, :func:`check_jacobian`,
:class:`GradingError`); one module per chapter holds that chapter's checks, each comparing a
student's function with the library's reference on seeded inputs and edge cases, and naming
known mistakes (including the paper's misprinted equations):

- ``kinematics``: chapters 01 and 02 (vehicle kinematics, the laser offset)
- ``kalman``: chapter 01a (the Kalman filter)
- ``observation``: chapter 03 (the observation model)
- ``association``: chapter 04 (gating and data association)
- ``localisation``: chapter 04a (one beacon's update, the NIS verdict)
- ``localisation_loop``: chapter 04a's whole localisation loop, scored on unseen runs
- ``ekf``: chapter 05 (landmark augmentation, the update in Joseph form)
- ``diagnose``: chapter 05a (the broken filters named with their evidence)
- ``metrics``: chapter 06 (the track against GPS, impossible GPS fixes)
- ``ann``: chapter 07 (the landmark network)
- ``verdict``: chapter 08 (the verdict)
- ``capstone``: chapter 09 (a student's whole EKF-SLAM loop, scored on unseen runs)
- ``smoothing``: chapter 10 (factor graphs)
- ``graph_slam``: chapter 11 (graph-SLAM from scratch)

:func:`forget_results` drops the whole-loop results the checks of 04a and 09 keep per
student function and run (a grader calls it after each submission).
"""
from .core import (NOT_WRITTEN, GradingError, Mistake, call, check_function, check_jacobian,
                   check_raises, describe, fail, fmt)
from ._tracks import forget_results

__all__ = ["NOT_WRITTEN", "GradingError", "Mistake", "call", "check_function", "check_jacobian",
           "check_raises", "describe", "fail", "fmt", "forget_results",
           "core", "kinematics", "kalman", "observation", "association", "localisation",
           "localisation_loop", "ekf", "diagnose", "metrics", "ann", "verdict", "capstone",
           "smoothing", "graph_slam"]
