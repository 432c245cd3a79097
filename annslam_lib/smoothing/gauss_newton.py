"""Graph-SLAM from scratch: the least-squares problem of a :class:`~.problem.GraphProblem`
built and solved by Gauss-Newton with a sparse solve, in numpy and scipy only.

The unknowns are the K poses (x, y, phi) and the L landmarks (x, y), one vector of 3K + 2L
numbers; a step moves them additively (the heading wrapped). Each factor has an error e
and a covariance S, the same as GTSAM's factors of :mod:`.solve` (so both minimise the same
cost, half the sum of e^T S^-1 e):

- the prior on pose 0: e = Log(P^-1 X_0), S = the prior's covariance;
- odometry between poses i and i + 1: e = Log(Delta^-1 X_i^-1 X_{i+1}) (:func:`.factors.between_error`);
- a range-bearing detection: e = (wrap(beta_hat - beta), r_hat - r), S = diag(sigma_beta^2, sigma_r^2),
  its Jacobians the observation model's (:func:`~annslam_lib.models.observation.observe`);
- a GPS fix: e = t(X) - xy, S = sigma_gps^2 I.

Each error is whitened (e_w = L^-1 e with S = L L^T) and stacked with its Jacobian rows
into a sparse J; one Gauss-Newton step solves the normal equations (J^T J) dx = -J^T e
(the information matrix J^T J is sparse: a pose touches its neighbours and the landmarks it
saw), accepted if the cost falls, halved otherwise. Log on SE(2) and its derivative are
written out (:func:`se2_log_jacobian`), not differentiated numerically.

Under-determined problems are refused before any step (:func:`~.problem.check_problem`: no
prior and too few GPS positions, a landmark no factor reaches) and again by the
factorisation: an information matrix that is singular (a free direction) raises
:class:`~.solve.SolverError` naming the variable where the factorisation failed.
"""
from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.observation import observe
from .problem import GraphProblem, check_problem
from .solve import SmoothingResult, SolverError

__all__ = ["se2_log_jacobian", "linearise", "information_matrix", "step",
           "solve_gauss_newton", "cost", "huber"]


def se2_log_jacobian(u, theta) -> tuple[np.ndarray, np.ndarray]:
    """Log of SE(2) at (u, theta) (..., 2), (...,) and its derivative with respect to theta
    at fixed u: xi = (V(theta)^-1 u, theta) with V^-1 = [[s, c], [-c, s]] / (s^2 + c^2),
    s = sin(theta)/theta, c = (1 - cos(theta))/theta (series below 1e-4 rad). Returns
    (xi (..., 3), d(V^-1 u)/d theta (..., 2))."""
    u = np.asarray(u, float)
    th = np.asarray(theta, float)
    small = np.abs(th) < 1e-4
    t = np.where(small, 1.0, th)
    s = np.where(small, 1.0 - th * th / 6.0, np.sin(t) / t)
    c = np.where(small, th / 2.0 - th ** 3 / 24.0, (1.0 - np.cos(t)) / t)
    ds = np.where(small, -th / 3.0, (t * np.cos(t) - np.sin(t)) / (t * t))
    dc = np.where(small, 0.5 - th * th / 8.0, (t * np.sin(t) - (1.0 - np.cos(t))) / (t * t))
    det = s * s + c * c
    ddet = 2.0 * (s * ds + c * dc)
    ux, uy = u[..., 0], u[..., 1]
    a = (s * ux + c * uy) / det
    b = (-c * ux + s * uy) / det
    da = (ds * ux + dc * uy) / det - ddet / det * a
    db = (-dc * ux + ds * uy) / det - ddet / det * b
    return np.stack([a, b, th], -1), np.stack([da, db], -1)


def _between(xi, xj, delta):
    """Errors (M, 3) of between factors and their Jacobians (M, 3, 3) with respect to the
    additive (x, y, phi) of pose i and of pose j."""
    ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    cd, sd = np.cos(delta[:, 2]), np.sin(delta[:, 2])
    dt = xj[:, :2] - xi[:, :2]
    # w = R_i^T (t_j - t_i); u = R_delta^T (w - t_delta); theta = phi_j - phi_i - phi_delta
    w = np.stack([ci * dt[:, 0] + si * dt[:, 1], -si * dt[:, 0] + ci * dt[:, 1]], -1)
    v = w - delta[:, :2]
    u = np.stack([cd * v[:, 0] + sd * v[:, 1], -sd * v[:, 0] + cd * v[:, 1]], -1)
    th = wrap_angle(xj[:, 2] - xi[:, 2] - delta[:, 2])
    e, dlog = se2_log_jacobian(u, th)
    Vinv = np.empty((len(th), 2, 2))
    tiny = np.abs(th) < 1e-4
    t = np.where(tiny, 1.0, th)
    s = np.where(tiny, 1.0 - th * th / 6.0, np.sin(t) / t)
    c = np.where(tiny, th / 2.0, (1.0 - np.cos(t)) / t)
    det = s * s + c * c
    Vinv[:, 0, 0], Vinv[:, 0, 1] = s / det, c / det
    Vinv[:, 1, 0], Vinv[:, 1, 1] = -c / det, s / det
    Rd_T = np.stack([np.stack([cd, sd], -1), np.stack([-sd, cd], -1)], -2)     # (M, 2, 2)
    Ri_T = np.stack([np.stack([ci, si], -1), np.stack([-si, ci], -1)], -2)
    A = Vinv @ Rd_T @ Ri_T                                                       # de/dt_j
    dw_dphi = np.stack([-si * dt[:, 0] + ci * dt[:, 1], -ci * dt[:, 0] - si * dt[:, 1]], -1)
    de_dphi_i = (Vinv @ Rd_T @ dw_dphi[..., None])[..., 0] - dlog
    Ji = np.zeros((len(th), 3, 3))
    Jj = np.zeros((len(th), 3, 3))
    Ji[:, :2, :2], Jj[:, :2, :2] = -A, A
    Ji[:, :2, 2], Jj[:, :2, 2] = de_dphi_i, dlog
    Ji[:, 2, 2], Jj[:, 2, 2] = -1.0, 1.0
    return e, Ji, Jj


def _whitener(cov) -> np.ndarray:
    """L^-1 with cov = L L^T, for each (..., n, n) covariance."""
    return np.linalg.inv(np.linalg.cholesky(cov))


class _Blocks:
    """Whitened error rows and their Jacobian blocks, gathered into one sparse matrix."""

    def __init__(self, n: int):
        self.n, self.errors, self.rows, self.cols, self.vals = n, [], [], [], []
        self.m = 0

    def add(self, e, blocks) -> None:
        """e (M, d) whitened errors; blocks: [(J (M, d, w), first column (M,))]."""
        M, d = e.shape
        self.errors.append(e.reshape(-1))
        r0 = self.m + np.arange(M) * d
        for J, col in blocks:
            w = J.shape[2]
            rr = r0[:, None, None] + np.arange(d)[None, :, None] + np.zeros((1, 1, w), int)
            cc = col[:, None, None] + np.zeros((1, d, 1), int) + np.arange(w)[None, None, :]
            self.rows.append(rr.reshape(-1))
            self.cols.append(cc.reshape(-1))
            self.vals.append(J.reshape(-1))
        self.m += M * d

    def matrix(self):
        e = np.concatenate(self.errors)
        J = sp.csr_matrix((np.concatenate(self.vals), (np.concatenate(self.rows),
                           np.concatenate(self.cols))), shape=(self.m, self.n))
        return e, J


def linearise(problem: GraphProblem, poses, landmarks) -> tuple[np.ndarray, sp.csr_matrix]:
    """The whitened errors e (m,) of every factor at ``poses`` (K, 3), ``landmarks`` (L, 2)
    and their sparse Jacobian J (m, 3K + 2L): columns 3k..3k+2 pose k, 3K + 2j.. landmark j.
    Rows: the prior (3), the odometry (3 each), the detections (2 each, in the problem's
    order), the GPS fixes (2 each)."""
    e, J, _ = _linearise(problem, poses, landmarks)
    return e, J


def _linearise(problem: GraphProblem, poses, landmarks):
    """:func:`linearise` and the slice of its detection rows."""
    K, L = problem.n_poses, problem.n_landmarks
    poses = _checks.array("poses", poses, (K, 3))
    landmarks = _checks.array("landmarks", landmarks, (L, 2))
    out = _Blocks(3 * K + 2 * L)
    if problem.prior_pose is not None:
        prior = np.asarray(problem.prior_pose, float)[None]
        e, _, Jj = _between(prior, poses[:1], np.zeros((1, 3)))
        W = _whitener(np.asarray(problem.prior_cov, float))
        out.add(e @ W.T, [(W @ Jj, np.array([0]))])
    if K > 1:
        k = np.arange(K - 1)
        e, Ji, Jj = _between(poses[k], poses[k + 1], problem.odometry)
        W = _whitener(problem.odometry_cov)
        out.add((W @ e[..., None])[..., 0], [(W @ Ji, 3 * k), (W @ Jj, 3 * (k + 1))])
    first = out.m
    if problem.obs_node.size:
        node, lm = problem.obs_node, problem.obs_landmark
        zhat, Hx, Hl = observe(poses[node], landmarks[lm])
        e = np.stack([wrap_angle(zhat[:, 1] - problem.obs_z[:, 1]),
                      zhat[:, 0] - problem.obs_z[:, 0]], -1)
        w = np.array([1.0 / problem.sigma_bearing, 1.0 / problem.sigma_range])
        swap = [1, 0]                                   # GTSAM's order: bearing, range
        out.add(e * w, [(Hx[:, swap, :] * w[None, :, None], 3 * node),
                        (Hl[:, swap, :] * w[None, :, None], 3 * K + 2 * lm)])
    if problem.gps_node.size:
        g = problem.gps_node
        e = (poses[g, :2] - problem.gps_xy) / problem.sigma_gps
        J = np.zeros((g.size, 2, 3))
        J[:, 0, 0] = J[:, 1, 1] = 1.0 / problem.sigma_gps
        out.add(e, [(J, 3 * g)])
    e, J = out.matrix()
    return e, J, slice(first, first + 2 * problem.obs_node.size)


def huber(r, k: float):
    """Huber's loss of whitened error norms ``r`` and the weights w = rho'(r)/r that make a
    least-squares step minimise it (iteratively reweighted least squares): rho = r^2/2 up to
    ``k``, k r - k^2/2 beyond (GTSAM's ``mEstimator.Huber``)."""
    r = np.asarray(r, float)
    big = r > k
    rho = np.where(big, k * r - 0.5 * k * k, 0.5 * r * r)
    w = np.where(big, k / np.where(big, r, 1.0), 1.0)
    return rho, w


def _robust(e, J, rb: slice, k: float | None):
    """The cost and the reweighted (e, J): the detections' rows scaled by sqrt(w) of
    :func:`huber` (``k`` None: plain least squares)."""
    if k is None:
        return 0.5 * float(e @ e), e, J
    r = np.hypot(e[rb][0::2], e[rb][1::2])
    rho, w = huber(r, k)
    scale = np.ones(e.size)
    scale[rb] = np.repeat(np.sqrt(w), 2)
    rest = np.ones(e.size, bool)
    rest[rb] = False
    f = 0.5 * float(e[rest] @ e[rest]) + float(rho.sum())
    return f, e * scale, sp.diags(scale) @ J


def cost(problem: GraphProblem, poses, landmarks, *, huber_k: float | None = None) -> float:
    """Half the sum of squared whitened errors (GTSAM's ``graph.error``); with ``huber_k``,
    the detections' terms are Huber's loss of their whitened norms instead."""
    e, J, rb = _linearise(problem, poses, landmarks)
    return _robust(e, J, rb, huber_k)[0]


def information_matrix(problem: GraphProblem, poses=None, landmarks=None) -> sp.csc_matrix:
    """J^T J at the given (default: the problem's initial) estimate: the information
    matrix whose sparsity pattern the chapter draws."""
    poses = problem.initial_poses if poses is None else poses
    landmarks = problem.initial_landmarks if landmarks is None else landmarks
    _, J = linearise(problem, poses, landmarks)
    return (J.T @ J).tocsc()


def _normal_step(J, e, K: int | None) -> np.ndarray:
    """dx of (J^T J) dx = -J^T e by a sparse LU factorisation (COLAMD ordering); a
    singular J^T J raises :class:`SolverError` naming the variable (with ``K``, the number
    of poses: pose or landmark)."""
    H = (J.T @ J).tocsc()
    g = J.T @ e

    def named(i: int) -> str:
        return _variable(i, K) if K is not None else f"unknown {i}"

    try:
        lu = spla.splu(H, permc_spec="COLAMD")
    except RuntimeError as err:
        empty = np.flatnonzero(H.diagonal() == 0)
        where = f" at {named(int(empty[0]))}" if empty.size else ""
        raise SolverError(f"the information matrix is singular{where} ({err}): an "
                          "under-determined graph (no prior, or a landmark the factors "
                          "do not pin down)") from err
    pivots = np.abs(lu.U.diagonal())
    if pivots.min() <= 1e-12 * pivots.max():
        bad = int(lu.perm_c[int(np.argmin(pivots))])
        raise SolverError(f"the information matrix is singular at {named(bad)}: an "
                          "under-determined graph (no prior, or a landmark the factors do "
                          "not pin down)")
    return -lu.solve(g)


def step(J, e) -> np.ndarray:
    """One Gauss-Newton step, eq. (11.4) of chapter 11: dx solving (J^T J) dx = -J^T e for
    a sparse Jacobian J (m, n) and whitened errors e (m,); a singular J^T J raises
    :class:`SolverError`."""
    J = sp.csr_matrix(J)
    e = _checks.array("e", e)
    if e.shape != (J.shape[0],):
        raise ValueError(f"e must have shape ({J.shape[0]},) for J {J.shape}, got {e.shape}")
    return _normal_step(J, e, None)


def _variable(index: int, K: int) -> str:
    return f"pose {index // 3}" if index < 3 * K else f"landmark {(index - 3 * K) // 2}"


def solve_gauss_newton(problem: GraphProblem, poses=None, landmarks=None, *,
                       max_iterations: int = 50, relative_tol: float = 1e-10,
                       huber_k: float | None = None, check: bool = True) -> SmoothingResult:
    """Gauss-Newton from ``poses`` / ``landmarks`` (default: the problem's initial, the
    EKF's estimate) until the cost falls by less than ``relative_tol`` of itself (module
    docstring). ``huber_k``: the detections weighed by Huber's loss (:func:`huber`) with
    that threshold on their whitened error, so that a wrong association pulls with a bounded
    force (the weights recomputed at every step). ``check=False`` skips
    :func:`~.problem.check_problem` (to show what the factorisation says of an
    under-determined graph). Raises :class:`SolverError` for a singular information matrix,
    a non-finite cost, or no convergence within ``max_iterations``."""
    max_iterations = _checks.integer("max_iterations", max_iterations, lo=1)
    if huber_k is not None:
        huber_k = _checks.real("huber_k", huber_k)
        if not huber_k > 0:
            raise ValueError(f"huber_k must be positive, got {huber_k}")
    c0 = time.process_time()
    if check:
        check_problem(problem)
    K = problem.n_poses
    x = np.array(problem.initial_poses if poses is None else poses, float)
    m = np.array(problem.initial_landmarks if landmarks is None else landmarks, float)
    f, e, J = _robust(*_linearise(problem, x, m), huber_k)
    f0 = f
    it = 0
    while True:
        if it >= max_iterations:
            raise SolverError(f"Gauss-Newton did not converge in {max_iterations} iterations "
                              f"(cost {f0:.6g} -> {f:.6g})")
        it += 1
        dx = _normal_step(J, e, K)
        frac = 1.0
        while True:
            xn = x + frac * dx[:3 * K].reshape(K, 3)
            xn[:, 2] = wrap_angle(xn[:, 2])
            mn = m + frac * dx[3 * K:].reshape(-1, 2)
            fn, en, Jn = _robust(*_linearise(problem, xn, mn), huber_k)
            if not math.isfinite(fn):
                raise SolverError(f"Gauss-Newton reached a non-finite cost at iteration {it}")
            if fn <= f or frac < 1e-3:
                break
            frac *= 0.5
        done = f - fn <= relative_tol * max(f, 1e-300)
        x, m, e, J, f = xn, mn, en, Jn, fn
        if done:
            break
    cpu = time.process_time() - c0
    return SmoothingResult("gauss-newton", problem.t.copy(), x, m, cpu, f0, f, it)

