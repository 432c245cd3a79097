"""A :class:`~annslam_lib.smoothing.problem.GraphProblem` solved with GTSAM (chapter 10):
incrementally (iSAM2, one update per pose, as the car drives) and in batch
(Levenberg-Marquardt over the whole graph, started from a given solution).

The factors (``factors``): ``gtsam.BetweenFactorPose2`` for odometry (noise in the tangent
space at the second pose, ``problem.world_to_tangent``), ``gtsam.BearingRangeFactor2D`` per
associated detection (GTSAM measures bearing from the pose's x axis, the laser from its
right: bearing - pi/2; its noise is ordered (bearing, range)), a GPS fix as a
``gtsam.CustomFactor`` whose error and Jacobian are :func:`gps_error`, and
``gtsam.PriorFactorPose2`` at the start.

What GTSAM taught us on these runs (measured): iSAM2 with Cholesky factorisation can stop
with an indeterminate system on Victoria Park, QR does not (the default here); batch LM
from dead reckoning can settle 65 m off on Victoria Park, so start it from the incremental
(or the EKF's) solution; iSAM2's partial relinearisation stops short of the optimum, which
a batch pass reaches. GTSAM's LM does NOT refuse an under-determined graph: its damping
holds the free directions wherever the start put them and it returns an answer. The guard
is :func:`~annslam_lib.smoothing.problem.check_problem`, run before every solve; what GTSAM
itself finds indeterminate (iSAM2, marginals) is raised as :class:`SolverError` with GTSAM's
message (it names the variable, ``x12`` for pose 12, ``l3`` for landmark 3), and LM that
stops at its iteration limit while the error still falls raises too.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..models.observation import inverse_observe
from .factors import tangent_to_world
from .problem import GraphProblem, check_problem, compose

__all__ = ["SolverError", "SmoothingResult", "gps_error", "build_graph", "solve_batch", "marginals",
           "solve_isam2", "pose_key", "landmark_key"]


class SolverError(RuntimeError):
    """A graph GTSAM could not solve (indeterminate, not converged); the message says why."""


def _gtsam():
    try:
        import gtsam
    except ImportError as e:              # pinned in environment.txt
        raise ImportError("the factor-graph chapter needs gtsam (pip install gtsam==4.3.0, "
                          "pinned in environment.txt)") from e
    return gtsam


def pose_key(k: int) -> int:
    """GTSAM key of pose k (symbol x_k)."""
    return _gtsam().symbol("x", int(k))


def landmark_key(j: int) -> int:
    """GTSAM key of landmark j (symbol l_j)."""
    return _gtsam().symbol("l", int(j))


def gps_error(pose, xy) -> tuple[np.ndarray, np.ndarray]:
    """Error of a GPS fix of the laser point and its Jacobian (chapter 10, the custom
    factor): e = t(X) - xy, with X = (x, y, phi) and, in GTSAM's tangent space at X
    (X exp(xi), xi's position part in the body frame), de/dxi = [R(phi), 0]."""
    pose = _checks.array("pose", pose, (3,))
    xy = _checks.array("xy", xy, (2,))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose[:2] - xy, np.array([[c, -s, 0.0], [s, c, 0.0]])


def _gps_factor(gtsam, key: int, xy, noise):
    xy = np.array(xy, dtype=float)

    def error(this, values, H):
        p = values.atPose2(this.keys()[0])
        c, s = math.cos(p.theta()), math.sin(p.theta())
        if H is not None:
            H[0] = np.array([[c, -s, 0.0], [s, c, 0.0]])
        return np.array([p.x() - xy[0], p.y() - xy[1]])

    return gtsam.CustomFactor(noise, [key], error)


class _Factors:
    """The problem's GTSAM factors, made on demand per pose (iSAM2) or all at once."""

    def __init__(self, gtsam, problem: GraphProblem, huber_k: float | None = None) -> None:
        self.g, self.p = gtsam, problem
        nm = gtsam.noiseModel
        self.br_noise = nm.Diagonal.Sigmas(np.array([problem.sigma_bearing, problem.sigma_range]))
        if huber_k is not None:          # the detections under Huber's loss (robust kernel)
            self.br_noise = nm.Robust.Create(nm.mEstimator.Huber.Create(float(huber_k)),
                                             self.br_noise)
        self.gps_noise = nm.Isotropic.Sigma(2, problem.sigma_gps)
        order = np.argsort(problem.obs_node, kind="stable")
        self.obs = order
        self.obs_off = np.searchsorted(problem.obs_node[order], np.arange(problem.n_poses + 1))
        g_order = np.argsort(problem.gps_node, kind="stable")
        self.gps = g_order
        self.gps_off = np.searchsorted(problem.gps_node[g_order], np.arange(problem.n_poses + 1))

    def prior(self):
        g, p = self.g, self.p
        if p.prior_pose is None:
            return None
        return g.PriorFactorPose2(pose_key(0), g.Pose2(*p.prior_pose),
                                  g.noiseModel.Gaussian.Covariance(p.prior_cov))

    def at(self, k: int) -> list:
        """The factors that end at pose k: odometry from k - 1, its detections, its GPS."""
        g, p = self.g, self.p
        out = []
        if k > 0:
            out.append(g.BetweenFactorPose2(pose_key(k - 1), pose_key(k),
                                            g.Pose2(*p.odometry[k - 1]),
                                            g.noiseModel.Gaussian.Covariance(p.odometry_cov[k - 1])))
        for i in self.obs[self.obs_off[k]:self.obs_off[k + 1]].tolist():
            r, b = p.obs_z[i]
            out.append(g.BearingRangeFactor2D(pose_key(k), landmark_key(p.obs_landmark[i]),
                                              g.Rot2(b - 0.5 * math.pi), r, self.br_noise))
        for i in self.gps[self.gps_off[k]:self.gps_off[k + 1]].tolist():
            out.append(_gps_factor(g, pose_key(k), p.gps_xy[i], self.gps_noise))
        return out

    def observations_at(self, k: int) -> np.ndarray:
        return self.obs[self.obs_off[k]:self.obs_off[k + 1]]


def build_graph(problem: GraphProblem, poses=None, landmarks=None, *,
                huber_k: float | None = None):
    """(gtsam.NonlinearFactorGraph, gtsam.Values) of the whole problem; values from
    ``poses`` (K, 3) and ``landmarks`` (L, 2), by default the problem's initial ones (the
    EKF's); ``huber_k``: the detections' noise wrapped in Huber's robust loss with that
    threshold. Checks the problem first (:func:`~annslam_lib.smoothing.problem.check_problem`)."""
    check_problem(problem)
    g = _gtsam()
    poses = problem.initial_poses if poses is None else _checks.array("poses", poses, (problem.n_poses, 3))
    landmarks = (problem.initial_landmarks if landmarks is None
                 else _checks.array("landmarks", landmarks, (problem.n_landmarks, 2)))
    fac = _Factors(g, problem, huber_k)
    graph = g.NonlinearFactorGraph()
    prior = fac.prior()
    if prior is not None:
        graph.add(prior)
    values = g.Values()
    for k in range(problem.n_poses):
        for f in fac.at(k):
            graph.add(f)
        values.insert(pose_key(k), g.Pose2(*poses[k]))
    for j in range(problem.n_landmarks):
        values.insert(landmark_key(j), g.Point2(*landmarks[j]))
    return graph, values


@dataclass
class SmoothingResult:
    """A solved graph. estimator: 'isam2' or 'batch'; poses (K, 3), landmarks (L, 2);
    t (K,): the poses' times; cpu_s: process CPU seconds of the solve (building the
    factors included); error_initial, error_final: the graph's error (sum of squared
    whitened residuals / 2) at the values LM started from (batch) or at the problem's
    initial values, the EKF's estimate (iSAM2, whose own start is built pose by pose), and
    at the solution; iterations (batch) or updates
    (iSAM2); step_cpu: iSAM2's CPU seconds per update, ``isam.update`` alone (empty for
    batch), step_landmarks: the landmarks in the graph at each update; node_cpu (K,) (iSAM2):
    the whole CPU seconds of each pose's turn of the loop (its factors and start values, the
    update when it ends a block, reading the estimate; pose 0's turn also holds the set-up
    before the loop), empty for batch; filtered (K, 3) (iSAM2): each pose as iSAM2 estimated
    it right after the first update that held it (with ``every = 1``, the filtered estimate:
    only the data up to that pose), empty for batch. ``poses`` is the final, smoothed one."""

    estimator: str
    t: np.ndarray
    poses: np.ndarray
    landmarks: np.ndarray
    cpu_s: float
    error_initial: float
    error_final: float
    iterations: int
    step_cpu: np.ndarray = field(default_factory=lambda: np.empty(0))
    step_landmarks: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    node_cpu: np.ndarray = field(default_factory=lambda: np.empty(0))
    filtered: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))

    @property
    def trajectory(self) -> np.ndarray:
        """(K, 4) rows (t, x, y, phi) of the poses."""
        return np.column_stack([self.t, self.poses])


def _read(g, values, K: int, L: int) -> tuple[np.ndarray, np.ndarray]:
    poses = np.empty((K, 3))
    for k in range(K):
        p = values.atPose2(pose_key(k))
        poses[k] = p.x(), p.y(), p.theta()
    lms = np.empty((L, 2))
    for j in range(L):
        lms[j] = values.atPoint2(landmark_key(j))
    return poses, lms


def _indeterminate(e: Exception, what: str) -> SolverError:
    return SolverError(f"{what} failed: {e} (an under-determined graph: a pose or landmark "
                       "that the factors do not pin down, e.g. a missing prior or a landmark "
                       "seen once by a bearing only)")


def solve_batch(problem: GraphProblem, poses=None, landmarks=None, *,
                max_iterations: int = 100, relative_tol: float = 1e-6,
                huber_k: float | None = None) -> SmoothingResult:
    """Levenberg-Marquardt over the whole graph from ``poses`` / ``landmarks`` (default:
    the problem's initial, the EKF's estimate; pass an iSAM2 solution to polish it);
    ``huber_k``: the detections under Huber's loss (:func:`build_graph`).
    Raises :class:`SolverError` if GTSAM finds the system indeterminate, or if LM stops at
    ``max_iterations`` with the error still falling by more than ``relative_tol``."""
    g = _gtsam()
    max_iterations = _checks.integer("max_iterations", max_iterations, lo=1)
    c0 = time.process_time()
    graph, values = build_graph(problem, poses, landmarks, huber_k=huber_k)
    params = g.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(relative_tol)
    params.setAbsoluteErrorTol(0.0)
    err0 = graph.error(values)
    opt = g.LevenbergMarquardtOptimizer(graph, values, params)
    try:
        sol = opt.optimize()
    except RuntimeError as e:
        raise _indeterminate(e, "batch Levenberg-Marquardt") from e
    err = graph.error(sol)
    its = opt.iterations()
    if not math.isfinite(err):
        raise SolverError(f"batch Levenberg-Marquardt ended with a non-finite error ({err})")
    if its >= max_iterations:
        # one more iteration tells whether it had converged at the limit
        opt2 = g.LevenbergMarquardtOptimizer(graph, sol, params)
        opt2.iterate()
        nxt = graph.error(opt2.values())
        if err - nxt > relative_tol * max(err, 1e-300):
            raise SolverError(f"batch Levenberg-Marquardt did not converge within max_iterations "
                              f"= {max_iterations} (error {err0:.6g} -> {err:.6g}, still falling to "
                              f"{nxt:.6g}): a poor start (start it from the incremental "
                              "solution) or more iterations")
    cpu = time.process_time() - c0
    P, Lm = _read(g, sol, problem.n_poses, problem.n_landmarks)
    return SmoothingResult("batch", problem.t.copy(), P, Lm, cpu, float(err0), float(err), int(its))


def solve_isam2(problem: GraphProblem, *, relinearize_threshold: float = 0.1,
                relinearize_skip: int = 10, factorization: str = "QR",
                every: int = 1) -> SmoothingResult:
    """iSAM2 over the problem's poses in time order: an update every ``every`` poses with
    their factors; a new pose starts at the previous pose's current estimate moved by the
    odometry, a new landmark at its first detection seen from there
    (``observation.inverse_observe``). factorization 'QR' (default) or 'CHOLESKY'.
    Besides the final (smoothed) solution, the result keeps each pose's estimate right
    after the update that first held it (``filtered``: with ``every = 1`` what iSAM2 knew
    of that pose at its own time, as a filter would) and each pose's whole CPU
    (``node_cpu``; chapter 10 times it against the EKF scan by scan).
    Needs a prior on the first pose (ValueError): iSAM2 solves from its first update on, and
    a first pose held by a GPS position alone has a free heading there (``solve_batch``
    takes a graph fixed by GPS fixes alone). Raises :class:`SolverError` if an update finds
    the system indeterminate."""
    g = _gtsam()
    check_problem(problem)
    if problem.prior_pose is None:
        raise ValueError("solve_isam2 needs a prior on the first pose (problem.prior_pose): its "
                         "first update would hold pose 0 by a GPS position alone, its heading "
                         "free; solve such a graph with solve_batch")
    every = _checks.integer("every", every, lo=1)
    _checks.choice("factorization", factorization, ("QR", "CHOLESKY"))
    c0 = time.process_time()
    params = g.ISAM2Params()
    params.setFactorization(factorization)
    params.setRelinearizeThreshold(relinearize_threshold)
    params.relinearizeSkip = relinearize_skip
    isam = g.ISAM2(params)
    fac = _Factors(g, problem)
    graph, values = g.NonlinearFactorGraph(), g.Values()
    prior = fac.prior()
    if prior is not None:
        graph.add(prior)
    known = np.zeros(problem.n_landmarks, dtype=bool)
    guess = last = np.asarray(problem.prior_pose if problem.prior_pose is not None
                              else problem.initial_poses[0], float)
    step_cpu, step_lm, all_factors = [], [], g.NonlinearFactorGraph()
    K = problem.n_poses
    filtered, node_end = np.empty((K, 3)), np.empty(K)
    block = 0                                   # the first pose not yet updated
    for k in range(K):
        if k > 0:
            guess = last = compose(last, problem.odometry[k - 1])
        values.insert(pose_key(k), g.Pose2(*guess))
        for f in fac.at(k):
            graph.add(f)
        for i in fac.observations_at(k).tolist():
            j = int(problem.obs_landmark[i])
            if not known[j]:
                known[j] = True
                lm, _, _ = inverse_observe(guess, problem.obs_z[i])
                values.insert(landmark_key(j), g.Point2(*lm))
        if (k + 1) % every and k < K - 1:
            node_end[k] = time.process_time()
            continue
        s0 = time.process_time()
        try:
            isam.update(graph, values)
        except RuntimeError as e:
            raise _indeterminate(e, f"iSAM2 update at pose {k}") from e
        step_cpu.append(time.process_time() - s0)
        step_lm.append(int(known.sum()))
        all_factors.push_back(graph)
        graph, values = g.NonlinearFactorGraph(), g.Values()
        for i in range(block, k + 1):           # the estimate now, before any later data
            p = isam.calculateEstimatePose2(pose_key(i))
            filtered[i] = p.x(), p.y(), p.theta()
        block = k + 1
        last = filtered[k].copy()
        node_end[k] = time.process_time()
    sol = isam.calculateEstimate()
    cpu = time.process_time() - c0
    node_cpu = np.diff(node_end, prepend=c0)
    P, Lm = _read(g, sol, K, problem.n_landmarks)
    init = g.Values()
    for k in range(K):
        init.insert(pose_key(k), g.Pose2(*problem.initial_poses[k]))
    for j in range(problem.n_landmarks):
        init.insert(landmark_key(j), g.Point2(*problem.initial_landmarks[j]))
    return SmoothingResult("isam2", problem.t.copy(), P, Lm, cpu,
                           float(all_factors.error(init)), float(all_factors.error(sol)),
                           len(step_cpu), np.array(step_cpu), np.array(step_lm, dtype=np.int64),
                           node_cpu, filtered)


def marginals(problem: GraphProblem, result: SmoothingResult) -> tuple[np.ndarray, np.ndarray]:
    """Marginal covariances at a solution (``gtsam.Marginals`` of the whole graph): poses
    (K, 3, 3) moved from GTSAM's tangent space to the filter's world-frame (dx, dy, dphi)
    (B Sigma B^T, B = blockdiag(R(phi), 1): the inverse of ``problem.world_to_tangent``),
    landmarks (L, 2, 2). For comparing with the EKF's covariances and for NEES."""
    g = _gtsam()
    graph, values = build_graph(problem, result.poses, result.landmarks)
    try:
        m = g.Marginals(graph, values)
    except RuntimeError as e:
        raise _indeterminate(e, "marginals") from e
    K, L = problem.n_poses, problem.n_landmarks
    P = np.empty((K, 3, 3))
    for k in range(K):
        P[k] = tangent_to_world(m.marginalCovariance(pose_key(k)), float(result.poses[k, 2]))
    Lc = np.empty((L, 2, 2))
    for j in range(L):
        Lc[j] = m.marginalCovariance(landmark_key(j))
    return P, Lc
