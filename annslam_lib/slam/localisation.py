"""EKF localisation on a known map (chapter 04a, "EKF localisation").

The whole-run filter is the course's EKF-SLAM run with ``SlamConfig.map_mode = 'known'``:
the surveyed landmarks sit in the state from the start with zero covariance, so every
gain's map rows are zero and the filter only localises (:func:`localise`). This module
adds what the chapter derives and grades: one beacon update written out for a pose-only
state (:func:`beacon_update`), the consistency verdict of a run's NIS
(:func:`nis_verdict`), and a dataset with another map (:func:`with_beacons`, for the
"what happens if the map is wrong" experiments).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.stats import chi2

from .. import _checks
from ..data.records import Dataset
from ..models.geometry import wrap_angle
from ..models.observation import observe
from .config import SlamConfig
from .dense import innovation
from .kalman import joseph_covariance, kalman_gain

__all__ = ["beacon_update", "nis_verdict", "with_beacons", "localise", "VERDICTS"]

#: What :func:`nis_verdict` can say.
VERDICTS = ("too small", "consistent", "too large")


def beacon_update(pose, P, z, beacon, R) -> tuple[np.ndarray, np.ndarray, dict]:
    """One EKF localisation update (chapter 04a, eq. 4a.1-4a.3) of the laser pose
    (x, y, phi) with covariance P (3, 3) by a sighting z = (range, laser bearing) of a
    beacon at the known position ``beacon`` (2,), noise covariance R (2, 2):

        zhat, H = h(pose, beacon), dh/dpose      (chapter 03; the map is known: no dh/dm)
        nu = z - zhat (bearing wrapped), S = H P H^T + R, K = P H^T S^-1
        pose+ = pose + K nu (heading wrapped),  P+ = (I - K H) P (I - K H)^T + K R K^T

    Parameters
    ----------
    pose : array_like, shape (3,)
        Laser pose (x, y, phi) (m, m, rad).
    P : array_like, shape (3, 3)
        Its covariance.
    z : array_like, shape (2,)
        The sighting (range, laser bearing) (m, rad), range > 0.
    beacon : array_like, shape (2,)
        The beacon's known position, m.
    R : array_like, shape (2, 2)
        Noise covariance of z.

    Returns
    -------
    pose_new : ndarray, shape (3,)
        pose+, heading wrapped to (-pi, pi].
    P_new : ndarray, shape (3, 3)
        P+ (Joseph form).
    info : dict
        ``zhat`` (2,), ``nu`` (2,), ``S`` (2, 2), ``K`` (3, 2) and ``d2`` = nu^T S^-1 nu.

    Raises
    ------
    ValueError
        For bad shapes, a beacon at the sensor, or an S that is not positive definite.
    """
    pose = _checks.array("pose", pose, (3,))
    if pose.ndim != 1:
        raise ValueError(f"pose must be one (x, y, phi), got shape {pose.shape}")
    P = _checks.covariance("P", P, 3)
    z = _checks.array("z", z, (2,))
    if z.ndim != 1 or z[0] <= 0:
        raise ValueError(f"z must be one (range > 0, bearing), got {z!r}")
    beacon = _checks.array("beacon", beacon, (2,))
    if beacon.ndim != 1:
        raise ValueError(f"beacon must be one (x, y), got shape {beacon.shape}")
    R = _checks.covariance("R", R, 2)
    zhat, Hp, _ = observe(pose, beacon)
    nu = innovation(z, zhat)
    K, S = kalman_gain(P, Hp, R)
    new = pose + K @ nu
    new[2] = float(wrap_angle(new[2]))
    return new, joseph_covariance(P, Hp, R, K), {
        "zhat": zhat, "nu": nu, "S": S, "K": K, "d2": float(nu @ np.linalg.solve(S, nu))}


def nis_verdict(nis, dof, p: float = 0.95) -> tuple[str, float, float, float]:
    """Judge a run's innovations (chapter 04a, eq. 4a.4): if the filter's S is right and the
    innovations are independent, the summed NIS is chi-square with the summed dof, so the
    average NIS per dof lies in [chi2.ppf((1-p)/2, D), chi2.ppf((1+p)/2, D)] / D with
    probability p (D = sum of dof). Returns (verdict, average, lo, hi); the verdict is
    'too small' (the filter's S is too large: R or Q over-stated), 'consistent' or 'too
    large' (S too small, or wrong associations). Innovations of a real run are correlated
    in time, so the band is then too narrow: a verdict outside it is a prompt to look,
    not a proof.

    Parameters
    ----------
    nis : array_like, shape (U,)
        The NIS of each update, >= 0.
    dof : array_like, shape (U,)
        The degrees of freedom of each (the innovation's size), > 0.
    p : float, optional
        Probability of the band, in (0, 1).

    Returns
    -------
    verdict : str
        'too small', 'consistent' or 'too large' (:data:`VERDICTS`).
    average : float
        The summed NIS over the summed dof.
    lo, hi : float
        The band of the average.

    Raises
    ------
    ValueError
        For empty or unequal ``nis`` and ``dof``, a negative NIS, dof <= 0 or ``p``
        outside (0, 1).
    """
    nis = _checks.array("nis", nis).ravel()
    dof = _checks.array("dof", dof).ravel()
    if nis.size == 0 or nis.shape != dof.shape:
        raise ValueError(f"nis and dof must be non-empty and of one length, got {nis.size} "
                         f"and {dof.size}")
    if np.any(nis < 0) or np.any(dof <= 0):
        raise ValueError("NIS values must be >= 0 and dof > 0")
    p = _checks.probability("p", p)
    D = float(dof.sum())
    avg = float(nis.sum() / D)
    lo, hi = (float(chi2.ppf(q, D) / D) for q in ((1 - p) / 2, (1 + p) / 2))
    verdict = VERDICTS[0] if avg < lo else VERDICTS[2] if avg > hi else VERDICTS[1]
    return verdict, avg, lo, hi


def with_beacons(dataset: Dataset, beacons) -> Dataset:
    """``dataset`` with another known map (a beacon moved, one missing): the map the
    filter of :func:`localise` is given, not the truth it is scored against."""
    _checks.instance("dataset", dataset, Dataset, "records.Dataset")
    b = _checks.points("beacons", beacons)
    return dataclasses.replace(dataset, beacons=b)


def localise(dataset: Dataset, config: SlamConfig | None = None, **changes):
    """EKF localisation of ``dataset`` on its known map: :func:`runner.run` with
    ``map_mode='known'`` (the dataset's default configuration, or ``config``, with
    ``changes``).

    Parameters
    ----------
    dataset : records.Dataset
        A run with a surveyed map (``dataset.beacons``).
    config : SlamConfig, optional
        None: ``SlamConfig.for_dataset(dataset.name)`` for a known name, else
        ``SlamConfig()``.
    **changes
        Fields of :class:`SlamConfig` to change.

    Returns
    -------
    SlamResult
        The run's result (:func:`runner.run`).

    Raises
    ------
    ValueError
        For an unknown field in ``changes`` or a dataset without a surveyed map.
    """
    from ..data import filter_default_names
    from .runner import run

    if config is None:
        config = (SlamConfig.for_dataset(dataset.name) if dataset.name in filter_default_names()
                  else SlamConfig())
    return run(dataset, config.replace(map_mode="known", **changes), progress=False)
