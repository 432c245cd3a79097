"""FastSLAM 1.0: a particle filter over the car's path, and in each particle one small EKF
per landmark (Montemerlo et al. 2002).

Given a path, the landmarks are independent of one another, so each particle carries its
own 2 x 2 Kalman filter per landmark instead of one joint covariance: N particles x L
landmarks x (2 + 4) numbers, and an update touches only the landmark seen. Per sighting
z = (range, bearing) of landmark j (known association here: the simulator's ids or the
course's associations):

- a particle that has not seen j yet starts its filter there: mean = g(pose, z) (the
  inverse observation model), covariance J_z R J_z^T; its weight is unchanged;
- otherwise, with zhat, H = h(pose, m_j), dh/dm_j: S = H Sigma H^T + R, K = Sigma H^T S^-1,
  m_j += K nu, Sigma = (I - K H) Sigma (I - K H)^T + K R K^T (Joseph), and the particle's
  log weight grows by log N(nu; 0, S): the importance weight, how well the particle's path
  and map predicted the sighting.

The path is moved and resampled as in :mod:`.particles` (the same :func:`~.particles.move`,
:func:`~.particles.normalise`, :func:`~.particles.systematic_resample`); resampling copies a
particle's whole map with it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.observation import inverse_observe, observe

__all__ = ["FastSlamParticles", "start", "sight", "resample"]


@dataclass
class FastSlamParticles:
    """poses (N, 3); means (N, L, 2) and covs (N, L, 2, 2) of each particle's landmark
    filters; seen (N, L) whether a filter has started; log_weights (N,)."""
    poses: np.ndarray
    means: np.ndarray
    covs: np.ndarray
    seen: np.ndarray
    log_weights: np.ndarray

    @property
    def n(self) -> int:
        return self.poses.shape[0]


def start(poses, n_landmarks: int) -> FastSlamParticles:
    """Particles at ``poses`` (N, 3), equal weights, no landmark seen yet."""
    p = _checks.array("poses", poses, (3,))
    if p.ndim != 2 or p.shape[0] == 0:
        raise ValueError(f"poses must have shape (N, 3) with N >= 1, got {p.shape}")
    L = _checks.integer("n_landmarks", n_landmarks, lo=0)
    N = p.shape[0]
    return FastSlamParticles(p.copy(), np.zeros((N, L, 2)), np.zeros((N, L, 2, 2)),
                             np.zeros((N, L), bool), np.full(N, -np.log(N)))


def sight(fs: FastSlamParticles, z, j: int, R) -> np.ndarray:
    """Every particle's update by the sighting ``z`` (range, bearing) of landmark ``j`` with
    noise covariance ``R`` (2, 2) (module docstring), in place. Returns the log weights'
    increments (N,) (0 where the landmark was new to the particle)."""
    z = _checks.array("z", z, (2,)).reshape(2)
    R = _checks.array("R", R, (2, 2))
    j = _checks.integer("j", j, lo=0, hi=fs.means.shape[1] - 1)
    if z[0] <= 0:
        raise ValueError(f"a sighting's range must be > 0, got {z[0]}")
    new = ~fs.seen[:, j]
    gain = np.zeros(fs.n)
    if new.any():
        m, _, Jz = inverse_observe(fs.poses[new], np.broadcast_to(z, (int(new.sum()), 2)))
        fs.means[new, j] = m
        fs.covs[new, j] = Jz @ R @ np.swapaxes(Jz, -1, -2)
        fs.seen[new, j] = True
    old = ~new
    if old.any():
        mu, Sig = fs.means[old, j], fs.covs[old, j]
        zhat, _, H = observe(fs.poses[old], mu)
        nu = z - zhat
        nu[:, 1] = wrap_angle(nu[:, 1])
        HT = np.swapaxes(H, -1, -2)
        S = H @ Sig @ HT + R
        Si = np.linalg.inv(S)
        K = Sig @ HT @ Si
        fs.means[old, j] = mu + (K @ nu[..., None])[..., 0]
        IKH = np.eye(2) - K @ H
        fs.covs[old, j] = IKH @ Sig @ np.swapaxes(IKH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
        d2 = np.einsum("ni,nij,nj->n", nu, Si, nu)
        gain[old] = -0.5 * (d2 + np.log(np.linalg.det(2 * np.pi * S)))
    fs.log_weights = fs.log_weights + gain
    return gain


def resample(fs: FastSlamParticles, indices) -> FastSlamParticles:
    """The particles at ``indices`` (from :func:`~.particles.systematic_resample`), each
    with its whole map, at equal weights."""
    i = np.asarray(indices, dtype=np.int64)
    return FastSlamParticles(fs.poses[i].copy(), fs.means[i].copy(), fs.covs[i].copy(),
                             fs.seen[i].copy(), np.full(i.size, -np.log(i.size)))
