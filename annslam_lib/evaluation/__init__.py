"""Evaluation layer: how good is a run?

- ``trajectory``: errors of a path against GPS, GPS outliers
- ``map``: a map against a surveyed one, absolute and after rigid alignment
- ``consistency``: NEES, NIS and their chi-square bands
- ``scan_null``: the null distribution of per-scan statistics when scans are correlated
- ``real_consistency``: a real run's map against the survey (joint NEES), and the split of
  its innovation covariance into H P H^T and R
- ``summary``: ``run_metrics``, the one summary of a run every table uses
- ``timing``: per-step cost of the efficient and dense filters
- ``calibration``: noise values read off the data (the GPS's own scatter)
- ``residuals``: how a residual that should be zero is shown (a bound, not its digits)
"""

__all__ = ["trajectory", "map", "consistency", "scan_null", "real_consistency", "summary",
           "timing", "calibration", "residuals"]
