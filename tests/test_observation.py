"""Observation model (annslam_lib.observation): laser convention, Jacobians by finite
differences and SymPy, round trips, the two-point landmark frame, bad input."""
import numpy as np
import pytest
import sympy as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st


from annslam_lib.models.geometry import numerical_jacobian, wrap_angle
from annslam_lib.models import observation

HYP = settings(max_examples=200, deadline=None, derandomize=True)
coord = st.floats(-100.0, 100.0)
near_pi = st.floats(np.pi - 1e-3, np.pi) | st.floats(-np.pi, -np.pi + 1e-3)
heading = st.floats(-np.pi, np.pi) | near_pi
offset = st.floats(-40.0, 40.0)


def assert_jac(J, J_fd, scale=1.0):
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-8 * max(1.0, scale))


# ------------------------------------------------------------- convention

def test_laser_bearing_convention():
    """pi/2 straight ahead, 0 to the right, pi to the left, whatever the heading."""
    for phi in (0.0, 1.0, -2.5, np.pi):
        pose = np.array([2.0, -1.0, phi])
        ahead = pose[:2] + 5 * np.array([np.cos(phi), np.sin(phi)])
        right = pose[:2] + 3 * np.array([np.sin(phi), -np.cos(phi)])
        left = pose[:2] - 4 * np.array([np.sin(phi), -np.cos(phi)])
        z, _, _ = observation.observe(pose, np.array([ahead, right, left]))
        np.testing.assert_allclose(z[:, 0], [5, 3, 4])
        np.testing.assert_allclose(z[:, 1], [np.pi / 2, 0, np.pi], atol=1e-12)
    # behind: -pi/2 (wrapped), never 3 pi / 2
    z, _, _ = observation.observe([0, 0, 0], [-2, 0])
    assert z[1] == pytest.approx(-np.pi / 2)


def test_bearing_matches_laser_points():
    """A landmark observed at (r, beta) lies where Laser.points puts beam beta."""
    pose = np.array([1.0, 2.0, 0.7])
    z = np.array([[6.0, 0.3], [2.0, 2.9]])
    lm, _, _ = observation.inverse_observe(pose, z)
    local = np.c_[z[:, 0] * np.sin(z[:, 1]), -z[:, 0] * np.cos(z[:, 1])]    # records.Laser.points
    c, s = np.cos(pose[2]), np.sin(pose[2])
    world = pose[:2] + local @ np.array([[c, s], [-s, c]])
    np.testing.assert_allclose(lm, world, atol=1e-12)


# ------------------------------------------------------- finite differences

@HYP
@given(x=coord, y=coord, phi=heading, dx=offset, dy=offset)
def test_observe_jacobians(x, y, phi, dx, dy):
    assume(np.hypot(dx, dy) > 0.5)
    pose, lm = np.array([x, y, phi]), np.array([x + dx, y + dy])
    z, Hp, Hl = observation.observe(pose, lm)
    assert -np.pi < z[1] <= np.pi
    Hp_fd = numerical_jacobian(lambda q: observation.observe(q, lm)[0], pose, angle_outputs=[1])
    Hl_fd = numerical_jacobian(lambda m: observation.observe(pose, m)[0], lm, angle_outputs=[1])
    assert_jac(Hp, Hp_fd, 100)
    assert_jac(Hl, Hl_fd, 100)
    np.testing.assert_allclose(Hl, -Hp[:, :2], atol=1e-15)   # only lm - position matters


@HYP
@given(x=coord, y=coord, phi=heading, r=st.floats(0.5, 80.0), beta=heading)
def test_inverse_observe_jacobians_and_round_trip(x, y, phi, r, beta):
    pose, z = np.array([x, y, phi]), np.array([r, beta])
    lm, Jp, Jz = observation.inverse_observe(pose, z)
    assert_jac(Jp, numerical_jacobian(lambda q: observation.inverse_observe(q, z)[0], pose), 200)
    assert_jac(Jz, numerical_jacobian(lambda q: observation.inverse_observe(pose, q)[0], z), 200)
    z2, Hp, Hl = observation.observe(pose, lm)
    assert z2[0] == pytest.approx(r, rel=1e-9)
    assert abs(wrap_angle(z2[1] - beta)) < 1e-9
    # the inverse model's Jacobian w.r.t. z inverts the observation's w.r.t. the landmark
    np.testing.assert_allclose(Hl @ Jz, np.eye(2), atol=1e-8)


@HYP
@given(xr=coord, yr=coord, xl=coord, yl=coord)
def test_two_point_jacobians(xr, yr, xl, yl):
    assume(np.hypot(xr - xl, yr - yl) > 0.5)
    pr, pl = np.array([xr, yr]), np.array([xl, yl])
    f, Jr, Jl = observation.landmark_from_two_points(pr, pl)
    assert -np.pi < f[2] <= np.pi
    assert_jac(Jr, numerical_jacobian(lambda q: observation.landmark_from_two_points(q, pl)[0], pr,
                                      angle_outputs=[2]), 300)
    assert_jac(Jl, numerical_jacobian(lambda q: observation.landmark_from_two_points(pr, q)[0], pl,
                                      angle_outputs=[2]), 300)


# ------------------------------------------------------------------- SymPy

@pytest.fixture(scope="module")
def symbolic():
    x, y, phi, xi, yi, r, be = sp.symbols("x y phi x_i y_i r beta", real=True)
    h = sp.Matrix([sp.sqrt((xi - x) ** 2 + (yi - y) ** 2),
                   sp.atan2(yi - y, xi - x) - phi + sp.pi / 2])
    g = sp.Matrix([x + r * sp.cos(phi + be - sp.pi / 2), y + r * sp.sin(phi + be - sp.pi / 2)])
    fns = {
        "h": (h, (x, y, phi, xi, yi)),
        "H_pose": (h.jacobian([x, y, phi]), (x, y, phi, xi, yi)),
        "H_landmark": (h.jacobian([xi, yi]), (x, y, phi, xi, yi)),
        "g": (g, (x, y, phi, r, be)),
        "J_pose": (g.jacobian([x, y, phi]), (x, y, phi, r, be)),
        "J_z": (g.jacobian([r, be]), (x, y, phi, r, be)),
    }
    return {k: sp.lambdify(args, e, "numpy") for k, (e, args) in fns.items()}


def test_observe_matches_sympy(symbolic):
    rng = np.random.default_rng(21)
    pose = np.c_[rng.uniform(-50, 50, (100, 2)), rng.uniform(-np.pi, np.pi, 100)]
    lm = pose[:, :2] + rng.uniform(-30, 30, (100, 2))
    z, Hp, Hl = observation.observe(pose, lm)          # batched over poses and landmarks
    for k in range(100):
        args = (*pose[k], *lm[k])
        ref = np.asarray(symbolic["h"](*args), float).ravel()
        assert z[k, 0] == pytest.approx(ref[0], abs=1e-10)
        assert abs(wrap_angle(z[k, 1] - ref[1])) < 1e-10
        np.testing.assert_allclose(Hp[k], np.asarray(symbolic["H_pose"](*args), float), atol=1e-10)
        np.testing.assert_allclose(Hl[k], np.asarray(symbolic["H_landmark"](*args), float),
                                   atol=1e-10)


def test_inverse_observe_matches_sympy(symbolic):
    rng = np.random.default_rng(22)
    pose = np.r_[rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
    z = np.c_[rng.uniform(0.5, 80, 50), rng.uniform(-np.pi, np.pi, 50)]
    lm, Jp, Jz = observation.inverse_observe(pose, z)           # one pose, M measurements
    assert lm.shape == (50, 2) and Jp.shape == (50, 2, 3) and Jz.shape == (50, 2, 2)
    for k in range(50):
        args = (*pose, *z[k])
        np.testing.assert_allclose(lm[k], np.asarray(symbolic["g"](*args), float).ravel(),
                                   atol=1e-10)
        np.testing.assert_allclose(Jp[k], np.asarray(symbolic["J_pose"](*args), float), atol=1e-10)
        np.testing.assert_allclose(Jz[k], np.asarray(symbolic["J_z"](*args), float), atol=1e-10)


def test_vectorised_observe_equals_loop():
    pose = np.array([3.0, -2.0, -3.1])
    lm = np.array([[10.0, 4.0], [-7.0, -2.0], [3.0, 5.0]])
    z, Hp, Hl = observation.observe(pose, lm)
    assert z.shape == (3, 2) and Hp.shape == (3, 2, 3) and Hl.shape == (3, 2, 2)
    for k in range(3):
        zk, Hpk, Hlk = observation.observe(pose, lm[k])
        np.testing.assert_allclose(z[k], zk)
        np.testing.assert_allclose(Hp[k], Hpk)
        np.testing.assert_allclose(Hl[k], Hlk)


@given(coord, coord, heading, st.lists(st.tuples(offset, offset), min_size=1, max_size=6))
@HYP
def test_value_only_copies_are_bitwise_observe(x, y, phi, offsets):
    """observe_values / inverse_observe_values: the same numbers as observe / inverse_observe
    to the last bit (they are the run-time copies of the ANN pseudo-measurement)."""
    pose = np.array([x, y, phi])
    lm = pose[:2] + np.array(offsets)
    assume(np.all(np.hypot(*(lm - pose[:2]).T) > 1e-3))
    z = observation.observe(pose, lm)[0]
    np.testing.assert_array_equal(observation.observe_values(pose, lm), z)
    np.testing.assert_array_equal(observation.inverse_observe_values(pose, z),
                                  observation.inverse_observe(pose, z)[0])
    poses = np.broadcast_to(pose, (lm.shape[0], 3))
    np.testing.assert_array_equal(observation.inverse_observe_values(poses, z),
                                  observation.inverse_observe(poses, z)[0])


def test_value_only_copies_refuse_what_observe_refuses():
    pose = np.array([1.0, 2.0, 0.3])
    with pytest.raises(ValueError, match="coincides"):
        observation.observe_values(pose, np.array([[1.0, 2.0]]))
    with pytest.raises(ValueError, match="range must be > 0"):
        observation.inverse_observe_values(pose, np.array([[0.0, 1.0]]))
    assert observation.observe_values(pose, np.empty((0, 2))).shape == (0, 2)


# -------------------------------------------------------- two-point frame

def test_two_point_frame_geometry():
    rng = np.random.default_rng(7)
    pr, pl = rng.uniform(-10, 10, (40, 2)), rng.uniform(-10, 10, (40, 2))
    f, _, _ = observation.landmark_from_two_points(pr, pl)
    T = observation.two_point_transform(pr, pl)
    h = lambda p: np.c_[p, np.ones(len(p))][..., None]  # noqa: E731
    # ijT_r sends the left point to the origin and the right point onto the +x axis
    np.testing.assert_allclose((T @ h(pl))[:, :2, 0], 0, atol=1e-12)
    onto = (T @ h(pr))[:, :2, 0]
    np.testing.assert_allclose(onto[:, 0], np.linalg.norm(pr - pl, axis=1), atol=1e-12)
    np.testing.assert_allclose(onto[:, 1], 0, atol=1e-12)
    # (i, j) is the robot origin seen from the landmark frame
    np.testing.assert_allclose(f[:, :2], T[:, :2, 2])


@pytest.mark.parametrize("pr, pl, theta", [
    ([3.0, 1.0], [1.0, 1.0], 0.0),                 # X_l < X_r
    ([2.0, -1.0], [2.0, 1.0], -np.pi / 2),          # vertical, y_r < y_l
    ([2.0, 3.0], [2.0, 1.0], np.pi / 2),            # vertical, y_r > y_l: +pi/2, not -pi/2
    ([1.0, 0.0], [3.0, 2.0], -3 * np.pi / 4),       # X_l > X_r, y_r < y_l: arctan - pi
    ([1.0, 2.0], [3.0, 0.0], 3 * np.pi / 4),        # X_l > X_r, y_r > y_l: arctan + pi
    ([1.0, 1.0], [3.0, 1.0], np.pi),                # pointing backwards: +pi, not -pi
])
def test_two_point_theta_cases(pr, pl, theta):
    assert observation.landmark_from_two_points(pr, pl)[0][2] == pytest.approx(theta, abs=1e-15)


# --------------------------------------------------------------- bad input

@pytest.mark.parametrize("call, match", [
    (lambda: observation.observe([1.0, 2.0, 0.3], [1.0, 2.0]), "landmark coincides with the sensor"),
    (lambda: observation.observe([1.0, 2.0, 0.3], [[5, 5], [1.0 + 1e-10, 2.0]]), "coincides"),
    (lambda: observation.observe([1.0, 2.0], [5.0, 5.0]), "pose must have shape"),
    (lambda: observation.observe([1.0, 2.0, 0.0], [5.0, 5.0, 1.0]), "landmark must have shape"),
    (lambda: observation.observe([1.0, 2.0, np.nan], [5.0, 5.0]), "pose contains NaN"),
    (lambda: observation.observe([1.0, 2.0, 0.0], [np.inf, 5.0]), "landmark contains NaN"),
    (lambda: observation.inverse_observe([0, 0, 0], [0.0, 1.0]), "range must be > 0"),
    (lambda: observation.inverse_observe([0, 0, 0], [[3.0, 1.0], [-1.0, 1.0]]), "range must be > 0"),
    (lambda: observation.inverse_observe([0, 0, 0], [1.0]), "z must have shape"),
    (lambda: observation.inverse_observe([0, 0, 0], [1.0, np.nan]), "z contains NaN"),
    (lambda: observation.landmark_from_two_points([1, 1], [1, 1]), "coincide"),
    (lambda: observation.landmark_from_two_points([1, 1, 0], [1, 1]), "p_right must have shape"),
    (lambda: observation.landmark_from_two_points([1, 1], [np.nan, 1]), "p_left contains NaN"),
])
def test_bad_input_raises(call, match):
    with pytest.raises(ValueError, match=match):
        call()
