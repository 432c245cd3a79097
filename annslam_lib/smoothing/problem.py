"""The SLAM problem of a run as a factor graph's ingredients (chapter 10), in plain numpy:
no solver here, so the pieces can be checked without GTSAM.

Built from an EKF run (:func:`build_problem`) with the course's own models:

- one pose per EVENT the filter processed (every scan, every GPS fix it used) plus a start
  pose at the first odometry sample;
- between two consecutive poses, the odometry factor: the course's motion model
  (``SlamConfig.motion_model``, the run loop's steps, ``slam.stretches``) run from
  the first pose with zero covariance to the second pose's time gives the relative pose
  Delta = X_k^-1 X_{k+1} and its covariance; the covariance is moved from the world frame
  (the filter's additive (dx, dy, dphi)) to GTSAM's tangent space at the second pose
  (X exp(xi), xi = (body-frame position, angle)): xi = blockdiag(R(phi_{k+1})^T, 1) delta;
  it is floored (``odometry_floor``) because with the car standing, or over one or two
  steps, it is singular (two noise inputs, three pose dimensions);
- per associated detection (the EKF's own associations: ``ObservationLog.landmark``), a
  range-bearing factor (``SlamConfig.sigma_range``, ``sigma_bearing``);
- per GPS fix the EKF used, a position factor (``sigma_gps``); a prior on the start pose
  (the EKF's initial pose and covariance).

Every pose is linked to the next by construction (K poses, K - 1 odometry factors), so the
graph is connected; a landmark seen fewer than ``min_sightings`` times is left out (counted
in ``counts['landmarks_dropped']``): its position would only echo its one measurement.
:func:`check_problem` refuses a problem that cannot have one solution (no prior and fewer
than two distinct GPS positions, a landmark no factor reaches), naming the cause.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..data.records import Dataset
from ..models.geometry import wrap_angle
from ..models.motion import control_table
from ..slam.config import SlamConfig
from ..slam import stretches
from ..slam.efficient import EkfSlam
from ..slam.results import STATUS, SlamResult

__all__ = ["GraphProblem", "build_problem", "check_problem", "relative_pose", "compose",
           "world_to_tangent"]

#: Node kinds (``GraphProblem.kind``).
KIND = {"start": 0, "scan": 1, "gps": 2}


@dataclass
class GraphProblem:
    """A pose-landmark factor graph's data (module docstring).

    t (K,), kind (K,) (:data:`KIND`), scan (K,) (the scan index, -1 for other nodes);
    odometry (K-1, 3): Delta between node k and k+1; odometry_cov (K-1, 3, 3): its
    covariance in the tangent space at node k+1; obs_node, obs_landmark (N,), obs_z (N, 2)
    (range, bearing in the laser convention: 0 to the right, pi/2 ahead); sigma_range,
    sigma_bearing; gps_node (G,), gps_xy (G, 2), sigma_gps; prior_pose (3,), prior_cov
    (3, 3) (tangent space at prior_pose) or None; initial_poses (K, 3), initial_landmarks
    (L, 2): the EKF's estimate (its pose after each scan's update; at a GPS node the node
    before moved on by the odometry; its final map); dead_reckoning
    (K, 3): the odometry chain from the prior; dense_t, dense_node, dense_rel: every
    odometry sample's pose relative to the node before it (a smoothed dense track:
    :meth:`dense_track`); landmark_ekf (L,): the EKF's index of each landmark;
    counts: what was built, floored and dropped.
    """

    t: np.ndarray
    kind: np.ndarray
    scan: np.ndarray
    odometry: np.ndarray
    odometry_cov: np.ndarray
    obs_node: np.ndarray
    obs_landmark: np.ndarray
    obs_z: np.ndarray
    sigma_range: float
    sigma_bearing: float
    gps_node: np.ndarray
    gps_xy: np.ndarray
    sigma_gps: float
    prior_pose: np.ndarray | None
    prior_cov: np.ndarray | None
    initial_poses: np.ndarray
    initial_landmarks: np.ndarray
    dead_reckoning: np.ndarray
    dense_t: np.ndarray
    dense_node: np.ndarray
    dense_rel: np.ndarray
    landmark_ekf: np.ndarray
    counts: dict = field(default_factory=dict)

    @property
    def n_poses(self) -> int:
        return self.t.size

    @property
    def n_landmarks(self) -> int:
        return self.initial_landmarks.shape[0]

    def dense_track(self, poses) -> np.ndarray:
        """(J, 4) rows (t, x, y, phi) at every odometry sample, each the node pose before it
        composed with the odometry's relative pose from that node (the course's motion model
        between the smoothed nodes), then the nodes themselves, in time order."""
        poses = _checks.array("poses", poses, (self.n_poses, 3))
        dense = compose(poses[self.dense_node], self.dense_rel)
        t = np.concatenate([self.dense_t, self.t])
        xyz = np.concatenate([dense, poses])
        order = np.argsort(t, kind="stable")
        return np.column_stack([t[order], xyz[order]])


def compose(a, b) -> np.ndarray:
    """SE(2) composition a * b of poses (..., 3), heading wrapped to (-pi, pi]."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1],
                     a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     wrap_angle(a[..., 2] + b[..., 2])], -1)


def relative_pose(a, b) -> np.ndarray:
    """a^-1 * b: pose b in the frame of pose a (..., 3)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], -1)


def world_to_tangent(P, phi) -> np.ndarray:
    """A pose covariance in the filter's world-frame coordinates (dx, dy, dphi) moved to
    GTSAM's Pose2 tangent space at a pose of heading ``phi`` (X exp(xi): xi's position part
    in the body frame): A P A^T with A = blockdiag(R(phi)^T, 1), to first order."""
    c, s = math.cos(phi), math.sin(phi)
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return A @ np.asarray(P, float) @ A.T


def _gps_used(result: SlamResult, gps) -> np.ndarray:
    """Indices into ``gps`` of the fixes the run used (accepted GPS updates)."""
    nis = result.nis
    t_used = nis["t"][(nis["kind"] == 1) & nis["accepted"]] if nis["t"].size else np.empty(0)
    idx = np.searchsorted(gps.t, t_used)
    ok = (idx < len(gps)) & (gps.t[np.minimum(idx, len(gps) - 1)] == t_used)
    if not ok.all():
        raise ValueError("the run's GPS updates do not match the dataset's fixes: pass the "
                         "dataset the result was computed from")
    return idx


def build_problem(dataset: Dataset, result: SlamResult, *, min_sightings: int = 2,
                  odometry_floor: tuple[float, float] = (1e-3, 1e-4)) -> GraphProblem:
    """The factor graph of an EKF run (module docstring): its events, its associations, its
    noise (``result.config``), its start. Chapter 10, "the graph from the course's pieces".

    dataset: the ``records.Dataset`` the run was computed from; result: its ``SlamResult``
    (``slam.run``); min_sightings: landmarks seen fewer times are left out (counted);
    odometry_floor (m, rad): standard deviations added (as variances) to every odometry
    factor's covariance in the tangent space (counted where the covariance was singular
    to 1e-12 of its largest eigenvalue before flooring) and to the prior's (a simulated
    run starts exactly: zero covariance).

    Raises ValueError for a run with the ANN landmark model or a known map (the graph uses
    the detections and builds the map), or a result that does not belong to the dataset.
    """
    _checks.instance("dataset", dataset, Dataset, "records.Dataset")
    _checks.instance("result", result, SlamResult, "slam.SlamResult")
    min_sightings = _checks.integer("min_sightings", min_sightings, lo=1)
    floor = np.asarray(odometry_floor, dtype=float)
    if floor.shape != (2,) or not np.all(np.isfinite(floor)) or np.any(floor < 0):
        raise ValueError(f"odometry_floor must be two finite standard deviations >= 0, got "
                         f"{odometry_floor!r}")
    cfg: SlamConfig = result.config
    if cfg.landmark_model != "inverse" or cfg.map_mode == "known":
        raise ValueError("build_problem needs a SLAM run on the detections (landmark_model "
                         "'inverse', map_mode 'slam'), got landmark_model "
                         f"{cfg.landmark_model!r}, map_mode {cfg.map_mode!r}")
    from ..slam.runner import prepare        # the run loop's own inputs and order
    prep = prepare(dataset, cfg)
    ds = prep.dataset
    odo, gps, log = ds.odometry, ds.gps, result.observations
    gps_used = _gps_used(result, gps)
    scans = result.scan_index
    if scans.size == 0:
        raise ValueError("the run processed no scan")
    det = prep.detections                    # laser calibration applied, as in the run's log
    scan_of = np.repeat(np.arange(len(det)), np.diff(det.offsets))
    rows = np.flatnonzero(np.isin(scan_of, scans))
    if scans.max() >= len(det) or rows.size != len(log) or not (
            np.array_equal(det.range[rows], log.range)
            and np.array_equal(det.bearing[rows], log.bearing)
            and np.array_equal(det.t[scans], result.trajectory[:, 0])):
        raise ValueError("the run's detections are not the dataset's: pass the dataset the "
                         "result was computed from")
    det_t = det.t
    node_of_scan = np.full(det_t.size, -1, dtype=np.int64)
    node_of_gps = np.full(len(gps), -1, dtype=np.int64)
    is_node_scan = np.zeros(det_t.size, dtype=bool)
    is_node_scan[scans] = True
    is_node_gps = np.zeros(len(gps), dtype=bool)
    is_node_gps[gps_used] = True

    controls = control_table(odo, ds.vehicle, cfg.sigma_speed, cfg.sigma_steer,
                             cfg.steer_noise_gain, array=True)
    t0, pose0 = float(odo.t[0]), np.asarray(result.initial_pose, float)
    zero = np.zeros((3, 3))
    ev_t, ev_code, ev_idx, ev_k = prep.events
    # the run loop's predictions between events (slam.stretches), chained from node to node
    legs = stretches.compound(odo.t, controls, ev_t, ev_k, ds.vehicle,
                              cfg.motion_model == "midpoint")
    starts = np.full((len(ev_t) + 1, 3), np.nan)       # the chain's pose at each stretch start
    start_node = np.zeros(len(ev_t) + 1, dtype=np.int64)
    nodes_t, nodes_kind, nodes_scan, dr = [t0], [KIND["start"]], [-1], [pose0]
    deltas, covs = [], []
    filt = EkfSlam(pose0, zero, ds.vehicle, cfg.motion_model)
    floored = 0
    ekf_pose = {}
    for tr, s in zip(result.trajectory, scans.tolist()):
        ekf_pose[("scan", s)] = tr[1:]

    def advance(s: int) -> None:
        starts[s] = filt.pose_tuple()
        start_node[s] = len(nodes_t) - 1
        filt.predict_stretch(legs.rows[s])

    for e, (t, code, idx) in enumerate(zip(ev_t, ev_code, ev_idx)):
        if not legs.processed[e]:
            continue
        advance(e)
        if not (is_node_scan[idx] if code == 2 else is_node_gps[idx]):
            continue
        pose, P = filt.pose, filt.pose_cov
        delta = relative_pose(dr[-1], pose)
        C = world_to_tangent(P, pose[2])
        C = 0.5 * (C + C.T)
        ev = np.linalg.eigvalsh(C)
        floored += int(ev[0] <= 1e-12 * max(ev[-1], 1e-300))
        C += np.diag([floor[0] ** 2, floor[0] ** 2, floor[1] ** 2])
        deltas.append(delta)
        covs.append(C)
        nodes_t.append(t)
        nodes_kind.append(KIND["scan"] if code == 2 else KIND["gps"])
        nodes_scan.append(idx if code == 2 else -1)
        dr.append(pose)
        if code == 2:
            node_of_scan[idx] = len(nodes_t) - 1
        else:
            node_of_gps[idx] = len(nodes_t) - 1
        filt = EkfSlam(pose, zero, ds.vehicle, cfg.motion_model)
    advance(len(ev_t))
    samples = legs.sample_poses(starts)              # every odometry sample, on the chain
    dense_node = start_node[legs.sample_stretch]
    dense_rel = relative_pose(np.array(dr)[dense_node], samples[:, 1:])
    if not np.all(node_of_scan[scans] >= 0):
        raise ValueError("the run's scans do not match the dataset's detections: pass the "
                         "dataset the result was computed from")

    # the EKF's estimate at each node: after each scan's update; at a GPS node, the last
    # scan's pose moved on by the odometry (a start for the solvers, nothing more)
    K = len(nodes_t)
    init = np.empty((K, 3))
    init[0] = pose0
    for k in range(1, K):
        s = nodes_scan[k]
        init[k] = ekf_pose[("scan", s)] if s >= 0 else compose(init[k - 1], deltas[k - 1])

    used = (log.landmark >= 0) & ((log.status == STATUS["associated"]) | (log.status == STATUS["new"]))
    lm_all = log.landmark[used]
    seen = np.bincount(lm_all, minlength=result.landmarks.shape[0])
    keep = np.flatnonzero(seen >= min_sightings)
    new_index = np.full(seen.size, -1, dtype=np.int64)
    new_index[keep] = np.arange(keep.size)
    rows = np.flatnonzero(used)
    rows = rows[new_index[log.landmark[rows]] >= 0]
    obs_node = node_of_scan[log.scan[rows]]
    counts = dict(poses=K, odometry=K - 1, odometry_singular=floored,
                  observations=int(rows.size), gps=int(gps_used.size),
                  landmarks=int(keep.size), landmarks_dropped=int(seen.size - keep.size),
                  observations_dropped=int(used.sum() - rows.size))
    order = np.argsort(gps_used)
    P0 = prep.cov0
    return GraphProblem(
        t=np.array(nodes_t), kind=np.array(nodes_kind, dtype=np.int8),
        scan=np.array(nodes_scan, dtype=np.int64),
        odometry=np.array(deltas).reshape(K - 1, 3), odometry_cov=np.array(covs).reshape(K - 1, 3, 3),
        obs_node=obs_node, obs_landmark=new_index[log.landmark[rows]],
        obs_z=np.column_stack([log.range[rows], log.bearing[rows]]),
        sigma_range=float(cfg.sigma_range), sigma_bearing=float(cfg.sigma_bearing),
        gps_node=node_of_gps[gps_used[order]], gps_xy=gps.xy[gps_used[order]],
        sigma_gps=float(cfg.sigma_gps), prior_pose=pose0.copy(),
        prior_cov=world_to_tangent(P0, pose0[2]) + np.diag([floor[0] ** 2, floor[0] ** 2, floor[1] ** 2]),
        initial_poses=init,
        initial_landmarks=result.landmarks[keep].copy(), dead_reckoning=np.array(dr),
        dense_t=samples[:, 0], dense_node=dense_node, dense_rel=dense_rel,
        landmark_ekf=keep, counts=counts)


def check_problem(problem: GraphProblem) -> None:
    """Refuse a graph without one solution, naming the cause (ValueError): non-finite or
    mis-shaped data, non-positive-definite noise, no prior and fewer than two distinct GPS
    positions (the whole solution could slide and turn: the gauge is free), a landmark no
    factor reaches. (A landmark with one range-bearing factor is not an error: one sighting
    fixes a point; ``build_problem``'s ``min_sightings`` leaves such landmarks out.) GTSAM's
    LM would return an answer for such graphs all the same (its damping holds the free
    directions), so this check runs before every solve.
    """
    _checks.instance("problem", problem, GraphProblem, "smoothing.GraphProblem")
    K, L = problem.n_poses, problem.n_landmarks
    if K < 1:
        raise ValueError("the graph has no pose")
    shapes = dict(odometry=(K - 1, 3), odometry_cov=(K - 1, 3, 3), initial_poses=(K, 3),
                  initial_landmarks=(L, 2), obs_z=(problem.obs_node.size, 2),
                  gps_xy=(problem.gps_node.size, 2))
    for name, shape in shapes.items():
        a = getattr(problem, name)
        if a.shape != shape:
            raise ValueError(f"problem.{name} has shape {a.shape}, expected {shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"problem.{name} holds non-finite values")
    if problem.obs_landmark.shape != problem.obs_node.shape:
        raise ValueError("problem.obs_landmark and obs_node differ in length")
    for name in ("obs_node", "gps_node"):
        a = getattr(problem, name)
        if a.size and (a.min() < 0 or a.max() >= K):
            raise ValueError(f"problem.{name} refers to a pose outside 0..{K - 1}")
    if problem.obs_landmark.size and (problem.obs_landmark.min() < 0
                                      or problem.obs_landmark.max() >= L):
        raise ValueError(f"problem.obs_landmark refers to a landmark outside 0..{L - 1}")
    if np.any(problem.obs_z[:, 0] <= 0):
        raise ValueError("a range-bearing measurement has range <= 0")
    for name in ("sigma_range", "sigma_bearing", "sigma_gps"):
        v = getattr(problem, name)
        if not (0 < v < math.inf):
            raise ValueError(f"problem.{name} must be positive and finite, got {v}")
    covs = list(problem.odometry_cov)
    if problem.prior_cov is not None:
        covs.append(problem.prior_cov)
    for i, C in enumerate(covs):
        if not np.allclose(C, C.T, rtol=0, atol=1e-12 * max(1.0, np.abs(C).max())) or \
                np.linalg.eigvalsh(0.5 * (C + C.T))[0] <= 0:
            what = (f"odometry factor {i} (poses {i} -> {i + 1})" if i < K - 1 else "the prior")
            raise ValueError(f"{what}: covariance not symmetric positive definite (a standing "
                             "car or an exact start: floor it, build_problem's odometry_floor)")
    if problem.prior_pose is None:
        xy = problem.gps_xy
        spread = float(np.max(np.ptp(xy, axis=0))) if xy.shape[0] else 0.0
        if np.unique(problem.gps_node).size < 2 or not spread > 0.0:
            raise ValueError("missing prior: no prior on a pose and fewer than two poses with "
                             "GPS fixes at distinct positions, so the whole solution may slide "
                             "and turn freely "
                             "(the gauge is free); give prior_pose and prior_cov")
    elif problem.prior_pose.shape != (3,) or problem.prior_cov is None or \
            problem.prior_cov.shape != (3, 3) or not np.all(np.isfinite(problem.prior_pose)):
        raise ValueError("the prior needs a finite prior_pose (3,) and prior_cov (3, 3)")
    seen = np.bincount(problem.obs_landmark, minlength=L)
    if np.any(seen == 0):
        j = int(np.flatnonzero(seen == 0)[0])
        raise ValueError(f"landmark {j} has no bearing-range factor ({int(np.sum(seen == 0))} "
                         "such): nothing fixes its position (under-determined)")
