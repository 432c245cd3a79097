"""The particle filter's pieces (``slam.particles``) against independent references: the
resampling's counts against N w, the weights against scipy's Gaussian density, and the
cloud after sightings of a beacon against the Kalman posterior of the same, nearly
linear, problem."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from annslam_lib.models.geometry import wrap_angle
from annslam_lib.models.vehicle import Vehicle
from annslam_lib.slam import particles as pf
from annslam_lib.slam.unscented import ukf_update


def test_effective_sample_size_runs_from_one_to_n():
    assert pf.effective_sample_size(np.full(50, 0.02)) == pytest.approx(50)
    assert pf.effective_sample_size(np.eye(1, 50)[0]) == pytest.approx(1)
    with pytest.raises(ValueError, match="summing to 1"):
        pf.effective_sample_size([0.5, 0.6])


@pytest.mark.parametrize("seed", range(5))
def test_systematic_resampling_copies_each_particle_floor_or_ceil_of_n_w(seed):
    rng = np.random.default_rng(seed)
    w = rng.dirichlet(np.full(200, 0.3))
    counts = np.bincount(pf.systematic_resample(w, rng), minlength=200)
    assert counts.sum() == 200
    assert np.all(counts >= np.floor(200 * w) - 1e-9) and np.all(counts <= np.ceil(200 * w))


def test_normalising_survives_tiny_likelihoods_and_refuses_none():
    w = pf.normalise(np.array([-1e4, -1e4 - np.log(3), -np.inf]))
    np.testing.assert_allclose(w, [0.75, 0.25, 0.0])
    with pytest.raises(pf.ParticleDepletion, match="all 3 particle weights vanished"):
        pf.normalise(np.full(3, -np.inf))
    with pytest.raises(pf.ParticleDepletion):
        pf.normalise(np.array([0.0, np.nan]))


def test_the_weights_are_the_gaussian_likelihood():
    rng = np.random.default_rng(4)
    p = np.column_stack([rng.normal(0, 0.5, 30), rng.normal(0, 0.5, 30), rng.normal(1.5, 0.1, 30)])
    R = np.diag([0.1**2, 0.02**2])
    lm, z = np.array([0.0, 10.0]), np.array([10.1, 0.05])
    lw, d2 = pf.weigh(p, np.zeros(30), z, lm, R)
    from annslam_lib.models.observation import observe
    zhat = observe(p, np.broadcast_to(lm, (30, 2)))[0]
    nu = np.column_stack([z[0] - zhat[:, 0], wrap_angle(z[1] - zhat[:, 1])])
    want = multivariate_normal(np.zeros(2), R).logpdf(nu)
    np.testing.assert_allclose(lw, want, rtol=1e-10)
    np.testing.assert_allclose(d2, np.einsum("ni,ij,nj->n", nu, np.linalg.inv(R), nu))


def test_the_cloud_after_sightings_matches_the_kalman_posterior():
    """A car standing still (no motion noise) sees two beacons: 20 000 particles drawn from
    the prior; their weighted mean and covariance against the UKF's posterior of the same
    sightings (nearly linear here): means within 3 Monte-Carlo standard errors, standard
    deviations within 10 %."""
    rng = np.random.default_rng(5)
    prior, P0 = np.array([0.0, 0.0, np.pi / 2]), np.diag([0.3**2, 0.3**2, 0.02**2])
    R = np.diag([0.3**2, 0.02**2])
    beacons = [np.array([5.0, 20.0]), np.array([-8.0, 15.0])]
    truth = np.array([0.1, -0.2, np.pi / 2 + 0.01])
    from annslam_lib.models.observation import observe
    sightings = []
    for _ in range(1):
        for b in beacons:
            z = observe(truth, b)[0] + rng.multivariate_normal(np.zeros(2), R)
            sightings.append((z, b))
    n = 20_000
    parts = rng.multivariate_normal(prior, P0, n)
    w = np.full(n, 1.0 / n)
    parts, w, info = pf.mcl_step(parts, w, [0.0, 0.0], 0.0, Vehicle(), np.eye(2) * 1e-12,
                                 sightings, R, rng, resample_below=0.0)
    m, C = pf.estimate(parts, w)
    x, P = prior, P0
    for z, b in sightings:
        x, P, _ = ukf_update(x, P, z, b, R)
    se = np.sqrt(np.diag(P) / info["ess"])
    assert np.all(np.abs(m - x) < 3 * se + 1e-12), (m - x, se)
    np.testing.assert_allclose(np.sqrt(np.diag(C)), np.sqrt(np.diag(P)), rtol=0.1)
    assert info["ess"] > 100


def test_a_sighting_no_particle_fits_is_refused_or_skipped_and_counted():
    rng = np.random.default_rng(6)
    parts = rng.normal(0, 0.01, (100, 3))
    w = np.full(100, 0.01)
    far = [(np.array([1e6, 0.0]), np.array([0.0, 5.0]))]          # 1000 km: fits nobody
    R = np.diag([1e-6, 1e-8])
    with pytest.raises(pf.ParticleDepletion, match="fits none of the 100 particles"):
        pf.mcl_step(parts, w, [0.0, 0.0], 0.0, Vehicle(), np.eye(2) * 1e-12, far, R, rng)
    p2, w2, info = pf.mcl_step(parts, w, [0.0, 0.0], 0.0, Vehicle(), np.eye(2) * 1e-12, far,
                               R, rng, on_depletion="skip")
    assert info["skipped"] == 1 and np.allclose(w2, 0.01)
