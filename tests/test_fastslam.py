"""FastSLAM 1.0's per-particle landmark filters (``slam.fastslam``) against a Kalman filter
of the landmark written independently (the course's general ``kf_update`` with the
observation model's Jacobian), and its importance weights against scipy's density."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from annslam_lib.models.geometry import wrap_angle
from annslam_lib.models.observation import inverse_observe, observe
from annslam_lib.slam import fastslam as fsl
from annslam_lib.slam import particles as pf
from annslam_lib.slam.kalman import kf_update


def test_each_particles_landmark_filter_is_the_kalman_filter_of_its_path():
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.normal(0, 0.3, 5), rng.normal(0, 0.3, 5), rng.normal(0.2, 0.05, 5)])
    R = np.diag([0.05**2, 0.01**2])
    truth = np.array([6.0, 9.0])
    zs = [observe(np.array([0.0, 0.0, 0.2]), truth)[0] + rng.multivariate_normal([0, 0], R)
          for _ in range(4)]
    fs = fsl.start(poses, 3)
    gains = [fsl.sight(fs, z, 1, R) for z in zs]
    assert np.all(gains[0] == 0) and fs.seen[:, 1].all() and not fs.seen[:, [0, 2]].any()
    for i, pose in enumerate(poses):                         # each particle, by hand
        m, _, Jz = inverse_observe(pose, zs[0])
        P = Jz @ R @ Jz.T
        logw = 0.0
        for z in zs[1:]:
            zhat, _, H = observe(pose, m)
            nu = z - zhat
            nu[1] = wrap_angle(nu[1])
            logw += multivariate_normal(np.zeros(2), H @ P @ H.T + R).logpdf(nu)
            m, P = kf_update(m, P, nu + H @ m, H, R)
        np.testing.assert_allclose(fs.means[i, 1], m, atol=1e-10)
        np.testing.assert_allclose(fs.covs[i, 1], P, atol=1e-12)
        np.testing.assert_allclose(sum(g[i] for g in gains), logw, rtol=1e-10)


def test_the_weights_favour_the_paths_that_moved_as_the_car_did():
    """All particles start at the car's pose (as FastSLAM does: the start is the map's
    frame) and move with noisy controls while the car sees two landmarks: the weights
    favour the particles near the true pose (their weighted mean squared position error is
    under a quarter of the cloud's), and after resampling each copy carries its own map.
    (Sightings from one pose alone cannot tell particles apart: a particle's map is built
    from its own path, so it agrees with itself.)"""
    from annslam_lib.models.motion import predict
    from annslam_lib.models.vehicle import Vehicle

    rng = np.random.default_rng(1)
    veh = Vehicle()
    truth = np.array([0.0, 0.0, np.pi / 2])
    R = np.diag([0.02**2, 0.003**2])
    Q = np.diag([0.3**2, 0.03**2])
    u, dt = np.array([3.0, 0.1]), 0.5
    lms = [np.array([8.0, 12.0]), np.array([-5.0, 14.0])]
    fs = fsl.start(np.repeat(truth[None], 2000, 0), 2)
    for step in range(6):
        if step:
            truth = predict(truth, u, dt, veh)[0]
            fs.poses = pf.move(fs.poses, u, dt, veh, Q, rng)
        for j, lm in enumerate(lms):
            fsl.sight(fs, observe(truth, lm)[0] + rng.multivariate_normal([0, 0], R), j, R)
    w = pf.normalise(fs.log_weights)
    e2 = np.sum((fs.poses[:, :2] - truth[:2]) ** 2, axis=1)
    assert w @ e2 < 0.25 * e2.mean(), (w @ e2, e2.mean())
    idx = pf.systematic_resample(w, rng)
    out = fsl.resample(fs, idx)
    np.testing.assert_array_equal(out.means, fs.means[idx])
    np.testing.assert_array_equal(out.poses, fs.poses[idx])
    assert out.n == 2000 and np.allclose(out.log_weights, -np.log(2000))


def test_bad_sightings_are_refused():
    fs = fsl.start(np.zeros((3, 3)), 2)
    with pytest.raises(ValueError, match="range must be > 0"):
        fsl.sight(fs, [0.0, 1.0], 0, np.eye(2))
    with pytest.raises(ValueError):
        fsl.sight(fs, [1.0, 1.0], 5, np.eye(2))
    with pytest.raises(ValueError):
        fsl.start(np.zeros((0, 3)), 2)
