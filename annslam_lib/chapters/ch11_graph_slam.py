"""Chapter 11 companion: graph-SLAM from scratch. The Car Park's graph as a least-squares
problem the chapter builds and solves itself (:mod:`annslam_lib.smoothing.gauss_newton`),
against GTSAM's batch solution on the same graph; the information matrix's sparsity beside
the EKF's dense covariance; what a missing prior and wrong associations do.

Each experiment is a function returning numbers (tested without a notebook).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from .. import _checks
from ..data.records import Dataset
from ..plots.style import RED, figure
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.runner import run
from ..smoothing import gauss_newton as gn
from ..smoothing import problem as gp
from ..smoothing import solve as gs

__all__ = ["setup", "car_park_problem", "sizes", "sparsity_figure", "against_gtsam",
           "gauge_eigenvalues", "without_prior", "wrong_associations", "WRONG_SHARE",
           "WRONG_SEED", "HUBER_K", "path_figure"]

#: The share of detections given to a wrong landmark in section 5, and the draw's seed.
WRONG_SHARE = 0.05
WRONG_SEED = 11
#: Huber's threshold on a detection's whitened error (section 5).
HUBER_K = 1.0


def car_park_problem(car: Dataset) -> dict:
    """The Car Park's EKF-SLAM run and its graph (chapter 10's ``build_problem``)."""
    _checks.instance("car", car, Dataset)
    ekf = run(car, SlamConfig.for_dataset("car_park"), progress=False)
    return {"ekf": ekf, "problem": gp.build_problem(car, ekf)}


def sizes(problem: gp.GraphProblem) -> dict:
    """The graph's counts: poses, landmarks, factors by kind, unknowns, error rows."""
    K, L = problem.n_poses, problem.n_landmarks
    prior = problem.prior_pose is not None
    rows = 3 * prior + 3 * (K - 1) + 2 * problem.obs_node.size + 2 * problem.gps_node.size
    return {"poses": K, "landmarks": L, "odometry": K - 1, "detections": problem.obs_node.size,
            "gps": problem.gps_node.size, "prior": int(prior), "unknowns": 3 * K + 2 * L,
            "rows": rows}


def sparsity_figure(problem: gp.GraphProblem, ekf):
    """Left: the nonzero entries of the information matrix J^T J at the EKF's estimate
    (poses first, then landmarks). Right: the EKF's final covariance (pose and map), every
    entry nonzero, as the magnitude of its correlations."""
    H = gn.information_matrix(problem)
    fig, (a, b) = figure(ncols=2, height=3.6)
    rows, cols = H.nonzero()
    a.plot(cols, rows, ",", color="k")
    a.set(xlim=(0, H.shape[1]), ylim=(H.shape[0], 0), xlabel="unknown (poses, then landmarks)",
          ylabel="unknown", title=f"graph: information matrix, {H.nnz / H.shape[0] ** 2:.1%} "
          "nonzero")
    P = ekf.covariance
    d = np.sqrt(np.diag(P))
    C = np.abs(P / np.outer(d, d))
    im = b.imshow(C, cmap="cividis", vmin=0, vmax=1)
    b.set(xlabel="state entry (pose, then landmarks)", ylabel="state entry",
          title=f"EKF: covariance, {np.mean(C > 1e-6):.0%} nonzero")
    fig.colorbar(im, ax=b, label="|correlation|")
    return fig


def against_gtsam(problem: gp.GraphProblem) -> dict:
    """The chapter's Gauss-Newton and GTSAM's batch Levenberg-Marquardt from the same start
    (the EKF's estimate): iterations, costs, the largest differences of the solutions, and
    each side's CPU seconds (process time, one run each)."""
    c0 = time.process_time()
    ours = gn.solve_gauss_newton(problem)
    c1 = time.process_time()
    theirs = gs.solve_batch(problem)
    c2 = time.process_time()
    dphi = np.angle(np.exp(1j * (ours.poses[:, 2] - theirs.poses[:, 2])))
    return {"ours": ours, "gtsam": theirs,
            "position": float(np.abs(ours.poses[:, :2] - theirs.poses[:, :2]).max()),
            "heading": float(np.abs(dphi).max()),
            "landmark": float(np.abs(ours.landmarks - theirs.landmarks).max()),
            "cpu_ours": c1 - c0, "cpu_gtsam": c2 - c1}


def _free(problem: gp.GraphProblem) -> gp.GraphProblem:
    return dataclasses.replace(problem, prior_pose=None, prior_cov=None,
                               gps_node=np.empty(0, np.int64), gps_xy=np.empty((0, 2)))


def gauge_eigenvalues(problem: gp.GraphProblem, poses, landmarks, k: int = 5) -> dict:
    """The k smallest eigenvalues of J^T J at a solution, with the prior and GPS and
    without them."""
    from scipy.linalg import eigh

    out = {}
    for name, p in (("with", problem), ("without", _free(problem))):
        H = gn.information_matrix(p, poses, landmarks).toarray()
        out[name] = eigh(H, eigvals_only=True, subset_by_index=[0, k - 1])
    return out


def without_prior(problem: gp.GraphProblem) -> dict:
    """What the solver says of the graph without its prior and GPS fixes: the check's
    refusal, and the factorisation's when the check is skipped."""
    free = _free(problem)
    said = {}
    try:
        gn.solve_gauss_newton(free)
    except ValueError as e:
        said["check"] = str(e)
    try:
        gn.solve_gauss_newton(free, check=False)
    except gs.SolverError as e:
        said["factorisation"] = str(e)
    return said


def wrong_associations(problem: gp.GraphProblem, share: float = WRONG_SHARE,
                       seed: int = WRONG_SEED, k: float = HUBER_K) -> dict:
    """A share of the detections given to a wrong landmark (a seeded draw); the solution
    of plain least squares and of Huber's loss against the clean solution: the largest
    landmark and position differences, metres."""
    clean = gn.solve_gauss_newton(problem)
    rng = np.random.default_rng(seed)
    lm = problem.obs_landmark.copy()
    bad = rng.choice(lm.size, int(share * lm.size), replace=False)
    lm[bad] = (lm[bad] + rng.integers(1, problem.n_landmarks, bad.size)) % problem.n_landmarks
    wrong = dataclasses.replace(problem, obs_landmark=lm)
    out = {"wrong": int(bad.size), "detections": int(lm.size)}
    for name, kk in (("plain", None), ("huber", k)):
        s = gn.solve_gauss_newton(wrong, huber_k=kk, max_iterations=100)
        out[name] = {"landmark": float(np.abs(s.landmarks - clean.landmarks).max()),
                     "position": float(np.hypot(*(s.poses[:, :2] - clean.poses[:, :2]).T).max()),
                     "solution": s}
    b = gs.solve_batch(wrong, huber_k=k, max_iterations=200)
    out["huber_vs_gtsam"] = float(max(np.abs(out["huber"]["solution"].poses[:, :2]
                                             - b.poses[:, :2]).max(),
                                      np.abs(out["huber"]["solution"].landmarks
                                             - b.landmarks).max()))
    return out


def path_figure(problem: gp.GraphProblem, plain, huber, clean):
    """The paths of section 5: clean, plain least squares with the wrong associations, and
    Huber's loss with them."""
    fig, ax = figure(height=3.8)
    ax.plot(clean.poses[:, 0], clean.poses[:, 1], color="k", lw=2, label="clean graph")
    ax.plot(plain.poses[:, 0], plain.poses[:, 1], color=RED, lw=1,
            label="5 % wrong, least squares")
    ax.plot(huber.poses[:, 0], huber.poses[:, 1], color="0.55", ls="--", lw=1,
            label="5 % wrong, Huber's loss")
    ax.set(xlabel="x [m]", ylabel="y [m]", title="the Car Park path with wrong associations")
    ax.set_aspect("equal", adjustable="datalim")          # equal scales, the full width
    ax.legend()
    return fig
