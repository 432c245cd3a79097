"""Trajectory errors against GPS (annslam_lib.metrics) on cases with known answers."""
import numpy as np
import pytest


from annslam_lib.data.records import Gps
from annslam_lib.evaluation import trajectory
from annslam_lib.models import geometry


def line(n=201, t0=0.0, t1=20.0, v=1.5, phi=0.4):
    """A straight drive at speed v along heading phi, rows (t, x, y, phi)."""
    t = np.linspace(t0, t1, n)
    s = v * (t - t0)
    return np.column_stack([t, 3 + s * np.cos(phi), -2 + s * np.sin(phi), np.full(n, phi)])


def gps_at(t, xy):
    return Gps(t=t, east=xy[:, 0], north=xy[:, 1])


def test_constant_offset_gives_that_error():
    traj = line()
    d, beta = 0.37, 2.1
    t = np.linspace(0.05, 19.95, 100)                  # between the rows: interpolation is used
    truth = geometry.interpolate_poses(traj, t)[:, :2]
    e = trajectory.trajectory_errors(traj, gps_at(t, truth + d * np.array([np.cos(beta), np.sin(beta)])))
    for value in (e.rmse, e.mean, e.max, e.final):
        assert value == pytest.approx(d, abs=1e-12)
    np.testing.assert_allclose(e.offset, np.broadcast_to(-d * np.array([np.cos(beta), np.sin(beta)]),
                                                         (100, 2)), atol=1e-12)
    assert e.n_outside == 0 and e.t.size == 100


def test_growing_error_known_rmse_max_final():
    """Error equal to the time since the start: RMSE = sqrt(mean t^2), max = final = t_end."""
    traj = line()
    t = np.arange(0.5, 20.0, 0.5)
    truth = geometry.interpolate_poses(traj, t)[:, :2]
    side = np.column_stack([-np.sin(0.4) * t, np.cos(0.4) * t])    # t metres to the left
    e = trajectory.trajectory_errors(traj, gps_at(t, truth + side))
    assert e.rmse == pytest.approx(np.sqrt(np.sum(t**2) / t.size), rel=1e-12)
    assert e.max == pytest.approx(t[-1], rel=1e-12) and e.final == pytest.approx(t[-1], rel=1e-12)
    assert e.t_max == t[-1]
    assert e.mean == pytest.approx(t.mean(), rel=1e-12)


def test_interpolation_positions_and_knots():
    traj = line(n=11)
    np.testing.assert_allclose(geometry.interpolate_poses(traj, traj[:, 0]), traj[:, 1:], atol=1e-12)
    mid = geometry.interpolate_poses(traj, 1.0)           # halfway between rows at 0 and 2 s
    assert mid.shape == (3,)
    np.testing.assert_allclose(mid[:2], 0.5 * (traj[0, 1:3] + traj[1, 1:3]), atol=1e-12)


def test_heading_interpolates_the_short_way_across_pi():
    traj = np.array([[0.0, 0, 0, 3.1], [1.0, 1, 0, -3.1]])     # turning left through +-pi
    phi = geometry.interpolate_poses(traj, [0.5, 0.25])[:, 2]
    assert abs(np.angle(np.exp(1j * (phi[0] - np.pi)))) < 1e-12
    step = 2 * np.pi - 6.2                                      # 0.0832 rad the short way
    assert phi[1] == pytest.approx(3.1 + step / 4, abs=1e-12)
    assert np.all(phi > -np.pi) and np.all(phi <= np.pi)


def test_only_fixes_inside_the_span_are_used():
    traj = line(t0=5.0, t1=15.0)
    t = np.arange(0.0, 20.0, 0.2)
    xy = np.zeros((t.size, 2))
    inside = (t >= 5.0) & (t <= 15.0)
    xy[inside] = geometry.interpolate_poses(traj, t[inside])[:, :2] + [0.1, 0.0]
    xy[~inside] = 1e6                                  # absurd fixes: must be ignored
    e = trajectory.trajectory_errors(traj, gps_at(t, xy))
    assert e.n_outside == int((~inside).sum()) and e.t.size == int(inside.sum())
    assert e.max == pytest.approx(0.1, abs=1e-12)


@pytest.mark.parametrize("bad", [np.zeros((5, 3)), np.zeros(4), np.zeros((2, 5, 4)),
                                 np.zeros((0, 4)), "abc"])
def test_bad_trajectory_shapes(bad):
    kind = TypeError if isinstance(bad, str) else ValueError
    with pytest.raises(kind):
        geometry.interpolate_poses(bad, 0.0)
    with pytest.raises(kind):
        trajectory.trajectory_errors(bad, gps_at(np.array([0.0]), np.zeros((1, 2))))


def test_bad_values_and_times():
    traj = line()
    nan = traj.copy()
    nan[3, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        trajectory.trajectory_errors(nan, gps_at(np.array([1.0]), np.zeros((1, 2))))
    backwards = traj[::-1]
    with pytest.raises(ValueError, match="non-decreasing"):
        geometry.interpolate_poses(backwards, 1.0)
    with pytest.raises(ValueError, match="outside"):
        geometry.interpolate_poses(traj, [1.0, 20.5])
    with pytest.raises(ValueError, match="NaN"):
        geometry.interpolate_poses(traj, [1.0, np.nan])
    with pytest.raises(ValueError, match="one-dimensional"):
        geometry.interpolate_poses(traj, np.ones((2, 2)))
    with pytest.raises(ValueError, match="no GPS fix inside"):
        trajectory.trajectory_errors(traj, gps_at(np.array([25.0, 26.0]), np.zeros((2, 2))))
    with pytest.raises(TypeError, match="Gps"):
        trajectory.trajectory_errors(traj, np.zeros((3, 3)))
