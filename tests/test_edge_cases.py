"""Numeric edge cases of the public API (issue: nothing lost, nothing leaked).

Each fault found by hand has its own test; then a property-based pass (hypothesis) feeds the
array functions NaN, inf, empty arrays, wrong shapes and extreme scales and holds them to
one contract: either a clear TypeError/ValueError, or an answer that is finite, of the right
shape, and equal to an independent formula. Returning anything for an input that should be
refused, or a non-finite or wrong answer for a valid one, is a silent wrong answer."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from annslam_lib import ann
from annslam_lib.data.records import Odometry
from annslam_lib.evaluation import map as map_eval
from annslam_lib.models import geometry, motion, observation
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.perception import association

PROP = settings(max_examples=300, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
CLEAR = (TypeError, ValueError)


# ------------------------------------------------------------------ the faults, one by one

@pytest.mark.parametrize("scale", [1e200, 1e-170, 1e-300, 1e300])
def test_mahalanobis_accepts_spd_matrices_at_extreme_scale(scale):
    """a c overflows (1e200 I) or underflows (1e-170 I) although S is a fine covariance: the
    Cholesky form gives d2 = |nu|^2 / scale, the determinant form refused it."""
    S = np.array([[[scale, 0.3 * scale], [0.3 * scale, 2.0 * scale]]])
    nu = np.array([math.sqrt(scale) * 1.5, math.sqrt(scale) * 0.25])   # bearing below pi
    if nu[1] > math.pi:
        nu[1] = 0.0
    z = nu[None, :]
    d2 = association.mahalanobis(z, np.zeros((1, 2)), S)
    # independent: the same quadratic form with everything scaled to O(1) first
    Sn, nun = S[0] / scale, nu / math.sqrt(scale)
    ref = float(nun @ np.linalg.solve(Sn, nun))
    assert d2.shape == (1, 1) and math.isfinite(d2[0, 0])
    assert d2[0, 0] == pytest.approx(ref, rel=1e-12)


def test_mahalanobis_still_refuses_a_singular_or_indefinite_s():
    for S in ([[1.0, 1.0], [1.0, 1.0]], [[1.0, 2.0], [2.0, 1.0]], [[0.0, 0.0], [0.0, 1.0]],
              [[1e200, 1e200], [1e200, 1e200]]):
        with pytest.raises(ValueError, match="not positive definite"):
            association.mahalanobis(np.zeros((1, 2)), np.ones((1, 2)), np.array([S]))


@pytest.mark.parametrize("distance", [1e154, 1e200, 1e300])
def test_observe_far_landmarks_keeps_range_and_jacobians(distance):
    """x*x overflows beyond 1e154; hypot does not: range, bearing and Jacobians stay finite
    and equal to the scaled-down problem times the scale."""
    pose = np.array([0.0, 0.0, 0.3])
    lm = np.array([0.6, 0.8]) * distance
    z, Hp, Hl = observation.observe(pose, lm)
    z1, Hp1, Hl1 = observation.observe(pose, np.array([0.6, 0.8]))
    assert np.all(np.isfinite(z)) and np.all(np.isfinite(Hp)) and np.all(np.isfinite(Hl))
    assert z[0] == pytest.approx(distance, rel=1e-15) and z[1] == pytest.approx(z1[1], abs=1e-15)
    np.testing.assert_allclose(Hl[0], Hl1[0], rtol=1e-15)                 # unit vector row
    np.testing.assert_allclose(Hl[1] * distance, Hl1[1], rtol=1e-12)      # 1 / r row
    np.testing.assert_array_equal(observation.observe_values(pose, lm[None, :]), z[None, :])


@pytest.mark.parametrize("value", [np.int64(2), np.float32(2.0), np.int32(2), 2, 2.0])
def test_match_landmarks_takes_numpy_scalars(value):
    a = np.array([[0.0, 0.0], [5.0, 5.0]])
    i, j = map_eval.match_landmarks(a, a + 1.0, value)
    assert i.tolist() == j.tolist() == [0, 1]
    with pytest.raises(TypeError, match="max_distance must be a number"):
        map_eval.match_landmarks(a, a, np.bool_(True))


def test_rigid_align_onto_identical_points_is_undefined():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    with pytest.raises(ValueError, match="points of b all coincide"):
        map_eval.rigid_align(a, np.ones((3, 2)))
    with pytest.raises(ValueError, match="points of a all coincide"):
        map_eval.rigid_align(np.ones((3, 2)), a)


def test_training_on_one_sample_is_refused():
    rng = np.random.default_rng(0)
    n = 20
    ts = ann.TrainingSet(X=rng.normal(size=(n, len(ann.FEATURE_NAMES))), Y=rng.normal(size=(n, 2)),
                         base=rng.normal(size=(n, 2)), target=rng.normal(size=(n, 2)),
                         beacon=np.arange(n) % 4, t=np.arange(n, dtype=float), scan=np.arange(n))
    one = ann.Split(train=np.array([0]), val=np.arange(1, 10), test=np.arange(10, 20))
    with pytest.raises(ValueError, match="training part has 1 sample"):
        ann.train(ts, one)


def test_mismatched_shapes_name_the_arguments():
    with pytest.raises(ValueError, match=r"encoder_speed \(3,\), steering \(2,\)"):
        motion.axle_speed(np.ones(3), np.zeros(2), ACFR_UTE)
    with pytest.raises(ValueError, match=r"pose \(3,\), landmark \(2,\)"):
        observation.observe(np.zeros((3, 3)), np.ones((2, 2)) + 5.0)
    with pytest.raises(ValueError, match=r"pose \(3,\), z \(2,\)"):
        observation.inverse_observe(np.zeros((3, 3)), np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"pose must be \(3,\) or \(4, 3\), got \(5, 3\)"):
        ann.encode(np.zeros((5, 3)), np.ones((4, 2)))
    with pytest.raises(ValueError, match=r"z must be \(n, 2\)"):
        ann.encode(np.zeros(3), np.ones((4, 3)))       # was read silently as 6 pairs


def test_odometry_whose_clock_stands_still_is_blamed_on_the_odometry():
    with pytest.raises(ValueError, match="odometry clock is not running"):
        Odometry(t=np.zeros(50), speed=np.ones(50), steering=np.zeros(50))
    Odometry(t=np.zeros(1), speed=np.ones(1), steering=np.zeros(1))     # one sample: fine


# ------------------------------------------------------------------ property-based contract

nasty = st.one_of(st.floats(-1e300, 1e300), st.sampled_from([0.0, -0.0, 1e-300, -1e-300,
                                                             1e154, -1e154, math.pi, -math.pi]),
                  st.sampled_from([math.nan, math.inf, -math.inf]))
finite = st.one_of(st.floats(-1e6, 1e6), st.sampled_from([1e-170, 1e150, -1e150, math.pi]))


def arrays(tail, elements=nasty, max_batch=3):
    """Arrays whose last axis is usually ``tail`` but not always, batches of 0..max_batch."""
    shapes = st.one_of(
        hnp.array_shapes(min_dims=1, max_dims=2, min_side=0, max_side=max_batch).map(
            lambda s: s[:-1] + (tail,)),
        hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4))
    return shapes.flatmap(lambda s: hnp.arrays(np.float64, s, elements=elements))


def _valid(*arrs):
    return all(np.all(np.isfinite(a)) for a in arrs)


def _broadcasts(*shapes):
    try:
        np.broadcast_shapes(*shapes)
        return True
    except ValueError:
        return False


@given(pose=arrays(3), lm=arrays(2))
@PROP
def test_property_observe(pose, lm):
    ok_shape = (pose.ndim >= 1 and pose.shape[-1] == 3 and lm.ndim >= 1 and lm.shape[-1] == 2
                and _broadcasts(pose.shape[:-1], lm.shape[:-1]))
    try:
        z, Hp, Hl = observation.observe(pose, lm)
    except CLEAR:
        return
    assert ok_shape and _valid(pose, lm), "an invalid input was accepted"
    dx, dy = lm[..., 0] - pose[..., 0], lm[..., 1] - pose[..., 1]
    r = np.hypot(dx, dy)
    assert np.all(np.isfinite(z)) and np.all(np.isfinite(Hp)) and np.all(np.isfinite(Hl))
    np.testing.assert_allclose(z[..., 0], r, rtol=1e-12)
    bearing = geometry.wrap_angle(np.arctan2(dy, dx) - pose[..., 2] + np.pi / 2)
    d = geometry.wrap_angle(z[..., 1] - bearing)
    # atan2 of the rotated vector against atan2 minus phi: equal to the rounding of phi
    assert np.all(np.abs(d) <= 1e-12 * np.maximum(1.0, np.abs(pose[..., 2])) + 1e-13)


@given(pose=arrays(3), z=arrays(2))
@PROP
def test_property_inverse_observe(pose, z):
    try:
        lm = observation.inverse_observe(pose, z)[0]
    except CLEAR:
        return
    assert _valid(pose, z) and pose.shape[-1] == 3 and z.shape[-1] == 2
    assert np.all(z[..., 0] > 0) and np.all(np.isfinite(lm))
    ang = pose[..., 2] + z[..., 1] - np.pi / 2
    ref = np.stack([pose[..., 0] + z[..., 0] * np.cos(ang), pose[..., 1] + z[..., 0] * np.sin(ang)], -1)
    scale = np.maximum(np.abs(pose[..., :2]).max(-1, initial=0) + z[..., 0], 1.0)
    assert np.all(np.abs(lm - ref).max(-1, initial=0) <= 1e-9 * scale * np.maximum(1, np.abs(ang)))


spd = st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-0.99, 0.99),
                st.sampled_from([1e-170, 1e-20, 1.0, 1e20, 1e200]))


@given(z=arrays(2, finite), zhat=arrays(2, finite), params=st.lists(spd, min_size=0, max_size=3),
       poison=st.sampled_from([None, "nan", "asym", "neg"]))
@PROP
def test_property_mahalanobis(z, zhat, params, poison):
    S = np.array([[[s * math.exp(2 * la), s * rho * math.exp(la + lb)],
                   [s * rho * math.exp(la + lb), s * math.exp(2 * lb)]] for la, lb, rho, s in params]
                 ).reshape(-1, 2, 2)
    if poison and S.size:
        S[0, 0, 1] = {"nan": math.nan, "asym": 2 * S[0, 0, 1] + S[0, 0, 0], "neg": S[0, 0, 1]}[poison]
        if poison == "neg":
            S[0, 1, 1] = -S[0, 1, 1]
    try:
        d2 = association.mahalanobis(z, zhat, S)
    except CLEAR:
        return
    assert poison is None or S.size == 0 or poison == "asym" and S[0, 0, 1] == 0
    assert z.ndim == 2 and zhat.ndim == 2 and S.shape[0] == zhat.shape[0]
    assert d2.shape == (z.shape[0], zhat.shape[0]) and np.all(d2 >= 0)
    for j in range(zhat.shape[0]):                     # independent: scale out, then solve
        s = math.sqrt(S[j, 0, 0] * 1.0) * math.sqrt(S[j, 1, 1] * 1.0)
        Sn = S[j] / s
        for i in range(z.shape[0]):
            nu = z[i] - zhat[j]
            nu[1] = geometry.wrap_angle(nu[1])
            ref = float((nu / math.sqrt(s)) @ np.linalg.solve(Sn, nu / math.sqrt(s)))
            if math.isfinite(ref):
                assert d2[i, j] == pytest.approx(ref, rel=1e-8, abs=1e-300)


@given(a=arrays(2, max_batch=5), b=arrays(2, max_batch=5))
@PROP
def test_property_rigid_align(a, b):
    try:
        R, t = map_eval.rigid_align(a, b)
    except CLEAR:
        return
    assert a.shape == b.shape and a.ndim == 2 and a.shape[0] >= 2 and _valid(a, b)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(t))
    np.testing.assert_allclose(R @ R.T, np.eye(2), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-9)


@given(a=arrays(2, max_batch=5), b=arrays(2, max_batch=5))
@PROP
def test_property_point_rmse(a, b):
    try:
        got = map_eval.point_rmse(a, b)
    except CLEAR:
        return
    assert a.shape == b.shape and a.ndim == 2 and a.shape[0] >= 1 and _valid(a, b)
    d = a - b
    ref = math.sqrt(sum(math.hypot(*row) ** 2 for row in d.tolist()) / len(d)) \
        if np.all(np.abs(d) < 1e150) else None
    assert math.isfinite(got) or ref is None
    if ref is not None:
        assert got == pytest.approx(ref, rel=1e-12)


@given(x=arrays(1, max_batch=4))
@PROP
def test_property_wrap_angle(x):
    try:
        w = geometry.wrap_angle(x)
    except CLEAR:
        return
    assert _valid(x)
    w = np.asarray(w)
    assert w.shape == x.shape and np.all((w > -np.pi) & (w <= np.pi))
    small = np.abs(x) < 1e6
    np.testing.assert_allclose(np.cos(w[small]), np.cos(x[small]), atol=1e-9)


@given(v=arrays(1, max_batch=4), alpha=arrays(1, max_batch=4))
@PROP
def test_property_axle_speed(v, alpha):
    try:
        vc, J = motion.axle_speed(v, alpha, ACFR_UTE)
    except CLEAR:
        return
    assert _valid(v, alpha) and np.all(np.abs(alpha) < np.pi / 2)
    assert np.all(np.isfinite(vc)) or np.any(np.abs(v) > 1e290)
    ref = v / (1 - np.tan(alpha) * ACFR_UTE.H / ACFR_UTE.L)
    np.testing.assert_allclose(vc, ref, rtol=1e-12)


@given(pose=arrays(3), z=arrays(2))
@PROP
def test_property_encode(pose, z):
    try:
        X, base = ann.encode(pose, z)
    except CLEAR:
        return
    assert _valid(pose, z) and z.shape[-1] == 2 and np.all(z[..., 0] > 0)
    n = z.reshape(-1, 2).shape[0]
    assert X.shape == (n, len(ann.FEATURE_NAMES)) and base.shape == (n, 2)
    assert np.all(np.isfinite(X))
    np.testing.assert_array_equal(base, observation.inverse_observe(
        np.broadcast_to(pose, (n, 3)), z.reshape(-1, 2))[0])


@pytest.mark.parametrize("scale", [1e-200, 1e200, 1e300])
def test_point_rmse_at_extreme_scale(scale):
    a = np.array([[3.0, 4.0], [0.0, 0.0]]) * scale
    assert map_eval.point_rmse(a) == pytest.approx(scale * math.sqrt(12.5), rel=1e-15)
    with pytest.raises(ValueError, match="pair up"):
        map_eval.point_rmse(a, a[:1])                 # (2, 2) against (1, 2): no broadcasting
