"""SLAM layer: the EKF over a whole run.

- ``config``: ``SlamConfig``, every choice of a run (defaults per dataset live with the data)
- ``base``: errors, the start check, the ``FilterBackend`` and ``LandmarkModel`` interfaces
- ``efficient``: the filter written to scale (``EkfSlam``)
- ``dense``: the textbook dense reference it is tested against, and the update's steps
- ``runner``: ``run()``, the event loop, landmark book-keeping and result assembly
- ``stretches``: the odometry between events, compounded once for a run
- ``compiled``: the scan's gating as one numba-compiled loop, for long runs (Victoria Park)
- ``results``: ``SlamResult`` and the per-detection log
- ``dead_reckoning``: odometry alone, and the initial pose from GPS
- ``threads``: single-threaded BLAS while a run goes
- ``kalman``: the Kalman filter in general form (1-D, linear n-D, the gate, the Bayes grid)
- ``localisation``: EKF localisation on a known map (one beacon update, the NIS verdict)
- ``unscented``: the unscented transform and a UKF of the car (sigma points, no Jacobians)
- ``particles``: a particle filter on a known map (Monte-Carlo localisation: move, weigh,
  systematic resampling, depletion said)
- ``fastslam``: FastSLAM 1.0, one small EKF per landmark in each particle, and its
  importance weights
"""
from __future__ import annotations

from .._lazy import attach

__getattr__, __dir__, __all__ = attach(
    __name__, ["config", "base", "efficient", "dense", "runner", "stretches", "compiled", "results",
               "dead_reckoning", "threads", "kalman", "localisation", "unscented", "particles",
               "fastslam"],
    {"run": "runner", "SlamConfig": "config", "SlamResult": "results", "EkfSlam": "efficient",
     "DenseEkfSlam": "dense"})
