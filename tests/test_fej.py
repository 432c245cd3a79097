"""First-estimates Jacobians (FEJ; ``SlamConfig.first_estimates``, ``slam.efficient``).

Checked against what the filter code does not contain:
- the theory: without GPS nothing observes the global heading, so in any consistent
  linearisation the heading's variance can never fall below its initial value (the state
  is a global rigid motion, known only through its prior, composed with what the
  measurements see; Huang, Mourikis & Roumeliotis 2008). FEJ must keep that bound, to
  rounding; the standard EKF, whose Jacobians move with its estimates, breaks it;
- a dense textbook update and prediction with the Jacobians written out by hand (finite
  differences of ``models.observation.observe`` at the landmark's first estimate, the
  motion Jacobian at the prior position), against the efficient filter's in-place algebra.
"""
import math

import numpy as np
import pytest

from annslam_lib.data import simulate
from annslam_lib.evaluation import consistency
from annslam_lib.data.records import Odometry
from annslam_lib.models import motion
from annslam_lib.models.observation import observe
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig
from annslam_lib.slam.efficient import EkfSlam

SR, SB = 0.1, math.radians(1.0)


@pytest.fixture(scope="module")
def sim():
    return simulate.simulate(seed=7, laps=2, raw_laser=False)


def heading_variances(ds, fej: bool):
    # the simulator starts at the true pose; a prior of 2 deg on the heading gives the bound
    cfg = SlamConfig.for_dataset("simulated", association="truth", gps_mode="none",
                                 first_estimates=fej, initial_sigma_xy=0.1,
                                 initial_sigma_phi=math.radians(2.0))
    r = runner.run(ds, cfg, progress=False)
    return r.pose_cov[:, 2, 2], cfg.initial_sigma_phi ** 2


def test_fej_never_gains_information_on_the_global_heading(sim):
    var_fej, var0 = heading_variances(sim, True)
    var_std, _ = heading_variances(sim, False)
    assert var_fej.min() >= var0 * (1 - 1e-9), var_fej.min() / var0
    # the standard EKF claims to know the global heading better than its prior did
    # (measured: 0.26 of the prior variance at the end of this run)
    assert var_std.min() < 0.5 * var0, var_std.min() / var0


def _filter_after_updates(fej: bool):
    """A filter with three landmarks, moved and updated so that the current landmark
    estimates differ from the first ones and the pose has been corrected."""
    f = EkfSlam(np.array([1.0, 2.0, 0.4]), np.diag([0.04, 0.03, 0.01]), ACFR_UTE, "euler", fej=fej)
    f.augment(np.array([[8.0, 1.2], [12.0, 2.0], [6.0, 0.5]]), SR, SB)
    odo = Odometry(t=np.array([0.0, 0.1]), speed=np.full(2, 3.0), steering=np.full(2, 0.05))
    u = motion.control_table(odo, ACFR_UTE, 0.7, math.radians(7))[0]
    f.predict(u, 0.1)
    x, _ = f.state()
    z = observe(x[:3], x[3:].reshape(-1, 2))[0] + np.array([[0.3, 0.02], [-0.2, -0.03], [0.1, 0.01]])
    f.update(z, [0, 1, 2], SR, SB)
    return f, u


def _numeric_jacobian(fun, x, eps=1e-6):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps
        d = fun(x + e) - fun(x - e)
        d[1] = (d[1] + math.pi) % (2 * math.pi) - math.pi
        cols.append(d / (2 * eps))
    return np.column_stack(cols)


@pytest.mark.parametrize("gated", [False, True])
def test_fej_update_equals_a_dense_update_with_the_first_estimates_jacobian(gated):
    """Gated: the scan's gating computed the Jacobians the update then reuses."""
    f, _ = _filter_after_updates(True)
    x, P = (a.copy() for a in f.state())
    first = f._first.copy()
    assert np.abs(first - x[3:].reshape(-1, 2)).max() > 0.05    # the estimates have moved
    j = 1
    z = observe(x[:3], x[3 + 2 * j:5 + 2 * j])[0] + np.array([0.15, -0.01])
    # H at (pose, first estimate of landmark j), by finite differences of observe
    at = np.concatenate([x[:3], first[j]])
    Hd = _numeric_jacobian(lambda v: observe(v[:3], v[3:])[0], at)
    H = np.zeros((2, x.size))
    H[:, :3], H[:, 3 + 2 * j:5 + 2 * j] = Hd[:, :3], Hd[:, 3:]
    nu = z - observe(x[:3], x[3 + 2 * j:5 + 2 * j])[0]
    nu[1] = (nu[1] + math.pi) % (2 * math.pi) - math.pi
    S = H @ P @ H.T + np.diag([SR**2, SB**2])
    K = P @ H.T @ np.linalg.inv(S)
    x_ref, P_ref = x + K @ nu, P - K @ S @ K.T
    if gated:
        d2 = f.innovation_d2(z[None], SR, SB)[0, j]
        assert d2 == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-6)
    nis, dof = f.update(z[None], [j], SR, SB)
    x_new, P_new = f.state()
    assert nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-6) and dof == 2
    np.testing.assert_allclose(x_new, x_ref, rtol=0, atol=1e-8)
    np.testing.assert_allclose(P_new, P_ref, rtol=0, atol=1e-9)


def test_fej_prediction_uses_the_prior_position():
    """The first prediction after an update: F = [[1, 0, -(y' - y)], [0, 1, x' - x], [0, 0, 1]]
    with (x, y) the position before the update; the noise is the standard step's."""
    f, u = _filter_after_updates(True)
    g, _ = _filter_after_updates(False)
    x_prior = np.array([f.x[0] - f._cx, f.x[1] - f._cy])
    assert np.hypot(f._cx, f._cy) > 1e-3                      # the update moved the pose
    xf, Pf = (a.copy() for a in f.state())
    xg, Pg = (a.copy() for a in g.state())
    np.testing.assert_allclose(xf, xg, atol=1e-12)         # same estimates, different Jacobians
    dt = 0.1
    f.predict(u, dt)
    g.predict(u, dt)
    x1, P1 = f.state()
    xs1, Ps1 = g.state()
    np.testing.assert_allclose(x1, xs1, atol=1e-12)        # the mean is the same motion model
    F_std = np.eye(xg.size)
    F_std[0, 2], F_std[1, 2] = -(xs1[1] - xg[1]), xs1[0] - xg[0]
    Q = Ps1 - F_std @ Pg @ F_std.T                          # the standard step's noise
    F = np.eye(xf.size)
    F[0, 2], F[1, 2] = -(x1[1] - x_prior[1]), x1[0] - x_prior[0]
    np.testing.assert_allclose(P1, F @ Pf @ F.T + Q, rtol=0, atol=1e-12)
    assert f._cx == f._cy == 0.0                            # used once


def test_fej_augment_uses_the_prior_position_in_the_heading_column():
    f, _ = _filter_after_updates(True)
    x, P = (a.copy() for a in f.state())
    cx, cy = f._cx, f._cy
    z = np.array([[9.0, 1.0]])
    f.augment(z, SR, SB)
    x2, P2 = f.state()
    # l = p + R(phi) q: d l / d(x, y, phi) with the heading column at the prior position
    lm = x2[-2:]
    Jp = np.array([[1.0, 0.0, -(lm[1] - (x[1] - cy))], [0.0, 1.0, lm[0] - (x[0] - cx)]])
    np.testing.assert_allclose(P2[-2:, :3], Jp @ P[:3, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(P2[-2:, 3:-2], Jp @ P[:3, 3:], rtol=0, atol=1e-12)


def test_fej_keeps_first_estimates_through_remove_and_rejects_the_dense_backend(sim):
    f, _ = _filter_after_updates(True)
    first = f._first.copy()
    f.remove([1])
    np.testing.assert_array_equal(f._first, first[[0, 2]])
    assert f.x.size == 3 + 2 * f._first.shape[0]
    cfg = SlamConfig.for_dataset("simulated", first_estimates=True)
    with pytest.raises(ValueError, match="efficient backend only"):
        runner.run(sim, cfg, progress=False, backend="dense")
    with pytest.raises(TypeError, match="first_estimates"):
        SlamConfig(first_estimates="yes")
    with pytest.raises(TypeError, match="fej"):
        EkfSlam(np.zeros(3), np.eye(3) * 0.01, ACFR_UTE, fej=1)


def test_fej_removes_the_pose_over_confidence_of_an_uncertain_start():
    """20 simulated runs (seeds no notebook uses) whose filter starts at a draw from its own
    prior (2 deg of heading, 0.1 m): the standard filter's run-average pose NEES is above
    the FEJ filter's, by a paired 95 % interval that excludes zero (measured on 50 runs:
    5.09 against 2.65, interval of the difference -3.4 .. -1.5; notebook 05's default,
    the exact start, shows no difference: 3.17 against 3.19)."""
    kw = dict(draw_initial=True, initial_sigma_xy=0.1, initial_sigma_phi=math.radians(2.0),
              association="truth")
    seeds = tuple(range(400, 420))
    std = consistency.monte_carlo(seeds, "midpoint", first_estimates=False, **kw)
    fej = consistency.monte_carlo(seeds, "midpoint", first_estimates=True, **kw)
    d = fej.nees_runs.mean(axis=1) - std.nees_runs.mean(axis=1)
    half = 2.093 * d.std(ddof=1) / math.sqrt(d.size)          # t(19) 97.5 % quantile
    assert d.mean() + half < 0, (d.mean(), half)
    assert std.nees.mean > 3.5 and fej.nees.mean < 3.2, (std.nees.mean, fej.nees.mean)
