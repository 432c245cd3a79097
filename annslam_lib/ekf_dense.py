"""The textbook EKF-SLAM, dense: the reference the efficient filter is checked against
(notebook 05 "why the textbook filter does not scale"; tests/test_ekf_slam.py;
benchmarks/bench_ekf_slam.py).

Same models and the same interface as ``ekf_slam.EkfSlam``, written the way a textbook
(and most public notebooks) writes it, with full-state matrices:

    predict:  P = G_x P G_x^T + G_u Q G_u^T       G_x = I_n with the 3x3 motion Jacobian F
                                                   (``kinematics.predict``), G_u (n x 2)
    update:   H dense (2m x n) from ``observation.observe``, S = H P H^T + R,
              K = P H^T S^-1, x += K nu, P = (I - K H) P (I - K H)^T + K R K^T (Joseph)
    augment:  P = Y P Y^T + Z R Z^T with Y = [I_n; J_pose E_v], Z = [0; J_z]
              (``observation.inverse_observe``)

Every step costs O(n^2) to O(n^3): fine for tens of landmarks, hopeless for hundreds.
"""
from __future__ import annotations

import numpy as np

from . import kinematics
from .ekf_slam import check_initial
from .geometry import wrap_angle
from .observation import inverse_observe, observe
from .vehicle import Vehicle

__all__ = ["DenseEkfSlam"]


class DenseEkfSlam:
    """Dense reference EKF-SLAM: x (n,), P (n, n). See the module docstring."""

    def __init__(self, x0, P0, vehicle: Vehicle, motion_model: str = "euler") -> None:
        x0, P0 = check_initial(x0, P0, vehicle, motion_model)
        self._mid = motion_model == "midpoint"
        self.vehicle = vehicle
        self.x = x0.copy()
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = 0.5 * (P0 + P0.T)

    # Names the run loop reads.
    @property
    def _px(self) -> float:
        return float(self.x[0])

    @property
    def _py(self) -> float:
        return float(self.x[1])

    @property
    def _pphi(self) -> float:
        return float(self.x[2])

    @property
    def _p(self) -> list:
        """The pose covariance's unique entries (00, 01, 02, 11, 12, 22)."""
        P = self.P
        return [P[0, 0], P[0, 1], P[0, 2], P[1, 1], P[1, 2], P[2, 2]]

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
        """Full-state prediction with the control row ``u`` of ``ekf_slam.control_table``
        (``kinematics.predict``; 'midpoint': evaluated at the mid-step heading);
        process noise dt * Delta B Q_c B^T = (Delta / dt) G Q_c G^T."""
        if dt <= 0.0:
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

    def update(self, z, lm, sigma_range: float, sigma_bearing: float):
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        lm = np.asarray(lm, dtype=np.int64).ravel()
        if lm.size == 0:
            return 0.0, 0
        zhat, H = self._jacobian(lm)
        nu = z - zhat
        nu[:, 1] = wrap_angle(nu[:, 1])
        R = np.diag(np.tile([sigma_range**2, sigma_bearing**2], lm.size))
        return self._kalman(H, nu.ravel(), R), 2 * lm.size

    def gps_update(self, xy, sigma_gps: float, gate: float = np.inf):
        H = np.zeros((2, self.x.size))
        H[0, 0] = H[1, 1] = 1.0
        nis = self._kalman(H, np.asarray(xy, dtype=float) - self.x[:2], sigma_gps**2 * np.eye(2), gate)
        return nis, nis <= gate

    def augment(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        z = np.asarray(z, dtype=float).reshape(-1, 2)
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
        idx = np.asarray(idx, dtype=np.int64).ravel()
        keep = np.setdiff1d(np.arange(self.x.size), np.concatenate([3 + 2 * idx, 4 + 2 * idx]))
        self.x = self.x[keep]
        self.P = self.P[np.ix_(keep, keep)]

    def health(self):
        return float(np.linalg.eigvalsh(self.P)[0]), float(np.max(np.abs(self.P - self.P.T)))
