"""annslam_lib: the library behind the annslam course on EKF-SLAM for a car-like
vehicle with an ANN landmark model.

Modules (each named after what it holds):
- ``vehicle``: the car's geometry (L, H, a, b)
- ``records``: the dataset object shared by real runs and the simulator
- ``registry``, ``fetch``, ``datasets``: the real runs, hash-checked, and their loaders
- ``simulate``: a seeded simulator of the same car with ground truth
- ``geometry``, ``kinematics``, ``observation``: the models and their Jacobians
- ``paper``: the paper's equations as printed (with their typos) and the errata
- ``plotting``, ``widgets``: figure and widget helpers for the notebooks
"""
__version__ = "0.1.0"
