"""Motion model (annslam_lib.kinematics) and geometry blocks: Jacobians by finite
differences and by SymPy, exact-arc properties, Euler convergence, bad input."""
import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp


from annslam_lib.models.geometry import numerical_jacobian, wrap_angle
from annslam_lib.models.vehicle import ACFR_UTE, Vehicle
from annslam_lib.models import geometry
from annslam_lib.models import motion

V = ACFR_UTE
HYP = settings(max_examples=200, deadline=None, derandomize=True)

coord = st.floats(-200.0, 200.0)
# Headings anywhere, with extra weight right next to +-pi where the wrap happens.
near_pi = st.floats(np.pi - 1e-3, np.pi) | st.floats(-np.pi, -np.pi + 1e-3)
heading = st.floats(-np.pi, np.pi) | near_pi
speed = st.floats(-5.0, 5.0)
steer = st.floats(-0.65, 0.65)
dt_s = st.floats(0.0, 0.5)
vehicles = st.builds(Vehicle, L=st.floats(1.0, 4.0), H=st.floats(-1.0, 1.0),
                     a=st.floats(-4.0, 4.0), b=st.floats(-1.0, 1.0))


def assert_jac(J, J_fd, scale=1.0):
    """Relative tolerance 1e-6 on each entry, with an absolute floor tied to the
    magnitude of the differentiated values (central-difference round-off)."""
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-8 * max(1.0, scale))


# --------------------------------------------------------------- geometry

def test_wrap_angle_range_and_ends():
    a = np.array([np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0, 7.0, -7.0])
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    assert w[0] == np.pi and w[1] == np.pi and w[2] == pytest.approx(np.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    assert wrap_angle(7.0) == pytest.approx(7.0 - 2 * np.pi)


def test_rot_is_rotation():
    R = geometry.rot([0.3, -2.0])
    assert R.shape == (2, 2, 2)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(2), R.shape),
                               atol=1e-14)
    np.testing.assert_allclose(R[0] @ [1.0, 0.0], [np.cos(0.3), np.sin(0.3)])


@HYP
@given(x=coord, y=coord, phi=heading, px=coord, py=coord)
def test_frame_jacobians(x, y, phi, px, py):
    pose, p = np.array([x, y, phi]), np.array([px, py])
    loc, J_pose, J_p = geometry.to_frame(pose, p)
    assert_jac(J_pose, numerical_jacobian(lambda q: geometry.to_frame(q, p)[0], pose), 400)
    assert_jac(J_p, numerical_jacobian(lambda q: geometry.to_frame(pose, q)[0], p), 400)
    back, K_pose, K_q = geometry.from_frame(pose, loc)
    np.testing.assert_allclose(back, p, atol=1e-9)
    assert_jac(K_pose, numerical_jacobian(lambda q: geometry.from_frame(q, loc)[0], pose), 400)
    assert_jac(K_q, numerical_jacobian(lambda q: geometry.from_frame(pose, q)[0], loc), 400)


# ------------------------------------------------------- finite differences

@HYP
@given(v_e=speed, alpha=st.floats(-1.1, 1.1), veh=vehicles)
def test_axle_speed_jacobian(v_e, alpha, veh):
    d = 1 - np.tan(alpha) * veh.H / veh.L
    if abs(d) < 0.05:       # too close to the singularity for a stable difference
        return
    v_c, J = motion.axle_speed(v_e, alpha, veh)
    J_fd = numerical_jacobian(lambda u: motion.axle_speed(u[0], u[1], veh)[0], [v_e, alpha])
    assert J.shape == (2,)
    assert_jac(J, J_fd[0], abs(v_c) / abs(d))


@HYP
@given(x=coord, y=coord, phi=heading, veh=vehicles)
def test_laser_and_axle_pose_jacobians(x, y, phi, veh):
    p = np.array([x, y, phi])
    lp, J = motion.laser_pose(p, veh)
    assert_jac(J, numerical_jacobian(lambda q: motion.laser_pose(q, veh)[0], p,
                                     angle_outputs=[2]), 200)
    ap, K = motion.axle_pose(lp, veh)
    assert_jac(K, numerical_jacobian(lambda q: motion.axle_pose(q, veh)[0], lp,
                                     angle_outputs=[2]), 200)
    np.testing.assert_allclose(ap, p, atol=1e-10)          # axle_pose inverts laser_pose
    np.testing.assert_allclose(J @ K, np.eye(3), atol=1e-12)


def test_axle_pose_inverts_laser_pose_and_puts_the_laser_at_a_b_in_the_car_frame():
    """Notebook 02, exercise 2.1's reference: a round trip both ways, and an independent
    check through the frame change (the laser, seen from the returned axle pose, sits at
    (a, b)), batched over cars' offsets and headings near +-pi."""
    rng = np.random.default_rng(21)
    n = 500
    poses = np.c_[rng.uniform(-100, 100, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    poses[:4, 2] = [np.pi, -np.pi + 1e-12, 0.0, np.pi / 2]
    for veh in (V, Vehicle(L=2.0, H=0.5, a=-1.3, b=-0.8), Vehicle(L=2.0, H=0.5, a=0.0, b=1.0)):
        axle, K = motion.axle_pose(poses, veh)
        assert axle.shape == poses.shape and K.shape == (n, 3, 3)
        np.testing.assert_array_equal(axle[:, 2], poses[:, 2])          # heading shared
        local = geometry.to_frame(axle, poses[:, :2])[0]
        np.testing.assert_allclose(local, np.broadcast_to([veh.a, veh.b], (n, 2)), atol=1e-11)
        np.testing.assert_allclose(motion.laser_pose(axle, veh)[0], poses, atol=1e-11)
        np.testing.assert_allclose(motion.axle_pose(motion.laser_pose(poses, veh)[0], veh)[0],
                                   poses, atol=1e-11)
        K_fd = numerical_jacobian(lambda q: motion.axle_pose(q, veh)[0], poses[7],
                                  angle_outputs=[2])
        assert_jac(K[7], K_fd, 200)
    # one pose by hand: laser at the origin heading +y; C is a behind (-y) and b to the right (+x)
    np.testing.assert_allclose(motion.axle_pose([0.0, 0.0, np.pi / 2], V)[0],
                               [V.b, -V.a, np.pi / 2], atol=1e-15)


@HYP
@given(x=coord, y=coord, phi=heading, v=speed, alpha=steer, dt=dt_s, veh=vehicles)
def test_predict_jacobians(x, y, phi, v, alpha, dt, veh):
    p, u = np.array([x, y, phi]), np.array([v, alpha])
    nxt, F, G = motion.predict(p, u, dt, veh)
    assert F.shape == (3, 3) and G.shape == (3, 2)
    assert -np.pi < nxt[2] <= np.pi
    F_fd = numerical_jacobian(lambda q: motion.predict(q, u, dt, veh)[0], p, angle_outputs=[2])
    G_fd = numerical_jacobian(lambda c: motion.predict(p, c, dt, veh)[0], u, angle_outputs=[2])
    assert_jac(F, F_fd, 200)
    assert_jac(G, G_fd, 200)


# ------------------------------------------------------------------- SymPy

@pytest.fixture(scope="module")
def symbolic():
    """F, G derived from first principles: the rear axle follows the bicycle model,
    the laser is the rigid point P_c + a T(phi) + b T(phi + pi/2); differentiate in
    time, then take one Euler step in laser coordinates."""
    x, y, phi, v, al, dt, L, a, b = sp.symbols("x y phi v alpha dt L a b", real=True)
    t = sp.Symbol("t")
    xc, yc, ph = (sp.Function(n)(t) for n in ("xc", "yc", "ph"))
    laser = sp.Matrix([xc + a * sp.cos(ph) - b * sp.sin(ph),
                       yc + a * sp.sin(ph) + b * sp.cos(ph), ph])
    axle_rate = {xc.diff(t): v * sp.cos(ph), yc.diff(t): v * sp.sin(ph),
                 ph.diff(t): v * sp.tan(al) / L}
    rate = laser.diff(t).subs(axle_rate).subs(ph, phi)
    assert not rate.has(xc) and not rate.has(yc)   # laser rate depends on heading only
    f = sp.Matrix([x, y, phi]) + dt * rate
    F = f.jacobian([x, y, phi])
    G = f.jacobian([v, al])
    args = (x, y, phi, v, al, dt, L, a, b)
    return [sp.lambdify(args, m, "numpy") for m in (f, F, G, rate)]


def test_predict_matches_sympy(symbolic):
    f_s, F_s, G_s, rate_s = symbolic
    rng = np.random.default_rng(11)
    for _ in range(100):
        p = np.r_[rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
        u = np.r_[rng.uniform(-4, 4), rng.uniform(-0.6, 0.6)]
        dt = rng.uniform(0, 0.3)
        veh = Vehicle(L=rng.uniform(1, 4), H=0.76, a=rng.uniform(-4, 4), b=rng.uniform(-1, 1))
        args = (*p, *u, dt, veh.L, veh.a, veh.b)
        nxt, F, G = motion.predict(p, u, dt, veh)
        ref = np.asarray(f_s(*args), float).ravel()
        np.testing.assert_allclose(nxt[:2], ref[:2], atol=1e-10)
        assert abs(wrap_angle(nxt[2] - ref[2])) < 1e-10
        np.testing.assert_allclose(F, np.asarray(F_s(*args), float), atol=1e-10)
        np.testing.assert_allclose(G, np.asarray(G_s(*args), float), atol=1e-10)
        np.testing.assert_allclose(motion.laser_velocity(p, u, veh),
                                   np.asarray(rate_s(*args), float).ravel(), atol=1e-10)


def test_axle_speed_from_rigid_body():
    """The encoder wheel at lateral offset H moves at v_c - omega H (rigid body), so
    axle_speed must invert that, for left turns, right turns and straight."""
    for alpha in (-0.5, 0.0, 0.3):
        v_c = 2.0
        omega = v_c * np.tan(alpha) / V.L
        v_e = v_c - omega * V.H
        assert motion.axle_speed(v_e, alpha, V)[0] == pytest.approx(v_c, rel=1e-12)


# ----------------------------------------------------- model properties

def test_zero_speed_and_zero_dt_are_identity():
    p = np.array([3.0, -4.0, 2.5])
    for u, dt in (([0.0, 0.4], 0.5), ([2.0, 0.4], 0.0)):
        nxt, F, G = motion.predict(p, u, dt, V)
        np.testing.assert_allclose(nxt, p, atol=1e-15)
        np.testing.assert_allclose(F, np.eye(3), atol=1e-15)
        np.testing.assert_allclose(motion.predict_exact(p, u, dt, V), p, atol=1e-12)


def test_straight_line_closed_form():
    p = np.array([1.0, 2.0, -2.0])
    v, dt = 3.0, 0.7
    expect = np.r_[p[:2] + v * dt * np.array([np.cos(p[2]), np.sin(p[2])]), p[2]]
    np.testing.assert_allclose(motion.predict(p, [v, 0.0], dt, V)[0], expect, atol=1e-12)
    np.testing.assert_allclose(motion.predict_exact(p, [v, 0.0], dt, V), expect, atol=1e-12)
    # tiny steering: the sinc form has no 0/0, and the arc tends to the line
    near = motion.predict_exact(p, [v, 1e-13], dt, V)
    np.testing.assert_allclose(near, expect, atol=1e-9)


def test_full_circle_returns_to_start():
    p = np.array([5.0, -3.0, 3.1])
    for v, alpha in ((2.0, 0.3), (1.5, -0.45), (-1.0, 0.2)):
        period = 2 * np.pi * V.L / abs(v * np.tan(alpha))
        end = motion.predict_exact(p, [v, alpha], period, V)
        np.testing.assert_allclose(end[:2], p[:2], atol=1e-9)
        assert abs(wrap_angle(end[2] - p[2])) < 1e-12
        half = motion.predict_exact(p, [v, alpha], period / 2, V)
        radius_axle = V.L / abs(np.tan(alpha))        # laser swings on a circle around the ICR
        assert np.linalg.norm(half[:2] - p[:2]) > radius_axle


def test_exact_matches_ode_integration():
    rng = np.random.default_rng(3)
    for _ in range(5):
        p = np.r_[rng.uniform(-10, 10, 2), rng.uniform(-np.pi, np.pi)]
        u = np.r_[rng.uniform(0.5, 3), rng.uniform(-0.6, 0.6)]
        sol = solve_ivp(lambda t, s: motion.laser_velocity(s, u, V), (0, 2.0), p,
                        rtol=1e-12, atol=1e-12)
        end = motion.predict_exact(p, u, 2.0, V)
        np.testing.assert_allclose(end[:2], sol.y[:2, -1], atol=1e-8)
        assert abs(wrap_angle(end[2] - sol.y[2, -1])) < 1e-8


def test_exact_is_a_flow():
    """Constant control: two half steps equal one step (semigroup property)."""
    p, u = np.array([0.0, 1.0, -3.0]), np.array([2.5, -0.4])
    one = motion.predict_exact(p, u, 1.2, V)
    two = motion.predict_exact(motion.predict_exact(p, u, 0.6, V), u, 0.6, V)
    np.testing.assert_allclose(one, two, atol=1e-12)


def test_euler_first_order_convergence():
    p, u, T = np.array([1.0, 2.0, 0.3]), np.array([2.0, 0.3]), 1.0
    exact = motion.predict_exact(p, u, T, V)
    errs = []
    for n in (100, 200, 400):
        q = p.copy()
        for _ in range(n):
            q = motion.predict(q, u, T / n, V)[0]
        errs.append(np.linalg.norm(q[:2] - exact[:2]))
    for e1, e2 in zip(errs, errs[1:]):
        assert 1.8 < e1 / e2 < 2.2
    assert errs[-1] < 1e-3


def test_batches_equal_loops():
    rng = np.random.default_rng(5)
    P = np.c_[rng.uniform(-9, 9, (6, 2)), rng.uniform(-np.pi, np.pi, 6)]
    U = np.c_[rng.uniform(-3, 3, 6), rng.uniform(-0.6, 0.6, 6)]
    dt = rng.uniform(0, 0.2, 6)
    nxt, F, G = motion.predict(P, U, dt, V)
    ex = motion.predict_exact(P, U, dt, V)
    lp, J = motion.laser_pose(P, V)
    assert nxt.shape == (6, 3) and F.shape == (6, 3, 3) and G.shape == (6, 3, 2)
    for i in range(6):
        n1, F1, G1 = motion.predict(P[i], U[i], dt[i], V)
        np.testing.assert_allclose(nxt[i], n1)
        np.testing.assert_allclose(F[i], F1)
        np.testing.assert_allclose(G[i], G1)
        np.testing.assert_allclose(ex[i], motion.predict_exact(P[i], U[i], dt[i], V))
        np.testing.assert_allclose(J[i], motion.laser_pose(P[i], V)[1])
    vc, Jv = motion.axle_speed(U[:, 0], U[:, 1], V)
    assert vc.shape == (6,) and Jv.shape == (6, 2)
    np.testing.assert_allclose(vc[2], motion.axle_speed(U[2, 0], U[2, 1], V)[0])


# --------------------------------------------------------------- bad input

@pytest.mark.parametrize("call, match", [
    (lambda: motion.predict([0, 0], [1, 0], 0.1, V), "pose must have shape"),
    (lambda: motion.predict([0, 0, 0], [1, 0, 0], 0.1, V), "control must have shape"),
    (lambda: motion.predict([0, np.nan, 0], [1, 0], 0.1, V), "pose contains NaN"),
    (lambda: motion.predict([0, 0, 0], [1, np.inf], 0.1, V), "control contains NaN"),
    (lambda: motion.predict([0, 0, 0], [1, 0], -0.1, V), "dt must be >= 0"),
    (lambda: motion.predict([0, 0, 0], [1, 0], np.nan, V), "dt contains NaN"),
    (lambda: motion.predict([0, 0, 0], [1, 1.6], 0.1, V), "steering"),
    (lambda: motion.predict_exact([0, 0, 0], [1, -np.pi / 2], 0.1, V), "steering"),
    (lambda: motion.predict([0, 0, 0], [1, 0], 0.1, None), "vehicle must be"),
    (lambda: motion.laser_pose([[0, 0]], V), "axle_pose must have shape"),
    (lambda: motion.axle_pose("abc", V), "laser_pose must be numeric"),
    (lambda: motion.axle_speed(1.0, np.arctan(V.L / V.H), V), "singular steering"),
    (lambda: motion.axle_speed(np.nan, 0.1, V), "encoder_speed contains NaN"),
    (lambda: motion.axle_speed(1.0, 2.0, V), "steering must satisfy"),
    (lambda: motion.predict(np.zeros((3, 3)), np.zeros((2, 2)), 0.1, V), "broadcast"),
])
def test_bad_input_raises(call, match):
    kind = TypeError if match in ("vehicle must be", "laser_pose must be numeric") else ValueError
    with pytest.raises(kind, match=match):
        call()
