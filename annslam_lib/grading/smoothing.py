"""Checks for the graded exercises of chapter 10 (factor graphs).

``check_between_error``: an odometry factor's error Log(Delta^-1 X_i^-1 X_j), eq. (10.5).
``check_bearing_range_error``: a range-bearing factor's error in GTSAM's order, eq. (10.6).
``check_tangent_to_world``: a marginal covariance read in the filter's coordinates, eq. (10.7).
References: :mod:`annslam_lib.smoothing.factors` (itself tested against GTSAM's factors).
"""
from __future__ import annotations

import math

import numpy as np

from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..smoothing import factors
from ..smoothing.problem import compose, relative_pose, world_to_tangent
from .core import Mistake, passed, check_function, forbids

__all__ = ["check_between_error", "check_bearing_range_error", "check_tangent_to_world"]

_B_ARGS = ("xi", "xj", "delta")
_BR_ARGS = ("pose", "landmark", "z")
_T_ARGS = ("S", "phi")



def _pose(rng, spread=30.0):
    return np.array([rng.uniform(-spread, spread), rng.uniform(-spread, spread),
                     rng.uniform(-math.pi, math.pi)])


# ------------------------------------------------------------------------- 10.1 between

def _between_cases(seed: int, n: int) -> list[tuple]:
    """Exact odometry (error zero), small and large rotations between the poses, headings on
    both sides of +-pi, errors whose own rotation (the logarithm's argument) is near pi and
    near 0, then ``n`` seeded random poses with noisy relative poses."""
    rng = np.random.default_rng(seed)
    cases = []
    for th in (0.0, 1e-5, 0.3, -2.0, 3.1, -3.13):
        xi = _pose(rng)
        d = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), th])
        xj = compose(xi, d)
        cases.append((xi, xj, d.copy()))
        noisy = d + rng.normal(0, [0.2, 0.2, 0.05])
        noisy[2] = wrap_angle(noisy[2])
        cases.append((xi, xj, noisy))
    cases.append((np.array([1.0, 2.0, math.pi - 0.01]), np.array([3.0, 2.5, -math.pi + 0.02]),
                  np.array([-2.0, 0.4, 0.05])))
    for th in (3.1, -3.13, 1e-5):             # the logarithm's own rotation near pi and near 0
        xi, xj = _pose(rng), _pose(rng)
        d = compose(relative_pose(xi, xj), np.array([rng.uniform(-4, 4), rng.uniform(-4, 4), -th]))
        cases.append((xi, xj, d))
    for _ in range(n):
        xi, xj = _pose(rng), _pose(rng)
        d = relative_pose(xi, xj) + rng.normal(0, [0.5, 0.5, 0.3])
        d[2] = wrap_angle(d[2])
        cases.append((xi, xj, d))
    return cases


def _between_mistakes(name: str) -> list[Mistake]:
    def world_difference(xi, xj, d):          # x_j - x_i - Delta, no frames
        e = np.asarray(xj, float) - np.asarray(xi, float) - np.asarray(d, float)
        e[2] = wrap_angle(e[2])
        return e

    def no_log(xi, xj, d):                    # the relative pose's coordinates, no V^-1
        return relative_pose(d, relative_pose(xi, xj))

    def reversed_pair(xi, xj, d):             # X_j^-1 X_i
        return factors.se2_log(relative_pose(d, relative_pose(xj, xi)))

    def delta_after(xi, xj, d):               # (X_i^-1 X_j)^-1 Delta: the sign flipped
        return factors.se2_log(relative_pose(relative_pose(xi, xj), d))

    return [
        Mistake(f"{name} subtracts poses in the world frame (x_j − x_i − Δ): Δ is measured in "
                "the frame of pose i, so it must be compared with pose j as seen from pose i.",
                world_difference, "Compare Δ with X_i⁻¹ X_j."),
        Mistake(f"{name} returns the coordinates of Δ⁻¹ X_i⁻¹ X_j without the logarithm: the "
                "error lives in the tangent space, eq. (10.4). They differ once the rotation "
                "is not small.", no_log, "Log(·) = (V(θ)⁻¹ t, θ)."),
        Mistake(f"{name} composes the pair the wrong way round: Δ is pose j in the frame of "
                "pose i.", reversed_pair, "X_i⁻¹ X_j, not X_j⁻¹ X_i."),
        Mistake(f"{name} has the error's sign flipped: GTSAM's error is the prediction "
                "against the measurement (eq. (10.4)).", delta_after,
                "Log(Δ⁻¹ X_i⁻¹ X_j), not Log((X_i⁻¹ X_j)⁻¹ Δ)."),
    ]


@forbids(factors.between_error, factors.se2_log)
def check_between_error(fn, *, seed: int = 0, n: int = 30, name: str = "my_between_error",
                        quiet: bool = False) -> str:
    """Grade ``fn(xi, xj, delta) -> (3,)``, chapter 10 eq. (10.5): the error of an odometry
    factor, Log(Delta^-1 X_i^-1 X_j), in GTSAM's tangent coordinates. Reference:
    ``smoothing.factors.between_error`` (equal to GTSAM's ``BetweenFactorPose2``).

    Catches a world-frame difference, the logarithm left out, the pair reversed, the sign
    flipped."""
    cases = _between_cases(seed, n)
    check_function(fn, factors.between_error, cases, name=name, arg_names=_B_ARGS,
                   labels=("v_x", "v_y", "ω"), angles=[2], mistakes=_between_mistakes(name),
                   what="smoothing.factors.between_error", quiet=True, rtol=1e-6, atol=1e-8)
    return passed(f"✓ {name} agrees with smoothing.factors.between_error (GTSAM's "
                  f"BetweenFactorPose2) on {len(cases)} pose pairs (errors rotated near 0 and "
                  "near π, headings across ±π).", quiet)


# ------------------------------------------------------------------- 10.2 bearing-range

def _br_cases(seed: int, n: int) -> list[tuple]:
    """A sighting across the bearing seam, one exact, one with the landmark behind, then
    ``n`` seeded random ones."""
    rng = np.random.default_rng(seed)
    cases = []
    pose = np.array([0.0, 0.0, 0.0])
    a = -math.pi / 2 + math.pi - 0.003                   # laser bearing pi - 0.003
    lm = 10 * np.array([math.cos(a), math.sin(a)])
    cases.append((pose, lm, np.array([10.2, -math.pi + 0.004])))
    pose = np.array([4.0, -2.0, 1.1])
    lm = np.array([9.0, 6.0])
    cases.append((pose, lm, observe(pose, lm)[0]))
    cases.append((pose, np.array([-3.0, -8.0]), np.array([12.0, -1.0])))
    for _ in range(n):
        pose = _pose(rng)
        ang, r = rng.uniform(-math.pi, math.pi), rng.uniform(2, 40)
        lm = pose[:2] + r * np.array([math.cos(ang), math.sin(ang)])
        zhat = observe(pose, lm)[0]
        z = zhat + rng.normal(0, [0.3, 0.05])
        z[1] = wrap_angle(z[1])
        cases.append((pose, lm, z))
    return cases


def _br_mistakes(name: str) -> list[Mistake]:
    def range_first(pose, lm, z):
        e = factors.bearing_range_error(pose, lm, z)
        return e[::-1]

    def measured_minus_predicted(pose, lm, z):
        return -factors.bearing_range_error(pose, lm, z)

    def unwrapped(pose, lm, z):
        zhat = observe(pose, lm)[0]
        return np.array([zhat[1] - z[1], zhat[0] - z[0]])

    def gtsam_bearing_vs_laser(pose, lm, z):   # GTSAM's bearing (from x) against the laser's
        zhat = observe(pose, lm)[0]
        return np.array([float(wrap_angle(zhat[1] - math.pi / 2 - z[1])), zhat[0] - z[0]])

    return [
        Mistake(f"{name} returns (range, bearing): GTSAM's BearingRange has its own order, "
                "and its noise model is ordered the same way.", range_first,
                "The bearing comes first: (σ_β, σ_r), e = (wrap(β̂ − β), r̂ − r)."),
        Mistake(f"{name} returns measured − predicted: a factor's error has the other sign.",
                measured_minus_predicted, "h(x) ⊖ z, the prediction against the measurement."),
        Mistake(f"{name} does not wrap the bearing error: a landmark predicted just below +π "
                "and measured just above −π is 0.007 rad off, not almost 2π.", unwrapped,
                "Wrap β̂ − β into (−π, π]."),
        Mistake(f"{name} compares GTSAM's bearing (from the pose's x axis) with the laser's "
                "(0 to the right, π/2 ahead): measure both in one convention.",
                gtsam_bearing_vs_laser,
                "The difference of two laser bearings is the same as of two GTSAM bearings."),
    ]


@forbids(factors.bearing_range_error)
def check_bearing_range_error(fn, *, seed: int = 0, n: int = 30,
                              name: str = "my_bearing_range_error", quiet: bool = False) -> str:
    """Grade ``fn(pose, landmark, z) -> (2,)``, chapter 10 eq. (10.6): a range-bearing
    factor's error (bearing, range) = (wrap(beta_hat - beta), r_hat - r). Reference:
    ``smoothing.factors.bearing_range_error`` (equal to GTSAM's ``BearingRangeFactor2D``
    with the laser's bearing shifted by -pi/2)."""
    cases = _br_cases(seed, n)
    check_function(fn, factors.bearing_range_error, cases, name=name, arg_names=_BR_ARGS,
                   labels=("bearing error", "range error"), angles=[0],
                   mistakes=_br_mistakes(name), what="smoothing.factors.bearing_range_error",
                   quiet=True, rtol=1e-6, atol=1e-9)
    return passed(f"✓ {name} agrees with smoothing.factors.bearing_range_error (GTSAM's "
                  f"BearingRangeFactor2D) on {len(cases)} sightings (across the bearing seam).",
                  quiet)


# -------------------------------------------------------------------- 10.3 the marginal

def _t_cases(seed: int, n: int) -> list[tuple]:
    rng = np.random.default_rng(seed)
    cases = [(np.diag([0.04, 0.01, 0.001]), 0.0), (np.diag([0.04, 0.01, 0.001]), math.pi / 2),
             (np.diag([0.09, 0.0004, 0.0003]), -2.5)]
    for _ in range(n):
        A = rng.normal(size=(3, 3)) * np.array([0.3, 0.3, 0.02])
        cases.append((A @ A.T + np.diag([1e-4, 1e-4, 1e-6]), float(rng.uniform(-math.pi, math.pi))))
    return cases


def _t_mistakes(name: str) -> list[Mistake]:
    def untouched(S, phi):
        return np.asarray(S, float)

    def transposed(S, phi):                   # A S A^T: world -> tangent instead
        return world_to_tangent(S, phi)

    def position_only(S, phi):                # the heading's cross terms left unrotated
        c, s = math.cos(phi), math.sin(phi)
        R = np.array([[c, -s], [s, c]])
        out = np.asarray(S, float).copy()
        out[:2, :2] = R @ out[:2, :2] @ R.T
        return out

    def flat(f):
        return lambda S, phi: np.ravel(f(S, phi))

    untouched, transposed, position_only = flat(untouched), flat(transposed), flat(position_only)
    return [
        Mistake(f"{name} returns GTSAM's covariance as it is: its position part is in the "
                "pose's own (body) frame; the filter's is in the world frame.", untouched,
                "Rotate by B = blockdiag(R(φ), 1): B S Bᵀ."),
        Mistake(f"{name} rotates the wrong way (world to body): GTSAM's covariance is in the "
                "body frame.", transposed, "R(φ), not R(φ)ᵀ, takes it to the world."),
        Mistake(f"{name} rotates only the 2 × 2 position block: the position-heading "
                "covariances (the third row and column) turn with it.", position_only,
                "B S Bᵀ with B = blockdiag(R(φ), 1)."),
    ]


@forbids(factors.tangent_to_world, world_to_tangent)
def check_tangent_to_world(fn, *, seed: int = 0, n: int = 30, name: str = "my_tangent_to_world",
                           quiet: bool = False) -> str:
    """Grade ``fn(S, phi) -> (3, 3)``, chapter 10 eq. (10.7): GTSAM's marginal covariance of
    a pose (tangent space) in the filter's world coordinates, B S B^T. Reference:
    ``smoothing.factors.tangent_to_world``."""
    cases = _t_cases(seed, n)
    check_function(fn, factors.tangent_to_world, cases, name=name, arg_names=_T_ARGS,
                   labels=tuple(f"P[{i}, {j}]" for i in range(3) for j in range(3)),
                   output=lambda out: np.ravel(np.asarray(out, dtype=float)),
                   mistakes=_t_mistakes(name), what="smoothing.factors.tangent_to_world",
                   quiet=True, rtol=1e-6, atol=1e-12)
    return passed(f"✓ {name} agrees with smoothing.factors.tangent_to_world on {len(cases)} "
                  "covariances.", quiet)
