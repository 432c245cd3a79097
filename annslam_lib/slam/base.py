"""What every EKF-SLAM backend shares: its errors, the start check, and the two interfaces
the run loop (:mod:`annslam_lib.slam.runner`) talks to.

:class:`FilterBackend` is what a filter must offer the loop: the efficient filter
(:mod:`~annslam_lib.slam.efficient`) and the dense textbook reference (:mod:`~annslam_lib.
slam.dense`) both implement it, and the loop uses nothing else of them. :class:`LandmarkModel`
is what turns a detection into the measurement the filter uses (the ANN of chapter 08).
"""
from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from .. import _checks
from ..models.vehicle import Vehicle
from .config import MOTION_MODELS

__all__ = ["InnovationError", "check_measurement", "check_initial", "check_dt", "check_sigmas", "check_z",
           "check_remove", "with_known_landmarks", "FilterBackend", "LandmarkModel"]


class InnovationError(ValueError):
    """The innovation covariance S of an update is not positive definite (singular):
    no gain exists. Typically zero measurement noise on a perfectly known state."""



def check_initial(x0, P0, vehicle: Vehicle, motion_model: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate a filter's start (shared by :class:`EkfSlam` and the dense reference):
    x0 (3,) and P0 (3, 3) finite, P0 symmetric PSD, a Vehicle, a known motion model.
    Returns float copies of x0 and P0."""
    _checks.choice("motion_model", motion_model, MOTION_MODELS)
    x0 = _checks.array("x0", x0).copy()
    P0 = _checks.array("P0", P0).copy()
    if x0.shape != (3,) or P0.shape != (3, 3):
        raise ValueError(f"x0 must be (3,) and P0 (3, 3), got {x0.shape} and {P0.shape}")
    if np.max(np.abs(P0 - P0.T)) > 1e-12 * max(1.0, np.max(np.abs(P0))):
        raise ValueError("initial covariance P0 must be symmetric")
    if np.min(np.linalg.eigvalsh(P0)) < -1e-12:
        raise ValueError("initial covariance P0 must be positive semi-definite")
    _checks.instance("vehicle", vehicle, Vehicle)
    return x0, P0



# Argument checks of the backends' public methods (both call them, so a wrong argument
# fails the same way in the efficient filter and the dense reference). Cheap: scalars are
# compared directly, arrays read once; the run loop calls them every scan.

def check_dt(dt) -> float:
    """A prediction step: a finite dt >= 0 (s); 0 does nothing. A negative or NaN dt is
    a clock fault, not a step."""
    if not (0.0 <= dt < np.inf):                        # NaN fails too
        raise ValueError(f"predict: dt must be finite and >= 0 s, got {dt!r}")
    return dt


def check_sigmas(name: str, *sigmas) -> None:
    """Measurement noise standard deviations: finite and > 0 (a zero noise makes S
    singular on a known state; NaN would spread through P)."""
    for v in sigmas:
        if not (0.0 < v < np.inf):
            raise ValueError(f"{name}: measurement noise sigma must be finite and > 0, got {v!r}")


def check_z(name: str, z) -> np.ndarray:
    """Range-bearing measurements z as a float (n, 2) array: finite, range > 0. (Called
    for every scan's gating, update and new landmarks: the common case, a float (n, 2)
    array, costs two reductions.)"""
    if type(z) is not np.ndarray or z.dtype != np.float64:
        z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.shape[1] != 2:
        if z.size % 2 or z.ndim > 2 or (z.ndim == 2 and z.shape[1] != 2):
            raise ValueError(f"{name}: z must be (n, 2) range-bearing pairs, got shape {z.shape}")
        z = z.reshape(-1, 2)
    # the sum is finite only if every entry is (NaN and inf propagate)
    if z.shape[0] and not (math.isfinite(z.sum()) and z[:, 0].min() > 0.0):
        raise ValueError(f"{name}: z must be finite with every range > 0")
    return z


def check_remove(idx, n_landmarks: int) -> np.ndarray:
    """Landmark indices to remove: integers in 0..n_landmarks-1 (a negative index would
    delete rows of the pose)."""
    a = np.asarray(idx)
    if a.size and a.dtype.kind not in "iu":
        raise TypeError(f"remove: landmark indices must be integers, got dtype {a.dtype}")
    a = a.astype(np.int64).ravel()
    if a.size and not (0 <= a.min() and a.max() < n_landmarks):
        raise ValueError(f"remove: landmark index out of range 0..{n_landmarks - 1}: "
                         f"{a[(a < 0) | (a >= n_landmarks)].tolist()}")
    return a



def with_known_landmarks(x, P, xy, sigma: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The state (x, P) with landmarks at known positions ``xy`` (k, 2) appended (a surveyed
    map: EKF localisation, chapter 04a): uncorrelated with the pose and with each other,
    covariance sigma^2 I each. With sigma = 0 the landmarks are exactly known: their rows
    of P, hence of every gain K = P H^T S^-1, are zero, so no update moves them."""
    xy = _checks.array("xy", xy, (2,)).reshape(-1, 2)
    sigma = _checks.real("sigma", sigma, lo=0.0)
    n, k = x.size, xy.shape[0]
    Pn = np.zeros((n + 2 * k, n + 2 * k))
    Pn[:n, :n] = P
    Pn[n:, n:] = sigma**2 * np.eye(2 * k)
    return np.concatenate([x, xy.ravel()]), Pn


@runtime_checkable
class FilterBackend(Protocol):
    """The filter as the run loop sees it (laser pose + landmarks, their covariance).

    Construction: ``Backend(x0, P0, vehicle, motion_model)``. Prediction: ``predict(u, dt)``
    with a row ``u`` of ``models.motion.control_table`` (the control held over the step,
    with its noise); ``predict_many(u, t, times, rows)`` runs a stretch of odometry samples
    step by step. (The run loop predicts the efficient filter by
    ``EkfSlam.predict_stretch``, stretches compounded beforehand, ``slam.stretches``, and
    any other backend by its ``predict``, step by step.)
    Observation: ``observation_model(sigma_range, sigma_bearing)`` -> (zhat (N, 2), S
    (N, 2, 2)) of every landmark; ``innovation_d2(z, sigma_range, sigma_bearing)`` -> the
    squared Mahalanobis distances (n, N) of detections to them, for gating; ``update(z, lm, sigma_range, sigma_bearing)`` ->
    (NIS, dof) for the associated detections; ``gps_update(xy, sigma, gate)`` -> (NIS,
    accepted); ``augment(z, sigma_range, sigma_bearing)`` -> indices of the new landmarks;
    ``add_known_landmarks(xy, sigma)`` -> indices of landmarks at known positions;
    ``remove(idx)`` marginalises landmarks out. Read access: ``pose`` (3,), ``pose_cov``
    (3, 3), ``pose_cov_entries()`` (its six unique entries, cheap), ``n_landmarks``,
    ``state()`` -> (x, P), ``health()`` -> (min eigenvalue, asymmetry)."""

    n_landmarks: int

    def predict(self, u, dt: float) -> None: ...
    def predict_many(self, u, t: float, times, rows, *, record: bool = True): ...
    def observation_model(self, sigma_range: float, sigma_bearing: float): ...
    def innovation_d2(self, z, sigma_range: float, sigma_bearing: float): ...
    def update(self, z, lm, sigma_range: float, sigma_bearing: float): ...
    def gps_update(self, xy, sigma_gps: float, gate: float = ...): ...
    def augment(self, z, sigma_range: float, sigma_bearing: float): ...
    def add_known_landmarks(self, xy, sigma: float = ...): ...
    def remove(self, idx) -> None: ...
    @property
    def pose(self) -> np.ndarray: ...
    @property
    def pose_cov(self) -> np.ndarray: ...
    def pose_cov_entries(self) -> tuple: ...
    def state(self) -> tuple[np.ndarray, np.ndarray]: ...
    def health(self) -> tuple[float, float]: ...


@runtime_checkable
class LandmarkModel(Protocol):
    """A learned landmark model (chapter 08; ``ann.TrainedModel``, ``ann.InverseModel``):
    ``pseudo_measurement(pose, z, intensity, width)`` -> z' (n, 2) replaces the detections
    z (n, 2) seen from the prior ``pose``; ``sigmas`` = (sigma_range, sigma_bearing) is its
    noise, which replaces the laser's."""

    sigmas: tuple

    def pseudo_measurement(self, pose, z, intensity, width) -> np.ndarray: ...


def check_measurement(P, H, R) -> tuple[np.ndarray, np.ndarray]:
    """H (m, n) and R (m, m) as arrays, checked against P (n, n); ValueError otherwise."""
    H = _checks.array("H", H)
    R = _checks.array("R", R)
    if H.ndim != 2 or H.shape[1] != P.shape[0]:
        raise ValueError(f"H must be (m, {P.shape[0]}) for a state of size {P.shape[0]}, "
                         f"got {H.shape}")
    if R.shape != (H.shape[0], H.shape[0]):
        raise ValueError(f"R must be {H.shape[0]} x {H.shape[0]} for {H.shape[0]} measurement "
                         f"rows, got {R.shape}")
    return H, R
