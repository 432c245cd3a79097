"""Smoothing layer: the same runs as factor graphs, solved with GTSAM (chapter 10).

- ``problem``: a run's graph as plain arrays (poses per event, odometry, range-bearing and
  GPS factors, the prior), built from an EKF run with the course's models, and its checks
- ``factors``: a between and a range-bearing factor's error, SE(2)'s logarithm, a marginal
  covariance read in the filter's coordinates (numpy, checked against GTSAM)
- ``solve``: the graph in GTSAM, solved incrementally (iSAM2) and in batch (LM)
- ``gauss_newton``: the same graph built and solved from scratch (whitened errors and their
  Jacobians, the sparse information matrix, Gauss-Newton steps), checked against GTSAM
- ``compare``: EKF against iSAM2 (its filtered and its smoothed estimate) and batch on the
  Car Park and Victoria Park, each side's whole CPU cut at every processed scan
  (``timed_run``; ``python -m annslam_lib compare``)
"""

__all__ = ["problem", "factors", "solve", "gauss_newton", "compare"]
