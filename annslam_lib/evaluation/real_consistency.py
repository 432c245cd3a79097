"""Consistency on a real run, where there is no truth: the map against the survey, and
where the innovation covariance comes from (notebook 05 "the Car Park run").

- :func:`survey_nees`: the map as a whole against the surveyed beacons. The errors of a
  SLAM map share its frame (one common shift and rotation), so counting beacons inside
  their marginal 2-sigma ellipses counts correlated events; the joint NEES
  e^T (P_mm + Sigma_survey)^-1 e of all matched landmarks, with their joint covariance
  and the survey's own uncertainty, is chi-square with 2 K dof for a consistent filter.
- :func:`innovation_split`: every update's innovation nu and its covariance
  S = H P H^T + R, per sensor (laser range and bearing, GPS east and north), split into the
  part the filter predicts from its own uncertainty (H P H^T) and the sensor's (R), on
  straights and in turns. A NIS far below 1 says S is too wide; this says which part is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from .._cache import memoize as _memoize
from ..models.geometry import wrap_angle
from ..models.uncertainty import mahalanobis2
from .consistency import MapConsistency, map_consistency

__all__ = ["survey_nees", "InnovationSplit", "innovation_split"]


def survey_nees(result, surveyed, mapped_index, surveyed_index, *,
                sigma_survey: float = 0.02) -> MapConsistency:
    """Joint NEES of the mapped landmarks ``result.landmarks[mapped_index]`` against the
    surveyed points ``surveyed[surveyed_index]`` (pairs, e.g. ``map_errors``' i_mapped and
    j_true), with the joint covariance of those landmarks from ``result.covariance`` plus
    ``sigma_survey``^2 per axis (independent survey errors), judged against chi-square with
    2 K dof (``consistency.map_consistency``). Notebook 05.

    Parameters
    ----------
    result : slam.results.SlamResult
        A run, with its final ``landmarks`` (M, 2) and ``covariance``.
    surveyed : array_like, shape (T, 2)
        The surveyed points, m.
    mapped_index : array_like of int, shape (K,)
        The mapped landmarks of the pairs.
    surveyed_index : array_like of int, shape (K,)
        Their surveyed partners.
    sigma_survey : float, optional
        Standard deviation of the survey per axis, m.

    Returns
    -------
    MapConsistency
        The joint NEES per dof (2 K dof) with its band.

    Raises
    ------
    ValueError
        For no pairs, unequal index arrays, an index out of range or used twice, or a
        covariance that does not match the map.
    """
    surveyed = _checks.points("surveyed", surveyed)
    i = np.asarray(mapped_index, dtype=np.int64).ravel()
    j = np.asarray(surveyed_index, dtype=np.int64).ravel()
    if i.size == 0 or i.size != j.size:
        raise ValueError(f"mapped_index and surveyed_index must pair K >= 1 landmarks, got {i.size} "
                         f"and {j.size}")
    n_lm = result.landmarks.shape[0]
    if i.min() < 0 or i.max() >= n_lm or j.min() < 0 or j.max() >= surveyed.shape[0]:
        raise ValueError("mapped_index or surveyed_index out of range")
    if np.unique(i).size != i.size or np.unique(j).size != j.size:
        raise ValueError("a landmark or a surveyed point is paired twice")
    sigma = _checks.real("sigma_survey", sigma_survey, lo=0.0)
    P = np.asarray(result.covariance, dtype=float)
    if P.shape != (3 + 2 * n_lm,) * 2:
        raise ValueError(f"result.covariance must be {(3 + 2 * n_lm,) * 2}, got {P.shape}")
    idx = np.ravel(np.c_[3 + 2 * i, 4 + 2 * i])
    C = P[np.ix_(idx, idx)] + sigma**2 * np.eye(idx.size)
    e = (np.asarray(result.landmarks, dtype=float)[i] - surveyed[j]).ravel()
    return map_consistency([float(mahalanobis2(e[None], np.zeros(e.size), C)[0])], [e.size])


@dataclass(frozen=True)
class InnovationSplit:
    """Per-observation innovations of a run and the two parts of their covariance
    (:func:`innovation_split`).

    sensor (m,): 'laser' or 'gps'; t (m,): time (s); turning (m,): |steering| above the
    threshold at that time; nu (m, 2): innovation (range m, bearing rad; or east, north m);
    hph (m, 2): the diagonal of H P H^T; r (m, 2): the diagonal of R; nis (m,): each
    observation's nu^T S^-1 nu with its own 2 x 2 S."""

    sensor: np.ndarray
    t: np.ndarray
    turning: np.ndarray
    nu: np.ndarray
    hph: np.ndarray
    r: np.ndarray
    nis: np.ndarray

    def rows(self):
        """(sensor, component, where, n, innovation RMS, sqrt(mean H P H^T),
        sqrt(mean R), share of R in S, NIS / dof) for every sensor, component and
        stretch (straight, turning, all)."""
        out = []
        names = {"laser": ("range", "bearing"), "gps": ("east", "north")}
        for sensor in ("laser", "gps"):
            for where, sel in (("straight", ~self.turning), ("turning", self.turning),
                               ("all", np.ones_like(self.turning))):
                m = (self.sensor == sensor) & sel
                if not m.any():
                    continue
                for c, comp in enumerate(names[sensor]):
                    hph, r = self.hph[m, c].mean(), self.r[m, c].mean()
                    out.append((sensor, comp, where, int(m.sum()),
                                float(np.sqrt(np.mean(self.nu[m, c] ** 2))), float(np.sqrt(hph)),
                                float(np.sqrt(r)), float(r / (hph + r)),
                                float(self.nis[m].sum() / (2 * m.sum()))))
        return out


@_memoize
def innovation_split(dataset, config=None, *, turning_steer: float = 0.05) -> InnovationSplit:
    """Run the filter (``slam.runner.run`` with ``config``) on ``dataset`` and record, at
    every laser and GPS update, each observation's innovation and the diagonals of
    H P H^T and R, before the update; ``turning`` where the odometry's |steering| exceeds
    ``turning_steer`` rad. The run itself is unchanged. Notebooks 05 and 06; computed once per
    machine (``annslam_lib._cache``).

    Parameters
    ----------
    dataset : records.Dataset
        The run's data.
    config : SlamConfig, optional
        As ``slam.runner.run``.
    turning_steer : float, optional
        |steering| above which the car counts as turning, rad.

    Returns
    -------
    InnovationSplit
        Per observation (m of them): sensor, time, turning, innovation (m, 2) and the
        diagonals of H P H^T and R (m, 2), and its NIS.

    Raises
    ------
    TypeError
        If ``dataset`` is not a records.Dataset.
    ValueError
        As ``slam.runner.run``, or for a negative ``turning_steer``.
    """
    from ..data.records import Dataset
    from ..slam.runner import run

    _checks.instance("dataset", dataset, Dataset)
    thr = _checks.real("turning_steer", turning_steer, lo=0.0)
    rows = []

    def record(filt):
        update, gps_update = filt.update, filt.gps_update

        def laser(z, lm, sr, sb):
            filt.flush()
            zhat, S = filt.observation_model(sr, sb)
            lm_idx = np.asarray(lm, dtype=np.int64).ravel()
            z = np.asarray(z, dtype=float)
            nu = np.c_[z[:, 0] - zhat[lm_idx, 0], wrap_angle(z[:, 1] - zhat[lm_idx, 1])]
            Rd = np.array([sr**2, sb**2])
            Sk = S[lm_idx]
            nis = np.einsum("ki,ki->k", nu, np.linalg.solve(Sk, nu[..., None])[..., 0])
            rows.extend(("laser", nu[k], np.diagonal(Sk[k]) - Rd, Rd, float(nis[k]))
                        for k in range(lm_idx.size))
            return update(z, lm, sr, sb)

        def gps(xy, sigma, gate=math.inf):
            filt.flush()
            x, P = filt.state()                           # the filter's own arrays: copy
            nu = np.asarray(xy, dtype=float) - x[:2]
            Rd = np.full(2, sigma**2)
            prior = P[:2, :2].copy()                      # before the update changes P in place
            S = prior + np.diag(Rd)
            out = gps_update(xy, sigma, gate)
            if out[1]:                                    # accepted fixes only
                rows.append(("gps", nu, np.diag(prior), Rd, float(nu @ np.linalg.solve(S, nu))))
            return out

        filt.update, filt.gps_update = laser, gps

    result = run(dataset, config, progress=False, inspect=record)
    # the k-th laser update is the k-th laser NIS row, with dof / 2 observations; the GPS
    # rows are the accepted fixes, in time order
    nis = result.nis
    laser = nis["kind"] == 0
    t_laser = iter(np.repeat(nis["t"][laser], (nis["dof"][laser] // 2).astype(np.int64)))
    t_gps = iter(nis["t"][(nis["kind"] == 1) & nis["accepted"].astype(bool)])
    t = np.array([next(t_laser) if r[0] == "laser" else next(t_gps) for r in rows])
    if next(t_laser, None) is not None or next(t_gps, None) is not None:
        raise RuntimeError("innovation_split: the recorded updates do not match the run's")
    steer = np.abs(np.interp(t, dataset.odometry.t, dataset.odometry.steering))
    return InnovationSplit(sensor=np.array([r[0] for r in rows]), t=t, turning=steer > thr,
                           nu=np.array([r[1] for r in rows]), hph=np.array([r[2] for r in rows]),
                           r=np.array([r[3] for r in rows]), nis=np.array([r[4] for r in rows]))
