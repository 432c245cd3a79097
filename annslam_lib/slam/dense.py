"""The textbook EKF-SLAM, dense: the reference the efficient filter is checked against
(notebook 05 "why the textbook filter does not scale"; tests/test_ekf_slam.py;
benchmarks/bench_ekf_slam.py).

Same models and the same interface as ``slam.efficient.EkfSlam``, written the way a textbook
(and most public notebooks) writes it, with full-state matrices:

    predict:  P = G_x P G_x^T + G_u Q G_u^T       G_x = I_n with the 3x3 motion Jacobian F
                                                   (``motion.predict``), G_u (n x 2)
    update:   H dense (2m x n) from ``observation.observe``, S = H P H^T + R,
              K = P H^T S^-1, x += K nu, P = (I - K H) P (I - K H)^T + K R K^T (Joseph)
    augment:  P = Y P Y^T + Z R Z^T with Y = [I_n; J_pose E_v], Z = [0; J_z]
              (``observation.inverse_observe``)

Every step costs O(n^2) to O(n^3): fine for tens of landmarks, hopeless for hundreds.

The single steps are also plain functions of (x, P), the references of notebook 05's graded
exercises (``grading.ekf``): :func:`augment_landmark` (section 1, landmark augmentation),
:func:`innovation`, :func:`kalman_gain`, :func:`joseph_covariance` (the general Kalman
filter's, ``slam.kalman``) and
:func:`joseph_update` / :func:`range_bearing_update` (section 3, the update).
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from ..models import motion as kinematics
from .base import (check_measurement, with_known_landmarks, check_dt, check_initial, check_remove, check_sigmas,
                   check_z)
from ..models.geometry import wrap_angle
from ..models.observation import inverse_observe, observe
from ..models.vehicle import Vehicle
from ..perception.association import mahalanobis_fast
from .kalman import joseph_covariance, kalman_gain

__all__ = ["DenseEkfSlam", "augment_landmark", "innovation", "kalman_gain", "joseph_covariance",
           "joseph_update", "range_bearing_update"]


class DenseEkfSlam:
    """Dense reference EKF-SLAM: x (n,), P (n, n). See the module docstring.

    Parameters
    ----------
    x0 : array_like, shape (3,)
        Initial laser pose (x, y, phi) (m, m, rad); the map starts empty.
    P0 : array_like, shape (3, 3)
        Its covariance (m^2, rad^2).
    vehicle : Vehicle
        The car (``L``, ``a``, ``b``) of the motion model.
    motion_model : {'euler', 'midpoint'}, optional
        The prediction's discretisation (``SlamConfig.motion_model``).

    Raises
    ------
    TypeError
        If ``x0`` or ``P0`` is not numeric or ``vehicle`` is not a Vehicle.
    ValueError
        If ``x0`` is not a finite (3,) array, ``P0`` not a finite symmetric positive
        semi-definite (3, 3) matrix, or ``motion_model`` is unknown.
    """

    def __init__(self, x0, P0, vehicle: Vehicle, motion_model: str = "euler") -> None:
        x0, P0 = check_initial(x0, P0, vehicle, motion_model)
        self._mid = motion_model == "midpoint"
        self.vehicle = vehicle
        self.x = x0.copy()
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = 0.5 * (P0 + P0.T)

    # The read access of slam.base.FilterBackend.
    def pose_tuple(self) -> tuple[float, float, float]:
        return float(self.x[0]), float(self.x[1]), float(self.x[2])

    def pose_cov_entries(self) -> tuple:
        """The pose covariance's unique entries (00, 01, 02, 11, 12, 22)."""
        P = self.P
        return (P[0, 0], P[0, 1], P[0, 2], P[1, 1], P[1, 2], P[2, 2])

    def predict_many(self, u, t: float, times, rows, *, record: bool = True):
        """:meth:`predict` over a stretch of odometry samples (``slam.base.FilterBackend``):
        the textbook loop, one dense prediction per sample."""
        n, poses = 0, [] if record else None
        for tk, row in zip(times, rows):
            if tk > t and u is not None:
                self.predict(u, tk - t)
                n += 1
            if record:
                poses.append((tk, *self.pose_tuple()))
            u, t = row, tk
        return u, t, n, poses

    @property
    def n_landmarks(self) -> int:
        return (self.x.size - 3) // 2

    @property
    def pose(self) -> np.ndarray:
        return self.x[:3].copy()

    @property
    def pose_cov(self) -> np.ndarray:
        return self.P[:3, :3].copy()

    def flush(self) -> None:
        """Nothing is deferred here."""

    def state(self):
        return self.x, self.P

    def landmarks(self) -> np.ndarray:
        return self.x[3:].reshape(-1, 2)

    def landmark_covs(self) -> np.ndarray:
        N = self.n_landmarks
        return np.array([self.P[3 + 2 * j:5 + 2 * j, 3 + 2 * j:5 + 2 * j] for j in range(N)])

    def predict(self, u, dt: float) -> None:
        """Full-state prediction with the control row ``u`` of ``models.motion.control_table``
        (``motion.predict``; 'midpoint': evaluated at the mid-step heading);
        process noise dt * Delta B Q_c B^T = (Delta / dt) G Q_c G^T."""
        if check_dt(dt) == 0.0:
            return
        v, alpha, _, w, _, q00, q01, q11, span = u
        at = self.x[:3].copy()
        if self._mid:                      # rate and Jacobians at the mid-step heading
            at[2] += 0.5 * dt * w
        pose, F, G = kinematics.predict(at, np.array([v, alpha]), dt, self.vehicle)
        pose[2] = wrap_angle(self.x[2] + dt * w)
        n = self.x.size
        Gx = np.eye(n)
        Gx[:3, :3] = F
        Gu = np.zeros((n, 2))
        Gu[:3] = G
        Q = np.array([[q00, q01], [q01, q11]]) * (span / dt)
        self.x[:3] = pose
        self.P = Gx @ self.P @ Gx.T + Gu @ Q @ Gu.T

    def _jacobian(self, lm):
        n = self.x.size
        lm = np.asarray(lm, dtype=np.int64)
        zhat, Hp, Hl = observe(self.x[:3], self.landmarks()[lm])
        H = np.zeros((2 * lm.size, n))
        for i, j in enumerate(lm.tolist()):
            H[2 * i:2 * i + 2, :3] = Hp[i]
            H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] += Hl[i]
        return zhat, H

    def observation_model(self, sigma_range: float, sigma_bearing: float):
        R = np.diag([sigma_range**2, sigma_bearing**2])
        zhat = np.empty((self.n_landmarks, 2))
        S = np.empty((self.n_landmarks, 2, 2))
        for j in range(self.n_landmarks):
            zj, H = self._jacobian([j])
            zhat[j] = zj[0]
            S[j] = H @ self.P @ H.T + R
        return zhat, S

    def innovation_d2(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """d2 (n, N) of detections z to every landmark (``slam.base.FilterBackend``):
        :meth:`observation_model` and ``perception.association.mahalanobis_fast``."""
        check_sigmas("innovation_d2", sigma_range, sigma_bearing)
        z = check_z("innovation_d2", z)
        zhat, S = self.observation_model(sigma_range, sigma_bearing)
        if zhat.shape[0] == 0:
            return np.empty((z.shape[0], 0))
        return mahalanobis_fast(z, zhat, S)

    def _kalman(self, H, nu, R, gate=np.inf):
        S = H @ self.P @ H.T + R
        nis = float(nu @ np.linalg.solve(S, nu))
        if nis > gate:
            return nis
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ nu
        self.x[2] = float(wrap_angle(self.x[2]))
        IKH = np.eye(self.x.size) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ R @ K.T
        return nis

    @staticmethod
    def _update_inputs(z, lm, sigma_range: float, sigma_bearing: float):
        """An update's detections (n, 2) and landmark indices (n,), checked."""
        check_sigmas("update", sigma_range, sigma_bearing)
        return check_z("update", z), np.asarray(lm, dtype=np.int64).ravel()

    def update(self, z, lm, sigma_range: float, sigma_bearing: float):
        z, lm = self._update_inputs(z, lm, sigma_range, sigma_bearing)
        if lm.size == 0:
            return 0.0, 0
        zhat, H = self._jacobian(lm)
        nu = z - zhat
        nu[:, 1] = wrap_angle(nu[:, 1])
        R = np.diag(np.tile([sigma_range**2, sigma_bearing**2], lm.size))
        return self._kalman(H, nu.ravel(), R), 2 * lm.size

    def gps_update(self, xy, sigma_gps: float, gate: float = np.inf):
        check_sigmas("gps_update", sigma_gps)
        xy = np.asarray(xy, dtype=float)
        if xy.shape != (2,) or not np.isfinite(xy).all():
            raise ValueError(f"gps_update: xy must be a finite (2,) position, got {xy!r}")
        H = np.zeros((2, self.x.size))
        H[0, 0] = H[1, 1] = 1.0
        nis = self._kalman(H, xy - self.x[:2], sigma_gps**2 * np.eye(2), gate)
        return nis, nis <= gate

    def add_known_landmarks(self, xy, sigma: float = 0.0) -> np.ndarray:
        """Append landmarks at known positions ``xy`` (k, 2) with covariance sigma^2 I each
        (:func:`slam.base.with_known_landmarks`; EKF localisation, chapter 04a). Returns
        their indices."""
        N0 = self.n_landmarks
        self.x, self.P = with_known_landmarks(self.x, self.P, xy, sigma)
        return np.arange(N0, self.n_landmarks)

    def augment(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        check_sigmas("augment", sigma_range, sigma_bearing)
        z = check_z("augment", z)
        k, n, N0 = z.shape[0], self.x.size, self.n_landmarks
        if k == 0:
            return np.empty(0, dtype=np.int64)
        lm, Jp, Jz = inverse_observe(self.x[:3], z)
        Y = np.zeros((n + 2 * k, n))
        Y[:n] = np.eye(n)
        Y[n:, :3] = Jp.reshape(2 * k, 3)
        Z = np.zeros((n + 2 * k, 2 * k))
        for i in range(k):
            Z[n + 2 * i:n + 2 * i + 2, 2 * i:2 * i + 2] = Jz[i]
        R = np.diag(np.tile([sigma_range**2, sigma_bearing**2], k))
        self.P = Y @ self.P @ Y.T + Z @ R @ Z.T
        self.x = np.concatenate([self.x, lm.ravel()])
        return np.arange(N0, N0 + k)

    def remove(self, idx) -> None:
        idx = check_remove(idx, self.n_landmarks)
        keep = np.setdiff1d(np.arange(self.x.size), np.concatenate([3 + 2 * idx, 4 + 2 * idx]))
        self.x = self.x[keep]
        self.P = self.P[np.ix_(keep, keep)]

    def health(self):
        return float(np.linalg.eigvalsh(self.P)[0]), float(np.max(np.abs(self.P - self.P.T)))


# ------------------------------------------------------------ the steps as functions of (x, P)

def _state(x, P) -> tuple[np.ndarray, np.ndarray]:
    """x (n,) with n = 3 + 2N and P (n, n), finite; ValueError otherwise."""
    x = _checks.array("x", x)
    P = _checks.array("P", P)
    if x.ndim != 1 or x.size < 3 or (x.size - 3) % 2:
        raise ValueError(f"x must be a state (x, y, phi, x_1, y_1, ...) of size 3 + 2N, "
                         f"got shape {x.shape}")
    if P.shape != (x.size, x.size):
        raise ValueError(f"P must be {x.size} x {x.size} for a state of size {x.size}, "
                         f"got {P.shape}")
    return x, P


def augment_landmark(x, P, z, R):
    """Landmark augmentation (notebook 05 section 1): the state and covariance with the
    landmarks seen at measurements ``z`` appended.

    x (n,), P (n, n); z (2,) or (k, 2) rows (range > 0, laser bearing); R (2, 2) the noise
    covariance of one measurement. With l = g(X_v, z) and its Jacobians G_v (2x3), G_z
    (2x2) from :func:`observation.inverse_observe`, each new landmark adds the blocks

        x+ = [x; l],   P+ = [[P, P_{:,v} G_v^T], [G_v P_{v,:}, G_v P_vv G_v^T + G_z R G_z^T]]

    (between two landmarks seen in the same scan, G_v,i P_vv G_v,j^T). Returns (x+, P+);
    the same numbers as :meth:`DenseEkfSlam.augment`.
    """
    x, P = _state(x, P)
    z = _checks.array("z", z, (2,)).reshape(-1, 2)
    R = _checks.array("R", R)
    if R.shape != (2, 2):
        raise ValueError(f"R must be the 2 x 2 covariance of one (range, bearing), got {R.shape}")
    lm, Gv, Gz = inverse_observe(x[:3], z)
    Gv = Gv.reshape(-1, 3)                              # (2k, 3): all new rows at once
    cross = Gv @ P[:3]                                  # (2k, n): G_v P_{v,:}
    new = Gv @ P[:3, :3] @ Gv.T
    for i in range(z.shape[0]):
        b = slice(2 * i, 2 * i + 2)
        new[b, b] += Gz[i] @ R @ Gz[i].T
    P_new = np.block([[P, cross.T], [cross, new]])
    return np.concatenate([x, lm.ravel()]), P_new


def innovation(z, z_hat) -> np.ndarray:
    """Innovation nu = z - z_hat of stacked (range, bearing) measurements (notebook 05
    section 3), the bearing entries wrapped to (-pi, pi]: a bearing measured at -3.13 rad
    and predicted at 3.13 rad is 0.02 rad off, not -6.26. z, z_hat (2m,) or (m, 2);
    returns (2m,)."""
    z = _checks.array("z", z).ravel()
    z_hat = _checks.array("z_hat", z_hat).ravel()
    if z.shape != z_hat.shape or z.size % 2:
        raise ValueError(f"z and z_hat must hold the same (range, bearing) pairs, got sizes "
                         f"{z.size} and {z_hat.size}")
    nu = z - z_hat
    nu[1::2] = wrap_angle(nu[1::2])
    return nu


def joseph_update(x, P, nu, H, R) -> tuple[np.ndarray, np.ndarray]:
    """EKF update with the innovation ``nu`` (notebook 05 section 3): K from
    :func:`kalman_gain`, x+ = x + K nu (heading wrapped to (-pi, pi]), P+ from
    :func:`joseph_covariance`. The arithmetic of :meth:`DenseEkfSlam.update`.
    Raises InnovationError for a singular S."""
    x, P = _state(x, P)
    H, R = check_measurement(P, H, R)
    nu = _checks.array("nu", nu).ravel()
    if nu.size != H.shape[0]:
        raise ValueError(f"nu has {nu.size} entries but H has {H.shape[0]} rows")
    K, _ = kalman_gain(P, H, R)
    x_new = x + K @ nu
    x_new[2] = float(wrap_angle(x_new[2]))
    return x_new, joseph_covariance(P, H, R, K)


def range_bearing_update(x, P, z, z_hat, H, R) -> tuple[np.ndarray, np.ndarray]:
    """EKF update from stacked (range, bearing) measurements ``z`` and their predictions
    ``z_hat`` (notebook 05 section 3, graded exercise): :func:`joseph_update` with the
    wrapped :func:`innovation`.

    Parameters
    ----------
    x : array_like, shape (n,)
        State (x, y, phi, x_1, y_1, ...), n = 3 + 2N.
    P : array_like, shape (n, n)
        Its covariance.
    z : array_like, shape (2m,) or (m, 2)
        Measured (range, bearing) pairs (m, rad).
    z_hat : array_like, shape (2m,) or (m, 2)
        Their predictions.
    H : array_like, shape (2m, n)
        Measurement Jacobian.
    R : array_like, shape (2m, 2m)
        Measurement noise covariance.

    Returns
    -------
    x_new : ndarray, shape (n,)
        Updated state, heading wrapped to (-pi, pi].
    P_new : ndarray, shape (n, n)
        Updated covariance (Joseph form).

    Raises
    ------
    InnovationError
        (a ValueError) For a singular S.
    ValueError
        If the shapes do not match or a value is not finite.
    """
    return joseph_update(x, P, innovation(z, z_hat), H, R)
