"""The unscented transform and an unscented Kalman filter (UKF) for the car.

The EKF pushes a Gaussian through a nonlinear function by its Jacobian at the mean (first
order). The unscented transform pushes 2n + 1 chosen points instead and fits the Gaussian of
what comes out: no Jacobian, and the mean is right to second order.

Sigma points (van der Merwe's scaled set): with lambda = alpha^2 (n + kappa) - n and
S = chol((n + lambda) P),

    X_0 = mean,  X_i = mean + S[:, i],  X_{n+i} = mean - S[:, i]            (i = 1..n)
    Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,  W_i = 1 / (2 (n + lambda))

They reproduce the mean and covariance exactly: sum Wm X = mean, sum Wc (X - mean)(X - mean)^T
= P. An angle among the outputs (a heading, a bearing) is averaged on the circle (the angle
of sum W (cos, sin)) and its deviations wrapped, or points on both sides of +-pi would
average to 0.

The filter (:func:`ukf_predict`, :func:`ukf_update`) uses the course's own motion model
(:func:`~annslam_lib.models.motion.predict`) and observation model
(:func:`~annslam_lib.models.observation.observe`), their values only. The control noise
enters the prediction through an augmented state (pose, control noise), so the sigma points
carry it through the model; the update is

    zhat, S = UT of h over the points + R;  P_xz = sum Wc (X - pose)(Z - zhat)^T
    K = P_xz S^-1;  pose+ = pose + K (z - zhat);  P+ = P - K S K^T

and a P+ that is no longer positive definite is refused, saying where.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.motion import predict
from ..models.observation import observe
from ..models.vehicle import Vehicle

__all__ = ["SigmaPoints", "sigma_points", "unscented_transform", "ukf_predict", "ukf_update",
           "ukf_backend", "UnscentedError"]


class UnscentedError(ValueError):
    """A covariance the unscented transform cannot use, or one a step made indefinite."""


class SigmaPoints:
    """Points (2n + 1, n) and their mean and covariance weights (2n + 1,)."""

    def __init__(self, points: np.ndarray, wm: np.ndarray, wc: np.ndarray):
        self.points, self.wm, self.wc = points, wm, wc


def _exact(name: str, value, shape: tuple) -> np.ndarray:
    a = _checks.array(name, value, shape)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    return a


def _chol(P, what: str) -> np.ndarray:
    """A square root S of P (S S^T = P): Cholesky's; for a positive SEMI-definite P (a
    state component known exactly, a control with no noise) the symmetric root of its
    eigen-decomposition, eigenvalues down to -1e-12 of the largest taken as 0."""
    P = 0.5 * (P + P.T)
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(P)
        if w[0] < -1e-12 * max(abs(w[-1]), 1e-300):
            raise UnscentedError(f"{what} is not positive semi-definite (smallest eigenvalue "
                                 f"{w[0]:.3g}): no sigma points can be drawn from it") from None
        return V * np.sqrt(np.clip(w, 0.0, None))


def sigma_points(mean, cov, *, alpha: float = 1.0, beta: float = 2.0,
                 kappa: float = 0.0) -> SigmaPoints:
    """van der Merwe's scaled sigma points of N(mean, cov) (module docstring).

    Parameters
    ----------
    mean : array_like, shape (n,)
    cov : array_like, shape (n, n)
        Symmetric positive definite.
    alpha, beta, kappa : float
        Spread (0 < alpha <= 1), prior knowledge of the distribution (2 for a Gaussian),
        secondary scaling; n + lambda must be positive.

    Returns
    -------
    SigmaPoints
        ``points`` (2n + 1, n), ``wm`` and ``wc`` (2n + 1,).

    Raises
    ------
    UnscentedError
        If ``cov`` is not positive definite.
    ValueError
        For wrong shapes, non-finite values or parameters that make n + lambda <= 0.
    """
    mean = _checks.array("mean", mean)
    if mean.ndim != 1:
        raise ValueError(f"mean must have shape (n,), got {mean.shape}")
    n = mean.size
    cov = _exact("cov", cov, (n, n))
    alpha, beta, kappa = (_checks.real(k, v) for k, v in
                          (("alpha", alpha), ("beta", beta), ("kappa", kappa)))
    if not 0 < alpha <= 1:
        raise ValueError(f"alpha must be in (0, 1], got {alpha}")
    lam = alpha * alpha * (n + kappa) - n
    if not n + lam > 0:
        raise ValueError(f"n + lambda = {n + lam:.3g} must be positive (raise kappa)")
    S = _chol((n + lam) * cov, "the covariance")
    points = np.vstack([mean, mean + S.T, mean - S.T])
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + 1.0 - alpha * alpha + beta
    return SigmaPoints(points, wm, wc)


def _mean(Y: np.ndarray, wm: np.ndarray, angles) -> np.ndarray:
    m = wm @ Y
    for i in angles:
        m[i] = np.arctan2(wm @ np.sin(Y[:, i]), wm @ np.cos(Y[:, i]))
    return m


def _deviations(Y: np.ndarray, m: np.ndarray, angles) -> np.ndarray:
    D = Y - m
    for i in angles:
        D[:, i] = wrap_angle(D[:, i])
    return D


def unscented_transform(sp: SigmaPoints, f, *, noise=None, angles=()) -> tuple:
    """The Gaussian fitted to ``f`` of the sigma points: ``(mean, cov, Y, D)`` with Y the
    transformed points (2n + 1, m), D their deviations from the mean (angles wrapped) and
    ``noise`` (m, m) added to the covariance. ``f`` maps (2n + 1, n) to (2n + 1, m);
    ``angles``: the output components that are angles (circular mean, wrapped
    deviations)."""
    Y = np.asarray(f(sp.points), float)
    if Y.ndim != 2 or Y.shape[0] != sp.points.shape[0]:
        raise ValueError(f"f must map the {sp.points.shape[0]} points to rows, got {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise UnscentedError("f gave a non-finite value at a sigma point")
    m = _mean(Y, sp.wm, angles)
    D = _deviations(Y, m, angles)
    C = (D * sp.wc[:, None]).T @ D
    if noise is not None:
        C = C + _exact("noise", noise, (Y.shape[1], Y.shape[1]))
    return m, 0.5 * (C + C.T), Y, D


def ukf_predict(pose, P, control, dt, vehicle: Vehicle, Q, **weights):
    """One UKF prediction of the laser pose over ``dt`` with control (v_c, alpha) whose
    noise has covariance ``Q`` (2, 2): the sigma points of the augmented state
    (pose, control noise) through the course's motion model. Returns (pose, P) (3,), (3, 3).
    ``weights``: :func:`sigma_points`' alpha, beta, kappa."""
    _checks.instance("vehicle", vehicle, Vehicle)
    pose = _exact("pose", pose, (3,))
    P = _exact("P", P, (3, 3))
    control = _exact("control", control, (2,))
    Q = _exact("Q", Q, (2, 2))
    mean = np.concatenate([pose, np.zeros(2)])
    cov = np.zeros((5, 5))
    cov[:3, :3], cov[3:, 3:] = P, Q
    sp = sigma_points(mean, cov, **weights)

    def move(X):
        return predict(X[:, :3], control + X[:, 3:], dt, vehicle)[0]

    m, C, _, _ = unscented_transform(sp, move, angles=(2,))
    return m, C


def ukf_update(pose, P, z, landmark, R, **weights):
    """One UKF update of the laser pose by a sighting z = (range, bearing) of a landmark at
    a known position (module docstring). Returns (pose, P, info) with info's ``nu``
    (innovation, bearing wrapped), ``S`` and ``K``.

    Raises
    ------
    UnscentedError
        If P is not positive definite, or P+ is not (the update's K S K^T took more than P
        held: e.g. R far smaller than the measurement's real noise with a large gain).
    """
    pose = _exact("pose", pose, (3,))
    P = _exact("P", P, (3, 3))
    z = _exact("z", z, (2,))
    landmark = _exact("landmark", landmark, (2,))
    R = _exact("R", R, (2, 2))
    sp = sigma_points(pose, P, **weights)

    def sight(X):
        return observe(X, np.broadcast_to(landmark, (X.shape[0], 2)))[0]

    zhat, S, _, Dz = unscented_transform(sp, sight, noise=R, angles=(1,))
    Dx = _deviations(sp.points, pose, (2,))
    Pxz = (Dx * sp.wc[:, None]).T @ Dz
    K = Pxz @ np.linalg.inv(S)
    nu = np.array([z[0] - zhat[0], wrap_angle(z[1] - zhat[1])])
    new = pose + K @ nu
    new[2] = wrap_angle(new[2])
    Pn = P - K @ S @ K.T
    Pn = 0.5 * (Pn + Pn.T)
    w = np.linalg.eigvalsh(Pn)
    if not w[0] > 0:
        raise UnscentedError(f"the updated covariance lost its definiteness (smallest "
                             f"eigenvalue {w[0]:.3g}) at the sighting z = {z.tolist()}")
    return new, Pn, {"nu": nu, "S": S, "K": K, "zhat": zhat}


def _pose_after(X, u_noise, controls, dt: float, vehicle: Vehicle, midpoint: bool):
    """The laser poses (M, 3) of sigma points X (M, 3) after ``dt`` with their controls
    (v, alpha) + noise: the course's Euler step (``models.motion.predict``), its rate at
    the mid-step heading for the 'midpoint' model."""
    u = np.broadcast_to(controls + u_noise, (X.shape[0], 2))
    at = X.copy()
    if midpoint:
        at[:, 2] += 0.5 * dt * u[:, 0] * np.tan(u[:, 1]) / vehicle.L
    nxt = predict(at, u, dt, vehicle)[0]
    out = X + (nxt - at)
    out[:, 2] = wrap_angle(X[:, 2] + dt * u[:, 0] * np.tan(u[:, 1]) / vehicle.L)
    return out


def ukf_backend():
    """:class:`UkfSlam`, made on first use (the dense backend it extends imports the
    perception layer's association code)."""
    from .dense import DenseEkfSlam

    class UkfSlam(DenseEkfSlam):
        """EKF-SLAM's state (laser pose, landmarks) filtered by the unscented transform:
        predictions and updates through sigma points of the whole state (no Jacobian of the
        models; the control noise added as the EKF adds it), the GPS update (linear) and a
        new landmark's initialisation as the dense EKF's. The run loop's ``backend='ukf'``
        (``slam.runner.run``)."""

        weights = {"alpha": 1.0, "beta": 2.0, "kappa": 0.0}

        def predict(self, u, dt: float) -> None:
            """The state's sigma points through the motion model; the control noise added
            as the EKF adds it, (Delta / dt) G Q_c G^T with G = d pose / d control at the
            mean (a rate noise: the same total over an interval however the scans cut it;
            as control noise on the points, Q_c Delta / dt would grow without bound for a
            short step)."""
            from .base import check_dt

            if check_dt(dt) == 0.0:
                return
            v, alpha, _, w, _, q00, q01, q11, span = u
            control = np.array([v, alpha])
            sp = sigma_points(self.x, self.P, **self.weights)

            def move(X):
                out = X.copy()
                out[:, :3] = _pose_after(X[:, :3], 0.0, control, dt, self.vehicle, self._mid)
                return out

            m, C, _, _ = unscented_transform(sp, move, angles=(2,))
            at = self.x[:3].copy()
            if self._mid:
                at[2] += 0.5 * dt * w
            G = predict(at, control, dt, self.vehicle)[2]
            Q = np.array([[q00, q01], [q01, q11]]) * (span / dt)
            C[:3, :3] += G @ Q @ G.T
            self.x, self.P = m, C

        def _measure(self, lm, R_diag):
            sp = sigma_points(self.x, self.P, **self.weights)
            lm = np.asarray(lm, dtype=np.int64)

            def sight(X):
                L = X[:, 3:].reshape(X.shape[0], -1, 2)[:, lm]          # (M, m, 2)
                z = observe(np.repeat(X[:, None, :3], lm.size, 1), L)[0]
                return z.reshape(X.shape[0], -1)

            R = np.diag(np.tile(R_diag, lm.size))
            zhat, S, _, Dz = unscented_transform(sp, sight, noise=R,
                                                 angles=tuple(range(1, 2 * lm.size, 2)))
            Dx = _deviations(sp.points, self.x, (2,))
            Pxz = (Dx * sp.wc[:, None]).T @ Dz
            return zhat, S, Pxz

        def observation_model(self, sigma_range: float, sigma_bearing: float):
            N = self.n_landmarks
            zhat, S = np.empty((N, 2)), np.empty((N, 2, 2))
            for j in range(N):
                zj, Sj, _ = self._measure([j], [sigma_range**2, sigma_bearing**2])
                zhat[j], S[j] = zj, Sj
            return zhat, S

        def update(self, z, lm, sigma_range: float, sigma_bearing: float):
            z, lm = self._update_inputs(z, lm, sigma_range, sigma_bearing)
            if lm.size == 0:
                return 0.0, 0
            zhat, S, Pxz = self._measure(lm, [sigma_range**2, sigma_bearing**2])
            nu = z.ravel() - zhat
            nu[1::2] = wrap_angle(nu[1::2])
            Si = np.linalg.inv(S)
            K = Pxz @ Si
            self.x = self.x + K @ nu
            self.x[2] = float(wrap_angle(self.x[2]))
            P = self.P - K @ S @ K.T
            self.P = 0.5 * (P + P.T)
            return float(nu @ Si @ nu), 2 * lm.size

    return UkfSlam
