"""Checks for the graded exercises of notebook 04 (gating and data association).

``check_innovation_d2``: the squared Mahalanobis distance of one innovation, with the
bearing difference wrapped, S = H P H^T + R, and a ValueError for an S that is not positive
definite. ``check_in_gate``: the chi-square gate decision. ``check_associate``: greedy
nearest-neighbour association with mutual exclusion on a d2 matrix, graded on crafted
scenes whose failure messages say which measurement went to which landmark and why that
is wrong. References: :mod:`annslam_lib.perception.association`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2
from scipy.stats._distn_infrastructure import rv_continuous

from ..perception.association import GATE, NEW, NEW_LANDMARK, REJECTED, associate, gate_threshold, mahalanobis
from ..models.observation import observe
from .core import (forbids, Mistake, Passed, call, check_function, check_raises, describe, fail, fmt,
                   prefetch, wrap_pi)
from .kalman import chi2_ppf

__all__ = ["check_innovation_d2", "check_in_gate", "check_associate"]

_D2_ARGS = ("z", "zhat", "H", "P", "R")


# ----------------------------------------------------------------------------- 4.1 d2

def _S(H, P, R):
    S = H @ P @ H.T + R
    return 0.5 * (S + S.T)


def _d2_reference(z, zhat, H, P, R) -> float:
    return float(mahalanobis(np.asarray(z)[None], np.asarray(zhat)[None], _S(H, P, R)[None])[0, 0])


def _random_P(rng) -> np.ndarray:
    """A 5 x 5 covariance of (x, y, phi, x_i, y_i): pose ~0.3 m / 3 deg, landmark ~0.3 m,
    correlated (random square root), so S has a range-bearing correlation."""
    scale = np.array([0.3, 0.3, math.radians(3.0), 0.3, 0.3]) * rng.uniform(0.3, 2.0)
    A = rng.normal(size=(5, 5)) * scale[:, None]
    return A @ A.T / 5


def _d2_case(pose, landmark, P, R, nu_or_z, *, absolute=False):
    zhat, Hp, Hm = observe(pose, landmark)
    H = np.concatenate([Hp, Hm], axis=1)
    z = np.asarray(nu_or_z, float) if absolute else zhat + np.asarray(nu_or_z, float)
    z = np.array([z[0], wrap_pi(z[1])])
    return (z, zhat, H, P, R)


def _d2_cases(seed: int, n: int) -> list[tuple]:
    """Seam cases (predicted bearing just below +pi, measured just above -pi, and the
    reverse), a strongly correlated S, then ``n`` seeded random cases with innovations
    drawn from 0.5 to 4 times S."""
    R0 = np.diag([0.1**2, math.radians(1.0) ** 2])
    P0 = np.diag([0.2**2, 0.2**2, math.radians(2.0) ** 2, 0.1**2, 0.1**2])
    left = math.pi / 2 - 0.004            # world direction of a landmark at bearing pi - 0.004
    right = math.pi / 2 + 0.004           # ... at bearing -pi + 0.004 (just past the seam)
    cases = [_d2_case(np.zeros(3), 10 * np.array([math.cos(left), math.sin(left)]), P0, R0,
                      [10.05, -math.pi + 0.006], absolute=True),
             _d2_case(np.zeros(3), 12 * np.array([math.cos(right), math.sin(right)]), P0, R0,
                      [11.9, math.pi - 0.003], absolute=True),
             _d2_case(np.array([1.0, 2.0, 2.5]), np.array([-6.0, 9.0]), P0, R0, [0.3, -0.02])]
    Pc = P0.copy()
    Pc[0, 2] = Pc[2, 0] = 0.8 * math.sqrt(P0[0, 0] * P0[2, 2])   # position-heading correlation
    cases.append(_d2_case(np.array([0.0, 0.0, 0.3]), np.array([6.0, 4.0]), Pc, R0, [0.2, 0.03]))
    rng = np.random.default_rng(seed)
    for _ in range(n):
        pose = np.r_[rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi)]
        a, r = rng.uniform(-np.pi, np.pi), rng.uniform(2, 40)
        lm = pose[:2] + r * np.array([math.cos(a), math.sin(a)])
        P = _random_P(rng)
        R = np.diag([rng.uniform(0.05, 0.2), math.radians(rng.uniform(0.5, 2.0))]) ** 2
        zhat, Hp, Hm = observe(pose, lm)
        H = np.concatenate([Hp, Hm], axis=1)
        nu = rng.multivariate_normal(np.zeros(2), _S(H, P, R)) * rng.choice([0.5, 1, 2, 4])
        cases.append(_d2_case(pose, lm, P, R, nu))
    return cases


def _quadratic(f):
    """A wrong d2 built as nu' f(S, R) nu with the right (wrapped) innovation."""
    def wrong(z, zhat, H, P, R):
        nu = np.array([z[0] - zhat[0], wrap_pi(z[1] - zhat[1])])
        return float(nu @ f(_S(H, P, R), H @ P @ H.T, R) @ nu)
    return wrong


def _unwrapped(z, zhat, H, P, R):
    nu = np.asarray(z) - np.asarray(zhat)
    return float(nu @ np.linalg.inv(_S(H, P, R)) @ nu)


def _singular_cases():
    """(args, why) that must raise ValueError: S not positive definite."""
    lm = np.array([8.0, 3.0])
    zhat, Hp, Hm = observe(np.zeros(3), lm)
    H = np.concatenate([Hp, Hm], axis=1)
    z = zhat + np.array([0.1, 0.02])
    Z5, Z2 = np.zeros((5, 5)), np.zeros((2, 2))
    v = np.array([0.31, -0.17, 0.013, 0.07, 0.05])   # rank-1 P: S singular up to rounding
    return [
        ((z, zhat, H, Z5, Z2), "S = H P H^T + R = 0 (P = 0 and R = 0): a measurement that "
         "cannot vary has no Mahalanobis distance"),
        ((z, zhat, H, np.outer(v, v), Z2), "S = H P H^T + R has rank 1 here (P = v v^T: "
         "uncertain along one direction only, R = 0). It is singular up to rounding (its "
         "determinant is ~1e-20, not exactly 0), so S^-1 is rounding noise; test that S is "
         "positive definite, e.g. its smallest eigenvalue (np.linalg.eigvalsh) against 1e-12 "
         "times its largest"),
        ((z, zhat, H, Z5, np.diag([0.01, -1e-4])), "S has a negative variance (R[1, 1] < 0): "
         "it is indefinite, so d2 could be negative"),
        ((z, zhat, H, Z5, -np.diag([0.01, 1e-4])), "S is negative definite (R = -diag(...)): "
         "no covariance"),
    ]


@forbids(mahalanobis)
def check_innovation_d2(fn, *, seed: int = 0, n: int = 40,
                        name: str = "my_innovation_d2", quiet: bool = False) -> str:
    """Grade ``fn(z, zhat, H, P, R) -> d2``, the gating statistic of notebook 04 section 9:
    nu = z − zhat with the bearing difference wrapped to (−pi, pi], S = H P H^T + R,
    d2 = nu^T S^-1 nu; and ``fn`` must raise ValueError when S is not positive definite
    (singular, indefinite, negative). Reference: ``association.mahalanobis``.

    Catches an unwrapped bearing innovation, S instead of S^-1, R instead of S, S without
    R, only the diagonal of S, the distance instead of its square.
    """
    cases = _d2_cases(seed, n)
    mistakes = [
        Mistake(f"{name} does not wrap the bearing innovation: at a landmark predicted just "
                "below +π and seen just above −π (or the reverse) the bearings differ by "
                "almost 2π, but the innovation is the small angle between them.", _unwrapped,
                "Wrap ν_β = z_β − ẑ_β into (−π, π] before the quadratic form, e.g. "
                "(a + np.pi) % (2 * np.pi) - np.pi."),
        Mistake(f"{name} weighs the innovation with S itself: the statistic then grows with "
                "the uncertainty instead of shrinking. Look again at which matrix the "
                "Mahalanobis distance uses (section 9).",
                _quadratic(lambda S, HPH, R: S),
                "d2 = νᵀ S⁻¹ ν (np.linalg.solve(S, ν) or np.linalg.inv(S))."),
        Mistake(f"{name} uses the laser's noise R alone as the innovation's covariance: the "
                "innovation is also uncertain because the pose and the landmark are, and with "
                "R alone a vague prediction looks wrong.",
                _quadratic(lambda S, HPH, R: np.linalg.inv(R)), "S = H P H^T + R."),
        Mistake(f"{name} leaves the measurement noise out of the innovation's covariance.",
                _quadratic(lambda S, HPH, R: np.linalg.inv(HPH)), "S = H P H^T + R."),
        Mistake(f"{name} divides each innovation component by its own variance, using only "
                "the diagonal of S: the range and bearing innovations are correlated "
                "(S[0, 1] ≠ 0).", _quadratic(lambda S, HPH, R: np.diag(1 / np.diag(S))),
                "d2 = νᵀ S⁻¹ ν needs the full inverse."),
        Mistake(f"{name} returns the Mahalanobis distance, not its square: the gate compares "
                "the squared distance (chi-square distributed).",
                lambda *a: math.sqrt(_d2_reference(*a))),
    ]
    check_function(fn, _d2_reference, cases, name=name, arg_names=_D2_ARGS, mistakes=mistakes,
                   what="association.mahalanobis", quiet=True)
    bad = _singular_cases()
    for args, why in bad:
        check_raises(fn, args, name=name, why=why, arg_names=_D2_ARGS)
    ok = (f"✓ {name} agrees with association.mahalanobis on {len(cases)} inputs and raises "
          f"ValueError for all {len(bad)} S that are not positive definite.")
    if not quiet:
        print(ok)
    return Passed(ok)


# ----------------------------------------------------------------------------- 4.2 gate

_PROBS = (0.5, 0.9, 0.95, 0.99, 0.999, 0.9999)


def _gate_cases(seed: int, n: int) -> list[tuple]:
    """(d2, prob): around each threshold, the 1-dof / 2-dof gap (6.63..9.21 at 99 %),
    just above and below 9 ('3 sigma'), 0 and +inf, then ``n`` seeded random pairs;
    none within 1e-6 (relative) of its threshold."""
    cases = [(9.1, 0.99), (9.3, 0.99), (7.0, 0.99), (6.0, 0.99), (0.0, 0.99),
             (math.inf, 0.99), (3.5, 0.95), (5.5, 0.9), (4.0, 0.9), (12.0, 0.999),
             (15.0, 0.9999), (1.0, 0.5), (1.5, 0.5)]
    for p in _PROBS:
        t = chi2_ppf(p, 2)
        cases += [(f * t, p) for f in (0.5, 0.97, 1.03, 2.0)]
    rng = np.random.default_rng(seed)
    cases += [(float(rng.uniform(0, 25)), float(rng.choice(_PROBS))) for _ in range(n)]
    return [(d, p) for d, p in cases
            if not math.isfinite(d) or abs(d - chi2_ppf(p, 2)) > 1e-6 * chi2_ppf(p, 2)]


#: The gate of exercise 4.2 (what the answers of its mistakes give away).
_GATE = "−2 ln(1 − prob) = chi2.ppf(prob, 2)"


def _gate_mistakes(name: str) -> list[Mistake]:
    t99 = chi2_ppf(0.99, 2)
    return [
        Mistake(f"{name} uses the threshold of a chi-square with 1 degree of freedom: how many "
                "components has the innovation, and what does that make the distribution of "
                "d2?", lambda d, p: d <= chi2_ppf(p, 1),
                f"The gate is d2 <= {_GATE} ({t99:.2f} at 99 %, not {chi2_ppf(0.99, 1):.2f})."),
        Mistake(f"{name} uses the threshold that only the share 1 − prob of the true "
                "measurements stay below; the gate lets through the share prob. Check which "
                "side of the disc your probability is.", lambda d, p: d <= chi2_ppf(1 - p, 2),
                "P(d2 <= t) = 1 − exp(−t/2), so the gate is d2 <= −2 ln(1 − prob), "
                "not −2 ln(prob)."),
        Mistake(f"{name} compares √d2 with the threshold: the threshold is for the SQUARED "
                "distance.", lambda d, p: math.sqrt(d) <= chi2_ppf(p, 2),
                f"Compare d2 itself with {_GATE}."),
        Mistake(f"{name} compares d2 with the square root of the threshold: d2 is already "
                "squared.", lambda d, p: d <= math.sqrt(chi2_ppf(p, 2)),
                f"Compare it with {_GATE} itself."),
        Mistake(f"{name} uses d2 <= 9, the one-dimensional '3σ' rule. In two dimensions the "
                "3σ ellipse holds only 98.9 %; the gate must follow prob.",
                lambda d, p: d <= 9.0, f"The gate is d2 <= {_GATE}."),
        Mistake(f"{name} ignores prob (it always uses the 99 % threshold {t99:.2f}): the "
                "threshold must follow the argument.", lambda d, p: d <= t99,
                f"The gate is d2 <= {_GATE}."),
        Mistake(f"{name} is inverted: it must return True when the measurement is INSIDE the "
                "gate, i.e. when it may come from the landmark.", lambda d, p: d > chi2_ppf(p, 2),
                f"Inside means d2 <= {_GATE}."),
    ]


def _as_bool(out, name: str, where: str) -> bool:
    if isinstance(out, (bool, np.bool_)):
        return bool(out)
    if isinstance(out, (int, float, np.integer, np.floating)) and out in (0, 1):
        return bool(out)
    if isinstance(out, np.ndarray) and out.size == 1 and out.dtype == bool:
        return bool(out.ravel()[0])
    fail(f"{name}({where}) returned {out!r:.60}; it should return True (inside the gate) or "
         f"False.")


@forbids(gate_threshold, rv_continuous.ppf, rv_continuous.isf)
def check_in_gate(fn, *, seed: int = 0, n: int = 40, name: str = "my_in_gate",
                  quiet: bool = False) -> str:
    """Grade ``fn(d2, prob) -> bool``, the chi-square gate of notebook 04 section 9: True iff
    d2 <= chi2.ppf(prob, 2) (the innovation has 2 degrees of freedom). Reference:
    ``association.gate_threshold``.

    Catches 1 dof, chi2.ppf(1 − prob) = −2 ln(prob), √d2 or √threshold, the fixed 9 ('3σ')
    or 9.21 (prob ignored), an inverted decision.
    """
    cases = _gate_cases(seed, n)
    names = ("d2", "prob")
    prefetch(fn, cases)
    got = [_as_bool(call(fn, c, name=name, arg_names=names), name, describe(c, names))
           for c in cases]
    exp = [c[0] <= chi2_ppf(c[1], 2) for c in cases]
    if got != exp:
        for m in _gate_mistakes(name):
            if [bool(m.wrong(*c)) for c in cases] == got:
                fail(m.text)
        bad = [k for k in range(len(cases)) if got[k] != exp[k]]
        d, p = cases[bad[0]]
        t = chi2_ppf(p, 2)
        fail(Mistake(f"{name} decides wrongly at {len(bad)} of {len(cases)} inputs. First: "
                     f"{name}(d2={fmt(d)}, prob={p}) returned {got[bad[0]]}, but the "
                     f"measurement is {'inside (True)' if exp[bad[0]] else 'outside (False)'} "
                     f"the {100 * p:g} % gate.", None,
                     f"The gate is d2 <= {_GATE} = {t:.4g} here.").text)
    ok = f"✓ {name} agrees with the chi-square gate on {len(cases)} inputs."
    if not quiet:
        print(ok)
    return Passed(ok)


# ----------------------------------------------------------------------------- 4.3 associate

def _assign_scenes() -> list[tuple[str, np.ndarray, float, float]]:
    """Crafted (title, d2, gate, new_landmark): every rule of the association, and the
    orders in which a plausible wrong algorithm breaks it."""
    inf = math.inf
    G, N = GATE, NEW_LANDMARK
    return [
        ("one measurement per gate", np.array([[0.8, 40.0], [30.0, 2.5], [50.0, 60.0]]), G, N),
        ("nearest in d2, not the first landmark in the gate",
         np.array([[6.0, 1.5, 30.0]]), G, N),
        ("two measurements, one landmark", np.array([[3.0, 50.0], [1.2, 50.0]]), G, N),
        ("the loser takes its second choice", np.array([[1.0, 5.0], [0.5, 40.0]]), G, N),
        ("pairs in increasing d2 over the whole matrix, not measurement by measurement",
         np.array([[2.0, 4.0, 50.0], [1.0, 50.0, 50.0], [50.0, 3.0, 8.0]]), G, N),
        ("between the gate and the new-landmark threshold", np.array([[12.0, 40.0]]), G, N),
        ("beyond the new-landmark threshold of every landmark",
         np.array([[24.0, 30.0], [35.0, 23.5]]), G, N),
        ("near one landmark, far from the other", np.array([[40.0, 15.0]]), G, N),
        ("an empty map", np.zeros((3, 0)), G, N),
        ("no measurements", np.zeros((0, 4)), G, N),
        ("+inf: landmarks not worth testing", np.array([[inf, 2.0], [inf, inf]]), G, N),
        ("greedy, not the optimal assignment", np.array([[1.0, 2.0], [2.0, 8.0]]), G, N),
        ("a 99.9 % gate (use the gate argument)", np.array([[12.0, 40.0]]),
         float(chi2.ppf(0.999, 2)), N),
        ("a higher new-landmark threshold (use the argument)", np.array([[24.0, 33.0]]), G,
         float(chi2.ppf(1 - 1e-7, 2))),
    ]


def _random_scenes(seed: int, n: int):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        nz, nl = int(rng.integers(1, 7)), int(rng.integers(1, 7))
        d2 = rng.exponential(rng.uniform(4, 20), (nz, nl))
        g = float(chi2.ppf(rng.choice([0.9, 0.99, 0.999]), 2))
        out.append((f"random scene {k}", d2, g, max(g, NEW_LANDMARK)))
    return out


def _code(a: int) -> str:
    return {NEW: "NEW (-1)", REJECTED: "REJECTED (-2)"}.get(int(a), f"landmark {int(a)}")


def _explain(i: int, got: np.ndarray, exp: np.ndarray, d2: np.ndarray, gate: float,
             new: float) -> str:
    """Why measurement i's assignment got[i] is wrong (the reference says exp[i])."""
    g, e = int(got[i]), int(exp[i])
    row = d2[i]
    if g >= 0 and not row[g] <= gate:
        return (f"z{i} was given landmark {g}, but its d2 = {fmt(row[g])} is outside the gate "
                f"(d2 <= {gate:.4g}): only landmarks inside the gate are candidates.")
    if g >= 0:
        others = [k for k in range(len(got)) if k != i and got[k] == g]
        if others:
            k = others[0]
            return (f"landmark {g} received both z{k} and z{i}: mutual exclusion, a landmark "
                    f"receives at most one measurement per scan (two measurements of one scan "
                    f"cannot be the same pole). The pair with the smaller d2 keeps it "
                    f"(z{k}: {fmt(d2[k, g])}, z{i}: {fmt(row[g])}).")
        owner = [k for k in range(len(exp)) if exp[k] == g]
        if owner:
            k = owner[0]
            tail = (f"z{i} then takes landmark {e} (d2 {fmt(row[e])}), the nearest one still "
                    f"free in its gate." if e >= 0 else
                    f"z{i} has no other free landmark in its gate, so it is REJECTED (-2).")
            return (f"z{i} was given landmark {g} (d2 {fmt(row[g])}), but landmark {g} belongs "
                    f"to z{k}, whose d2 {fmt(d2[k, g])} is the smaller one: take the pairs "
                    f"(measurement, landmark) inside the gates in increasing d2 over the whole "
                    f"matrix, accepting a pair when both are still free. {tail}")
        if e >= 0:
            return (f"z{i} was given landmark {g} (d2 {fmt(row[g])}), but landmark {e} is "
                    f"nearer in Mahalanobis distance (d2 {fmt(row[e])}) and free: take the "
                    f"pairs in increasing d2, accepting a pair when both are still free "
                    f"(greedy nearest neighbour, not an optimal assignment).")
    if e >= 0:
        owner = [k for k in range(len(got)) if k != i and got[k] == e]
        if owner:
            k = owner[0]
            return (f"z{i} should get landmark {e} (d2 {fmt(row[e])}), but it went to z{k} "
                    f"(d2 {fmt(d2[k, e])}), which is farther from it: pairs are taken in "
                    f"increasing d2 over the whole matrix, so the nearer pair wins.")
        return (f"z{i} is inside the gate of landmark {e} (d2 {fmt(row[e])} <= {gate:.4g}) and "
                f"no nearer measurement claims that landmark: assign it, not "
                f"{_code(g)}.")
    nearest = float(np.min(row)) if row.size else math.inf
    if e == NEW:
        return (f"z{i} is beyond the new-landmark threshold from every landmark (smallest d2 "
                f"{fmt(nearest)} > {new:.4g}): it is a NEW landmark (-1), not {_code(g)}.")
    # e == REJECTED
    if g == NEW:
        return (f"z{i} is not far enough from every landmark to be new (smallest d2 "
                f"{fmt(nearest)} <= {new:.4g}, the new-landmark threshold): REJECTED (-2), so "
                f"that a poorly predicted old landmark does not become a duplicate.")
    return f"z{i} should be REJECTED (-2), not {_code(g)}."


@forbids(associate)
def check_associate(fn, *, seed: int = 0, n: int = 40, name: str = "my_associate",
                    quiet: bool = False) -> str:
    """Grade ``fn(d2, gate, new_landmark) -> assign`` (n,), the data association of notebook
    04 section 9: pairs (i, j) with d2[i, j] <= gate taken greedily in increasing d2, each
    accepted when measurement i and landmark j are both still free (nearest neighbour with
    mutual exclusion); the others NEW (-1) if d2 > new_landmark for every landmark (all
    NEW for an empty map), else REJECTED (-2). Reference: ``association.associate``.

    Crafted scenes come first: a failure names the scene, the measurement, the landmark it
    got and should get, with the d2 values that decide it.
    """
    scenes = _assign_scenes() + _random_scenes(seed, n)
    prefetch(fn, [(d2, gate, new) for _, d2, gate, new in scenes])
    for title, d2, gate, new in scenes:
        args = (d2.copy(), gate, new)
        out = call(fn, args, name=name, arg_names=("d2", "gate", "new_landmark"))
        exp = associate(d2, gate=gate, new_landmark=new)
        try:
            got = np.asarray(out, dtype=float).reshape(-1) if np.size(out) else np.zeros(0)
        except (TypeError, ValueError):
            fail(f"{name} returned {out!r:.80} for the scene '{title}'; expected an array of "
                 f"{d2.shape[0]} integers")
        if got.shape != exp.shape:
            fail(f"{name} returned {got.size} values for the scene '{title}' (d2 of shape "
                 f"{d2.shape}); expected one per measurement, {exp.size}.")
        if not np.all(np.isfinite(got) & (got == np.round(got))):
            fail(f"{name} returned {fmt(got)} for the scene '{title}': the assignment holds "
                 f"integers (a landmark index, NEW = -1 or REJECTED = -2).")
        got = got.astype(int)
        if np.any((got < REJECTED) | (got >= d2.shape[1])):
            fail(f"{name} returned {got.tolist()} for the scene '{title}' with "
                 f"{d2.shape[1]} landmarks: each entry must be a landmark index "
                 f"0..{d2.shape[1] - 1}, NEW (-1) or REJECTED (-2).")
        if not np.array_equal(got, exp):
            i = int(np.flatnonzero(got != exp)[0])
            fail(f"{name} is wrong on the scene '{title}': d2 = {fmt(d2)} (rows: measurements "
                 f"z0, z1, ...; columns: landmarks), gate {gate:.4g}, new_landmark {new:.4g}. "
                 f"Expected {exp.tolist()}, got {got.tolist()}. "
                 + _explain(i, got, exp, d2, gate, new))
    ok = f"✓ {name} agrees with association.associate on {len(scenes)} scenes."
    if not quiet:
        print(ok)
    return Passed(ok)
