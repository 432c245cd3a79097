"""A particle filter for the car: Monte-Carlo localisation (MCL) on a known map.

The belief is N particles (poses) with weights instead of one Gaussian. Each step:

1. **predict**: every particle moves by the course's motion model
   (:func:`~annslam_lib.models.motion.predict`) with its own draw of the control noise
   (v_c, alpha) ~ N(control, Q);
2. **weigh**: a sighting z = (range, bearing) of a landmark at a known position multiplies
   each particle's weight by the likelihood N(z; h(particle), R) (:func:`weigh`), kept as
   logarithms and normalised by log-sum-exp, so a thousand small likelihoods do not
   underflow to zero;
3. **resample** when the effective sample size 1 / sum w^2 (:func:`effective_sample_size`)
   falls below a share of N: systematic resampling (:func:`systematic_resample`), one
   random offset and N evenly spaced pointers, so particle i is copied floor(N w_i) or
   ceil(N w_i) times.

If every weight vanishes, the filter does not carry on with made-up weights. In
logarithms no weight underflows, so "vanished" is said of the fit: a sighting whose
Mahalanobis distance d^2 = nu^T R^-1 nu exceeds the chi-square gate of probability 1e-9
(:data:`DEPLETION_GATE`, 41.4 for two dimensions) for EVERY particle fits none of them (in
plain numbers its weights would all be below e^-20 of a perfect fit), and so does a weight
that is not a number: :func:`mcl_step` raises :class:`ParticleDepletion` saying so, or
recovers by keeping the weights it had before that sighting (``on_depletion="skip"``),
counting each such sighting.
"""
from __future__ import annotations

import numpy as np

from scipy.stats import chi2

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.motion import predict
from ..models.observation import observe
from ..models.vehicle import Vehicle

__all__ = ["DEPLETION_GATE", "ParticleDepletion", "effective_sample_size", "systematic_resample", "normalise",
           "move", "weigh", "mcl_step", "estimate"]


#: d^2 beyond which a sighting fits no particle (chi-square, 2 dof, probability 1e-9).
DEPLETION_GATE = float(chi2.ppf(1.0 - 1e-9, 2))


class ParticleDepletion(RuntimeError):
    """Every particle's weight vanished: the sighting fits none of them."""


def effective_sample_size(weights) -> float:
    """1 / sum w^2 of normalised weights: N for equal weights, 1 when one particle holds
    them all."""
    w = _checks.array("weights", weights)
    if w.ndim != 1 or w.size == 0 or np.any(w < 0) or not abs(w.sum() - 1.0) < 1e-9:
        raise ValueError("weights must be a non-empty 1-D array of non-negative numbers "
                         "summing to 1")
    return float(1.0 / np.sum(w * w))


def systematic_resample(weights, rng: np.random.Generator) -> np.ndarray:
    """Indices of the particles kept (N,): pointers (u + k) / N, k = 0..N-1, one uniform u
    in [0, 1), placed on the cumulative weights."""
    effective_sample_size(weights)                       # checks them
    w = np.asarray(weights, float)
    n = w.size
    c = np.cumsum(w)
    c[-1] = 1.0                                          # no pointer past the end
    return np.searchsorted(c, (rng.random() + np.arange(n)) / n, side="right")


def normalise(log_weights) -> np.ndarray:
    """Weights from their logarithms, by log-sum-exp (the largest becomes exp(0)).

    Raises
    ------
    ParticleDepletion
        If every log weight is -inf (all likelihoods zero) or any is NaN.
    """
    lw = np.asarray(log_weights, float)
    if lw.ndim != 1 or lw.size == 0:
        raise ValueError("log_weights must be a non-empty 1-D array")
    if np.any(np.isnan(lw)) or not np.any(np.isfinite(lw)):
        raise ParticleDepletion(f"all {lw.size} particle weights vanished (no particle fits "
                                "the sighting, or a weight is not a number)")
    w = np.exp(lw - lw[np.isfinite(lw)].max())
    return w / w.sum()


def move(particles, control, dt, vehicle: Vehicle, Q, rng: np.random.Generator) -> np.ndarray:
    """Step 1: every particle (N, 3) moved by the motion model with its own control drawn
    from N(control, Q) (2, 2)."""
    p = _checks.array("particles", particles, (3,))
    if p.ndim != 2:
        raise ValueError(f"particles must have shape (N, 3), got {p.shape}")
    u = _checks.array("control", control, (2,))
    draws = rng.multivariate_normal(u.reshape(2), _checks.array("Q", Q, (2, 2)), p.shape[0])
    return predict(p, draws, dt, vehicle)[0]


def weigh(particles, log_weights, z, landmark, R) -> tuple[np.ndarray, np.ndarray]:
    """Step 2: log weights plus each particle's log-likelihood of the sighting ``z``
    (range, bearing) of ``landmark`` (2,), N(z; h(particle), R), the bearing's difference
    wrapped; and each particle's d^2 = nu^T R^-1 nu."""
    p = _checks.array("particles", particles, (3,))
    z = _checks.array("z", z, (2,)).reshape(2)
    R = _checks.array("R", R, (2, 2))
    zhat = observe(p, np.broadcast_to(_checks.array("landmark", landmark, (2,)).reshape(2),
                                      (p.shape[0], 2)))[0]
    nu = np.stack([z[0] - zhat[:, 0], wrap_angle(z[1] - zhat[:, 1])], -1)
    Ri = np.linalg.inv(R)
    d2 = np.einsum("ni,ij,nj->n", nu, Ri, nu)
    _, logdet = np.linalg.slogdet(2 * np.pi * R)
    return np.asarray(log_weights, float) - 0.5 * (d2 + logdet), d2


def estimate(particles, weights) -> tuple[np.ndarray, np.ndarray]:
    """The weighted mean pose (heading averaged on the circle) and covariance (3, 3)."""
    p = np.asarray(particles, float)
    w = np.asarray(weights, float)
    m = w @ p
    m[2] = np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))
    d = p - m
    d[:, 2] = wrap_angle(d[:, 2])
    return m, (d * w[:, None]).T @ d


def mcl_step(particles, weights, control, dt, vehicle: Vehicle, Q, sightings, R,
             rng: np.random.Generator, *, resample_below: float = 0.5,
             on_depletion: str = "raise") -> tuple[np.ndarray, np.ndarray, dict]:
    """One MCL step (module docstring): move, weigh by each (z, landmark) of ``sightings``,
    resample when the effective sample size is below ``resample_below`` N. Returns
    (particles, weights, info) with info's ``ess``, ``resampled`` and ``skipped`` (the
    sightings that fitted no particle, with ``on_depletion="skip"``; with ``"raise"`` they
    raise :class:`ParticleDepletion`)."""
    if on_depletion not in ("raise", "skip"):
        raise ValueError(f"on_depletion must be 'raise' or 'skip', got {on_depletion!r}")
    p = move(particles, control, dt, vehicle, Q, rng)
    lw = np.log(np.asarray(weights, float))
    skipped = 0
    for z, landmark in sightings:
        new, d2 = weigh(p, lw, z, landmark, R)
        if not np.nanmin(d2, initial=np.inf) <= DEPLETION_GATE or np.any(np.isnan(new)):
            if on_depletion == "raise":
                raise ParticleDepletion(
                    f"the sighting z = {np.asarray(z).tolist()} fits none of the "
                    f"{p.shape[0]} particles (smallest d^2 {np.nanmin(d2, initial=np.inf):.3g} > "
                    f"{DEPLETION_GATE:.1f}): every weight vanished")
            skipped += 1
            continue
        lw = new
    w = normalise(lw)
    ess = effective_sample_size(w)
    resampled = ess < resample_below * w.size
    if resampled:
        p = p[systematic_resample(w, rng)]
        w = np.full(w.size, 1.0 / w.size)
    return p, w, {"ess": ess, "resampled": bool(resampled), "skipped": skipped}
