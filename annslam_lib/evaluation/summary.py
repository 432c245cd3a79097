"""One summary of a filter run: :func:`run_metrics` -> :class:`RunMetrics` (notebooks 05, 06,
08; ``python -m annslam_lib reproduce``).

Every table of the course that describes a run (the Car Park metrics of chapter 05, the
SLAM explorer's readout, the verdict's configurations, the R-scale sweep) takes its numbers
from here, so one definition of each number exists:

- trajectory: RMSE of the filtered path at the odometry rate against the GPS fixes inside
  its span (``evaluation.trajectory``), over the whole run and after ``t_heldout``, and
  over the whole run after the best SE(2) alignment (the frame error removed);
- pose uncertainty: the mean trace of the laser POSITION covariance, P_xx + P_yy (m^2),
  after each scan's update (a trace over x, y and phi would add m^2 to rad^2);
- consistency: total laser NIS over its degrees of freedom (1 for a consistent filter);
- map (where a surveyed map exists): matched, missed and spurious landmarks within
  ``max_distance`` AS MAPPED (a count that depends on the map's frame), and the RMSE
  absolute and after the best rigid alignment with duplicates, matched in the best frame
  (``evaluation.map.map_errors``, align first), and over a set of held-out beacons.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .. import _checks
from ..data.records import Dataset
from .map import MapErrors, map_errors, match_landmarks, point_rmse
from .trajectory import trajectory_errors

__all__ = ["METRICS", "RunMetrics", "run_metrics", "pose_trace", "nis_per_dof",
           "heldout_map_rmse"]

#: The metrics of the results tables: key -> description (units).
METRICS = {
    "map_rmse": "map RMSE vs surveyed beacons, absolute (m)",
    "map_rmse_aligned": "map RMSE after the best rigid alignment (m)",
    "map_rmse_heldout": "map RMSE over the held-out beacons (m)",
    "map_rmse_heldout_aligned": "map RMSE over the held-out beacons, whole map aligned (m)",
    "traj_rmse": "trajectory RMSE vs GPS, whole run (m)",
    "traj_rmse_aligned": "trajectory RMSE vs GPS after the best SE(2) alignment, whole run (m)",
    "traj_rmse_heldout": "trajectory RMSE vs GPS, held-out time (m)",
    "pose_trace": "mean pose covariance trace P_xx + P_yy, whole run (m^2)",
    "pose_trace_heldout": "mean pose covariance trace, held-out time (m^2)",
    "landmarks": "landmarks in the final map",
    "matched": "landmarks matched to a surveyed beacon (1 m)",
    "unmatched": "landmarks without a surveyed beacon (spurious, or simply not surveyed)",
}


@dataclass(frozen=True)
class RunMetrics:
    """The numbers of one run (module docstring); NaN (counts: -1) where not measurable:
    no GPS fix inside the run, no surveyed map, no held-out window or beacons given."""

    scans: int
    landmarks: int
    rejected: int
    traj_rmse: float
    traj_rmse_heldout: float
    traj_rmse_aligned: float
    pose_trace: float
    pose_trace_heldout: float
    nis_per_dof: float
    map_rmse: float = math.nan
    map_rmse_aligned: float = math.nan
    map_rmse_heldout: float = math.nan
    map_rmse_heldout_aligned: float = math.nan
    matched: int = -1
    missed: int = -1
    spurious: int = -1
    duplicates: int = -1
    map_errors: MapErrors | None = field(default=None, repr=False)

    @property
    def unmatched(self) -> int:
        return self.spurious

    def as_dict(self) -> dict:
        """The metrics as a dict (map_errors left out), with ``unmatched``."""
        d = {k: v for k, v in asdict(self).items() if k != "map_errors"}
        d["unmatched"] = self.unmatched
        return d

    def line(self) -> str:
        """One or two lines for a readout."""
        text = (f"{self.scans} scans, {self.landmarks} landmarks, {self.rejected} observations "
                f"rejected, NIS/dof {self.nis_per_dof:.3f}, path RMSE vs GPS "
                f"{self.traj_rmse:.3f} m")
        if self.matched >= 0:
            text += (f"\nmap: {self.matched} beacons matched, {self.missed} not (yet) mapped, "
                     f"{self.spurious} spurious ({self.duplicates} duplicates); RMSE "
                     f"{self.map_rmse:.3f} m absolute, {self.map_rmse_aligned:.3f} m aligned")
        return text


def pose_trace(result) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), P_xx + P_yy (K,)) of the laser position after every scan's update (m^2)."""
    P = np.asarray(result.pose_cov)
    return np.asarray(result.trajectory[:, 0]), P[:, 0, 0] + P[:, 1, 1]


def nis_per_dof(result) -> float:
    """Total laser-update NIS over its total degrees of freedom (GPS updates left out);
    NaN without any laser update."""
    k = result.nis["kind"] == 0
    dof = float(np.sum(result.nis["dof"][k]))
    return float(np.sum(result.nis["nis"][k]) / dof) if dof > 0 else math.nan


def heldout_map_rmse(result, beacons, held_out, max_distance: float = 1.0, *,
                     aligned: bool = False) -> float:
    """Map RMSE (m) over the surveyed beacons ``held_out`` (indices into ``beacons``) that
    the map matches; NaN if none is. Absolute: matched as mapped
    (``evaluation.map.match_landmarks``). ``aligned``: the pairs and the frame of
    ``evaluation.map.map_errors`` (the WHOLE map aligned onto the survey first; NaN when it
    cannot be aligned)."""
    if aligned:
        try:
            m = map_errors(result.landmarks, beacons, max_distance=max_distance)
        except ValueError:
            return math.nan
        return _heldout_aligned(m, held_out)
    i, j = match_landmarks(result.landmarks, beacons, max_distance)
    sel = np.isin(j, np.asarray(held_out))
    if not sel.any():
        return math.nan
    return point_rmse(result.landmarks[i[sel]], beacons[j[sel]])


def _heldout_aligned(m: MapErrors | None, held_out) -> float:
    """RMSE over the held-out beacons of an aligned map's errors (NaN: none, or no map)."""
    if m is None:
        return math.nan
    sel = np.isin(m.j_true, np.asarray(held_out))
    return float(np.sqrt(np.mean(m.error_aligned[sel] ** 2))) if sel.any() else math.nan


def trajectory_rmse(traj, gps) -> tuple[float, float]:
    """(absolute, SE(2)-aligned) RMSE against the fixes in the span; NaN without any."""
    if traj.shape[0] == 0:
        return math.nan, math.nan
    inside = (gps.t >= traj[0, 0]) & (gps.t <= traj[-1, 0])
    if not np.any(inside):
        return math.nan, math.nan
    e = trajectory_errors(traj, gps)
    return e.rmse, e.rmse_aligned


def run_metrics(result, dataset: Dataset, *, t_heldout: float | None = None,
                held_out_beacons=None, max_distance: float = 1.0) -> RunMetrics:
    """The :class:`RunMetrics` of one filter run on ``dataset`` (module docstring).

    Parameters
    ----------
    result : slam.results.SlamResult
        The run.
    dataset : records.Dataset
        The data it ran on (its GPS and, if any, its surveyed beacons).
    t_heldout : float, optional
        Start of the held-out time, s; None: no held-out time.
    held_out_beacons : array_like of int, optional
        Indices of held-out surveyed beacons; None: none.
    max_distance : float, optional
        Largest distance of a landmark match, m.

    Returns
    -------
    RunMetrics
        The run's numbers; NaN (counts: -1) where not measurable.

    Raises
    ------
    TypeError
        If ``dataset`` is not a records.Dataset.
    """
    _checks.instance("dataset", dataset, Dataset, "records.Dataset")
    t, tr = pose_trace(result)
    odo = result.odometry_trajectory
    held = {}
    if t_heldout is not None:
        late = t >= t_heldout
        held = dict(pose_trace_heldout=float(tr[late].mean()) if late.any() else math.nan,
                    traj_rmse_heldout=trajectory_rmse(odo[odo[:, 0] >= t_heldout], dataset.gps)[0])
    c = result.counts
    whole = trajectory_rmse(odo, dataset.gps)
    out = dict(scans=int(c["scans"]), landmarks=int(result.landmarks.shape[0]),
               rejected=int(c["rejected"]), traj_rmse=whole[0], traj_rmse_aligned=whole[1],
               traj_rmse_heldout=held.get("traj_rmse_heldout", math.nan),
               pose_trace=float(tr.mean()) if tr.size else math.nan,
               pose_trace_heldout=held.get("pose_trace_heldout", math.nan),
               nis_per_dof=nis_per_dof(result))
    if dataset.beacons is not None:
        i, _ = match_landmarks(result.landmarks, dataset.beacons, max_distance)
        n_map, n_true = int(result.landmarks.shape[0]), len(dataset.beacons)
        out.update(matched=int(i.size), missed=n_true - int(i.size), spurious=n_map - int(i.size),
                   duplicates=0)
        m = None
        if n_map >= 2:
            try:                           # aligned first: a map in a wrong frame is scored too
                m = map_errors(result.landmarks, dataset.beacons, max_distance=max_distance)
            except ValueError:             # nothing matches in any frame: the map RMSE stays NaN
                m = None
            if m is not None:
                out.update(map_errors=m, duplicates=m.duplicates, map_rmse=m.rmse,
                           map_rmse_aligned=m.rmse_aligned)
        if held_out_beacons is not None:
            out["map_rmse_heldout"] = heldout_map_rmse(result, dataset.beacons, held_out_beacons,
                                                       max_distance)
            out["map_rmse_heldout_aligned"] = _heldout_aligned(m, held_out_beacons)
    return RunMetrics(**out)
