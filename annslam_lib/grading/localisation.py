"""Checks for the graded exercises of chapter 04a (EKF localisation).

``check_beacon_update``: one localisation update of the pose by a sighting of a known
beacon (pose and covariance after it), with the bearing innovation and the heading
wrapped. ``check_nis_verdict``: the two-sided chi-square verdict on a run's NIS.
References: :mod:`annslam_lib.slam.localisation`.
"""
from __future__ import annotations

import math

import numpy as np

from ..models.observation import observe
from ..slam import dense, localisation
from .core import (Mistake, passed, call, check_function, check_raises, describe, fail, forbids, prefetch,
                   wrap_pi)
from .kalman import chi2_ppf

__all__ = ["check_beacon_update", "check_nis_verdict"]

_U_ARGS = ("pose", "P", "z", "beacon", "R")
_LABELS = ("x+", "y+", "phi+") + tuple(f"P+[{i}, {j}]" for i in range(3) for j in range(3))


def _flat(out):
    """(pose+, P+) as one vector of 12 numbers: what the check compares."""
    pose, P = out
    return np.concatenate([np.ravel(np.asarray(pose, dtype=float)),
                           np.ravel(np.asarray(P, dtype=float))])


def _reference(pose, P, z, beacon, R):
    new, P_new, _ = localisation.beacon_update(pose, P, z, beacon, R)
    return new, P_new


def _variant(*, H_of=lambda Hp, Hm: Hp, nu_of=None, R_used=True, wrap_heading=True):
    """A wrong update built from the right pieces with one of them changed."""
    def wrong(pose, P, z, beacon, R):
        zhat, Hp, Hm = observe(np.asarray(pose, float), np.asarray(beacon, float))
        H = H_of(Hp, Hm)
        nu = np.asarray(z, float) - zhat
        nu = nu_of(nu) if nu_of else np.array([nu[0], wrap_pi(nu[1])])
        Rr = np.asarray(R, float) if R_used else np.zeros((2, 2))
        S = H @ P @ H.T + Rr
        K = P @ H.T @ np.linalg.inv(S)
        new = np.asarray(pose, float) + K @ nu
        if wrap_heading:
            new[2] = wrap_pi(new[2])
        IKH = np.eye(3) - K @ H
        return _flat((new, IKH @ P @ IKH.T + K @ np.asarray(R, float) @ K.T))
    return wrong


def _cases(seed: int, n: int) -> list[tuple]:
    """A sighting across the bearing seam (predicted just below +pi, measured just above
    -pi), a heading that crosses +-pi in the update, a beacon straight ahead and one
    behind, the chapter's numbers, then ``n`` seeded random poses, covariances, beacons and
    sightings (innovations drawn from S)."""
    R0 = np.diag([0.1**2, math.radians(1.0) ** 2])
    P0 = np.diag([0.2**2, 0.2**2, math.radians(3.0) ** 2])
    cases = []
    # the bearing seam: the laser bearing is the angle from the laser's right (chapter 03);
    # a beacon at world direction phi - pi/2 + (pi - 0.003) has bearing pi - 0.003
    pose = np.array([0.0, 0.0, 0.0])
    a = -math.pi / 2 + math.pi - 0.003
    beacon = 10 * np.array([math.cos(a), math.sin(a)])
    cases.append((pose, P0, np.array([10.02, -math.pi + 0.004]), beacon, R0))
    # the heading close to +pi, pushed over it by the update
    pose = np.array([2.0, 1.0, math.pi - 0.002])
    b = pose[:2] + 8 * np.array([math.cos(pose[2] - 0.3), math.sin(pose[2] - 0.3)])
    zhat, _, _ = observe(pose, b)
    cases.append((pose, np.diag([0.3**2, 0.3**2, math.radians(5.0) ** 2]),
                  np.array([zhat[0], wrap_pi(zhat[1] - 0.06)]), b, R0))
    cases.append((np.array([5.0, -3.0, 0.4]), P0, None, np.array([12.0, 1.0]), R0))
    cases.append((np.array([5.0, -3.0, 0.4]), P0, None, np.array([-4.0, -7.0]), R0))
    rng = np.random.default_rng(seed)
    for _ in range(n):
        pose = np.r_[rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi)]
        A = rng.normal(size=(3, 3)) * np.array([0.3, 0.3, math.radians(3.0)]) * rng.uniform(0.3, 2)
        P = A @ A.T / 3 + np.diag([1e-4, 1e-4, 1e-6])
        ang, r = rng.uniform(-np.pi, np.pi), rng.uniform(2, 30)
        beacon = pose[:2] + r * np.array([math.cos(ang), math.sin(ang)])
        R = np.diag([rng.uniform(0.05, 0.3), math.radians(rng.uniform(0.5, 3))]) ** 2
        cases.append((pose, P, None, beacon, R))
    out = []
    for pose, P, z, beacon, R in cases:
        if z is None:                      # a sighting drawn from the prediction's S
            zhat, Hp, _ = observe(pose, beacon)
            S = Hp @ P @ Hp.T + R
            z = zhat + np.random.default_rng(len(out) + 17 * seed).multivariate_normal(np.zeros(2), S)
            z[1] = wrap_pi(z[1])
        out.append((pose, P, z, beacon, R))
    return out


@forbids(localisation.beacon_update, dense.joseph_update, dense.range_bearing_update,
         dense.innovation)
def check_beacon_update(fn, *, seed: int = 0, n: int = 40, name: str = "my_beacon_update",
                        quiet: bool = False) -> str:
    """Grade ``fn(pose, P, z, beacon, R) -> (pose+, P+)``, chapter 04a eq. 4a.1-4a.3: the
    EKF localisation update of the laser pose by one sighting of a beacon at a known
    position; ValueError for a beacon at the sensor. Reference:
    ``localisation.beacon_update``.

    Catches the landmark's Jacobian used for the pose's, an unwrapped bearing innovation,
    an unwrapped heading, the innovation's sign, R left out of S.
    """
    cases = _cases(seed, n)
    mistakes = [
        Mistake(f"{name} uses the Jacobian with respect to the LANDMARK (the third output of "
                "observation.observe), not the one with respect to the pose: the map is known, "
                "the pose is what the update corrects.",
                _variant(H_of=lambda Hp, Hm: np.column_stack([Hm, np.zeros(2)])),
                "H = ∂h/∂pose (its second output)."),
        Mistake(f"{name} does not wrap the bearing innovation: a beacon predicted just below "
                "+π and seen just above −π is 0.007 rad off, not almost 2π.",
                _variant(nu_of=lambda nu: nu), "Wrap ν_β = z_β − ẑ_β into (−π, π] before "
                "using it."),
        Mistake(f"{name} leaves the heading unwrapped after the update: φ + (K ν)_φ can step "
                "over ±π, and the pose's heading must stay in (−π, π].",
                _variant(wrap_heading=False)),
        Mistake(f"{name} has the innovation's sign reversed: the correction K ν must move the "
                "prediction TOWARDS the measurement.",
                _variant(nu_of=lambda nu: -np.array([nu[0], wrap_pi(nu[1])])), "ν = z − ẑ."),
        Mistake(f"{name} leaves the laser's noise out of the innovation covariance: the gain "
                "then trusts the sighting as if the laser had no noise.",
                _variant(R_used=False), "S = H P Hᵀ + R."),
    ]
    check_function(fn, _reference, cases, name=name, arg_names=_U_ARGS, labels=_LABELS,
                   angles=[2], mistakes=mistakes, output=_flat,
                   what="localisation.beacon_update", quiet=True, rtol=1e-6, atol=1e-9)
    P0 = np.diag([0.04, 0.04, 0.001])
    bad = [((np.array([3.0, 4.0, 0.2]), P0, np.array([1.0, 0.5]), np.array([3.0, 4.0]),
             np.diag([0.01, 3e-4])), "the beacon is at the sensor's position: range 0 has no "
            "bearing, and observation.observe raises ValueError; let it, or raise your own")]
    for args, why in bad:
        check_raises(fn, args, name=name, why=why, arg_names=_U_ARGS)
    return passed(f"✓ {name} agrees with localisation.beacon_update on {len(cases)} sightings "
                  f"(across the bearing seam, the heading crossing ±π, random poses).", quiet)



# ----------------------------------------------------------------------------- 4a.3 verdict

_V_ARGS = ("nis", "dof", "p")


def _verdict_cases(seed: int, n: int) -> list[tuple]:
    """Runs of 1 to 300 updates with 2 or 4 dof each (mixed), whose average NIS per dof
    sits inside, just inside, just outside and far outside the band on either side, for
    p = 0.9, 0.95, 0.99; then ``n`` seeded random ones."""
    rng = np.random.default_rng(seed)
    cases = []
    for m in (1, 5, 40, 300):
        dof = rng.choice([2.0, 4.0], size=m)
        D = dof.sum()
        for p in (0.9, 0.95, 0.99):
            lo, hi = chi2_ppf((1 - p) / 2, D) / D, chi2_ppf((1 + p) / 2, D) / D
            for target in (0.5 * lo, 0.98 * lo, 1.02 * lo, 0.5 * (lo + hi), 0.98 * hi, 1.02 * hi, 2 * hi):
                w = rng.uniform(0.5, 1.5, m)
                nis = w / w.sum() * target * D                   # average NIS/dof = target
                cases.append((nis, dof.copy(), p))
    for _ in range(n):
        m = int(rng.integers(1, 200))
        dof = rng.choice([1.0, 2.0, 3.0, 4.0], size=m)
        nis = rng.chisquare(dof) * rng.choice([0.3, 1.0, 1.0, 3.0])
        cases.append((nis, dof, float(rng.choice([0.9, 0.95, 0.99]))))
    return cases


def _verdict_of(avg, lo, hi):
    return localisation.VERDICTS[0] if avg < lo else localisation.VERDICTS[2] if avg > hi \
        else localisation.VERDICTS[1]


def _verdict_mistakes(name: str) -> list[Mistake]:
    def one_sided(nis, dof, p):
        D = float(np.sum(dof))
        return _verdict_of(np.sum(nis) / D, -math.inf, chi2_ppf(p, D) / D)

    def same_q(nis, dof, p):                 # both bounds from p: chi2.ppf(1 - p), chi2.ppf(p)
        D = float(np.sum(dof))
        return _verdict_of(np.sum(nis) / D, chi2_ppf(1 - p, D) / D, chi2_ppf(p, D) / D)

    def per_update(nis, dof, p):             # the band of ONE update, not of the average
        d = float(np.mean(dof))
        return _verdict_of(np.sum(nis) / np.sum(dof), chi2_ppf((1 - p) / 2, d) / d,
                           chi2_ppf((1 + p) / 2, d) / d)

    def count_not_dof(nis, dof, p):          # D = number of updates
        D = float(len(nis))
        return _verdict_of(np.sum(nis) / np.sum(dof), chi2_ppf((1 - p) / 2, D) / D,
                           chi2_ppf((1 + p) / 2, D) / D)

    def not_per_dof(nis, dof, p):            # the mean NIS against a band per dof
        D = float(np.sum(dof))
        return _verdict_of(np.mean(nis), chi2_ppf((1 - p) / 2, D) / D, chi2_ppf((1 + p) / 2, D) / D)

    def swapped(nis, dof, p):
        v = localisation.nis_verdict(nis, dof, p)[0]
        return {"too small": "too large", "too large": "too small"}.get(v, v)

    return [
        Mistake(f"{name} checks only the upper side: an average NIS far BELOW its band is a "
                "finding too (the filter's S is too large: R or Q over-stated, as on the Car "
                "Park).", one_sided, "Use the two-sided band chi2.ppf((1 ∓ p)/2, D) / D."),
        Mistake(f"{name}'s band holds 2p − 1 of the averages, not p: a two-sided band of "
                "probability p leaves (1 − p)/2 on each side.", same_q,
                "chi2.ppf((1 − p)/2, D) and chi2.ppf((1 + p)/2, D), not chi2.ppf(1 − p, D) "
                "and chi2.ppf(p, D)."),
        Mistake(f"{name} judges the average with the band of a SINGLE update: the sum of the "
                "run's NIS is chi-square with the SUMMED dof D, and its band per dof narrows "
                "as D grows.", per_update),
        Mistake(f"{name} counts updates, not degrees of freedom: D is the sum of the dof "
                "(each range-bearing sighting adds 2).", count_not_dof),
        Mistake(f"{name} compares the mean NIS per update with a band per dof.", not_per_dof,
                "Divide the summed NIS by the summed dof."),
        Mistake(f"{name} has 'too small' and 'too large' swapped: the verdict names the "
                "average NIS, 'too small' when it lies below the band.", swapped),
    ]


@forbids(localisation.nis_verdict)
def check_nis_verdict(fn, *, seed: int = 0, n: int = 40, name: str = "my_nis_verdict",
                      quiet: bool = False) -> str:
    """Grade ``fn(nis, dof, p) -> 'too small' | 'consistent' | 'too large'``, chapter 04a
    eq. 4a.4: the average NIS per dof against the two-sided chi-square band of the summed
    dof. Reference: ``localisation.nis_verdict``.

    Catches a one-sided test, the band of probability 2p − 1, the band of one update,
    updates counted instead of dof, the mean NIS not divided by the dof, the verdicts
    swapped.
    """
    cases = _verdict_cases(seed, n)
    prefetch(fn, cases)
    got = []
    for c in cases:
        out = call(fn, c, name=name, arg_names=_V_ARGS)
        if not isinstance(out, str) or out not in localisation.VERDICTS:
            fail(f"{name}({describe(c, _V_ARGS)}) returned {out!r:.60}; it should return one of "
                 f"{', '.join(repr(v) for v in localisation.VERDICTS)}.")
        got.append(out)
    exp = [localisation.nis_verdict(*c)[0] for c in cases]
    if got != exp:
        for m in _verdict_mistakes(name):
            if [m.wrong(*c) for c in cases] == got:
                fail(m.text)
        k = next(i for i in range(len(cases)) if got[i] != exp[i])
        _, avg, lo, hi = localisation.nis_verdict(*cases[k])
        fail(f"{name}({describe(cases[k], _V_ARGS)}) returned {got[k]!r}, expected {exp[k]!r}: "
             f"the average NIS per dof is {avg:.4g}, its {100 * cases[k][2]:.0f} % band "
             f"[{lo:.4g}, {hi:.4g}]. {sum(g != e for g, e in zip(got, exp))} of {len(cases)} "
             f"verdicts differ.")
    return passed(f"✓ {name} agrees with localisation.nis_verdict on {len(cases)} runs of 1 to "
                  f"300 updates.", quiet)
