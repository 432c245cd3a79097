"""The EKF-SLAM run over a whole dataset: :func:`run` (notebook 05; notebook 06 for
Victoria Park).

A scan (:func:`run`)
    predict to its time; gate every detection against every landmark at once
    (:meth:`EkfSlam.observation_model`: predicted measurements and innovation
    covariances elementwise over the landmarks; chi-square gate, nearest neighbour with
    mutual exclusion as ``association.associate``); one batch update with all associated
    detections; then the new landmarks join the state, as TENTATIVE ones if
    ``landmark_min_observations`` > 1 (deleted again unless seen often enough soon).

Initial pose (``SlamConfig.initial_pose``)
    Not hand-tuned: on real runs the position is the first GPS fix and the heading the
    least-squares fit of the first seconds of dead reckoning to the GPS track
    (``slam.dead_reckoning.initial_pose_from_gps``; Car Park: -127 deg, where the original
    program's hand value was about -112 deg). The fit looks ahead ``initial_window``
    seconds, a batch step before the filter starts; with gps_mode 'init' those fixes are
    then also used as updates (counted twice, a mild optimism about the start).

ANN landmark model (``SlamConfig.landmark_model = 'ann'``, ``run(..., landmark_model=m)``;
notebook 08, ``annslam_lib.ann``)
    The paper feeds the network's landmark position to the filter at initialisation and
    in the update. The network's output l_ann is computed FROM the detection z (and the
    prior pose), so it is not a second, independent measurement: using z and l_ann
    together would count the same measurement twice. Here l_ann REPLACES z, expressed as
    the range-bearing pseudo-measurement z' = h(prior pose, l_ann) (``model.
    pseudo_measurement``, computed right after the prediction to the scan time, the pose
    the network was trained on), with the model's own noise (``model.sigmas``: RMS
    residuals on validation data) instead of (sigma_range, sigma_bearing). Then the rest
    is unchanged: gating and the update use z'; a new landmark is g(prior pose, z') =
    l_ann, with P_ll = J_pose P_vv J_pose^T + J_z R' J_z^T, the inverse model's Jacobians
    at z' (the correction's own dependence on the pose is neglected, as the network's input
    pose is the prior, not a state the update may move). A model with zero correction and
    R' = R reproduces the plain filter to rounding (tests/test_ann.py).
"""
from __future__ import annotations

import dataclasses
import math
import sys
import time

import numpy as np

from .._cache import memoize
from ..data import filter_default_names
from ..data.records import Dataset, Detections
from ..data.screening import Screening, screen
from ..models.uncertainty import chi2_quantile
from ..models.motion import control_table
from ..perception.association import NEW, REJECTED, associate_fast
from ..perception.jcbb import search_checked
from .base import FilterBackend, LandmarkModel
from .config import SlamConfig
from . import compiled, stretches
from .results import STATUS, ObservationLog, SlamResult, landmark_history, nis_arrays
from .efficient import diag_blocks
from .threads import one_blas_thread

__all__ = ["run", "run_cached", "prepare", "Prepared", "Events", "event_schedule",
           "initial_pose", "initial_covariance", "source_detections"]


def _resolve_dataset(dataset) -> Dataset:
    if isinstance(dataset, str):
        from ..data import loaders as datasets
        if dataset not in ("car_park", "victoria_park"):
            raise ValueError(f"unknown dataset {dataset!r}: pass 'car_park', 'victoria_park' or "
                             "a records.Dataset (e.g. from simulate.simulate())")
        return datasets.load(dataset)
    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be a records.Dataset or a dataset name, got "
                         f"{type(dataset).__name__}")
    return dataset



def source_detections(dataset: Dataset, source: str) -> Detections:
    """The detections the filter would use on ``dataset`` for ``SlamConfig.feature_source``
    ``source`` (``perception.sources.detections_for``), before any laser calibration."""
    from ..perception import sources          # beacon extraction, only when needed
    return sources.detections_for(dataset, source=source)


def initial_pose(dataset: Dataset, config: SlamConfig) -> tuple[np.ndarray, dict]:
    """The filter's start pose under ``config.initial_pose`` (module docstring, "Initial
    pose"; chapter 05).

    Parameters
    ----------
    dataset : records.Dataset
    config : SlamConfig
        ``initial_pose``: 'auto' (the truth on a simulated run, else 'gps'), 'truth',
        'gps' (first fix and the heading fitted over ``initial_window`` seconds) or a pose.

    Returns
    -------
    pose : ndarray (3,)
        (x, y, phi) of the laser.
    info : dict
        ``policy`` and, for 'gps', the fit's ``fixes``, ``travel``, ``rms`` and ``window``.
    """
    policy = config.initial_pose
    if policy == "auto":
        policy = "truth" if dataset.truth is not None else "gps"
    if policy == "truth":
        if dataset.truth is None:
            raise ValueError("SlamConfig.initial_pose = 'truth' needs a simulated dataset "
                             "(dataset.truth is None)")
        return np.array(dataset.truth.poses[0, 1:4], dtype=float), {"policy": "truth"}
    if policy == "gps":
        from .dead_reckoning import initial_pose_from_gps
        try:
            fit = initial_pose_from_gps(dataset.odometry, dataset.gps, dataset.vehicle,
                                        window=config.initial_window)
        except ValueError as e:
            raise ValueError(f"initial pose from GPS failed ({e}); pass "
                             "SlamConfig.initial_pose = (x, y, phi)") from e
        return fit.pose.copy(), {"policy": "gps", "fixes": fit.fixes, "travel": fit.travel,
                                 "rms": fit.rms, "window": fit.window}
    return np.array(policy, dtype=float), {"policy": "given"}


def initial_covariance(config: SlamConfig) -> np.ndarray:
    """The start pose's covariance, diag(sigma_xy^2, sigma_xy^2, sigma_phi^2) from
    ``config.initial_sigma_xy`` and ``initial_sigma_phi`` (chapter 05), (3, 3)."""
    s_xy, s_phi = config.initial_sigma_xy, config.initial_sigma_phi
    return np.diag([s_xy**2, s_xy**2, s_phi**2])


@dataclasses.dataclass(frozen=True)
class Events:
    """The GPS fixes and scans of a run in the order the filter meets them (lists, one
    entry per event): time ``t``, ``code`` (0 a GPS fix, 2 a scan), ``index`` (the fix's
    or scan's own index) and ``odometry_before`` (how many odometry samples come before
    it: those earlier, and at equal time those before a scan but after a fix)."""
    t: list
    code: list
    index: list
    odometry_before: list

    def __iter__(self):
        return iter((self.t, self.code, self.index, self.odometry_before))


def event_schedule(odo_t, gps_t, scan_t) -> Events:
    """The GPS fixes (code 0) and scans (code 2) in time order (ties: GPS first, as in the
    Car Park file's own event list), with the odometry samples before each
    (:class:`Events`). The run loop, the factor graph and the capstone share it."""
    t = np.concatenate([gps_t, scan_t])
    code = np.concatenate([np.zeros(gps_t.size, np.int64), np.full(scan_t.size, 2, np.int64)])
    idx = np.concatenate([np.arange(gps_t.size), np.arange(scan_t.size)])
    order = np.lexsort((code, t))
    t, code, idx = t[order], code[order], idx[order]
    k_end = np.where(code == 2, np.searchsorted(odo_t, t, side="right"),
                     np.searchsorted(odo_t, t, side="left"))
    return Events(t.tolist(), code.tolist(), idx.tolist(), k_end.tolist())


@dataclasses.dataclass(frozen=True)
class Prepared:
    """What a run starts from (:func:`prepare`): the screened dataset and what screening
    repaired, the configuration, the detections (laser calibration applied), the start pose
    with its covariance and how it was found, and the event schedule."""
    dataset: Dataset
    screening: Screening
    config: SlamConfig
    detections: Detections
    pose0: np.ndarray
    cov0: np.ndarray
    initial_info: dict
    events: Events


def prepare(dataset, config: SlamConfig | None = None) -> Prepared:
    """Everything a run needs before its first step (chapter 05; the factor graph of
    chapter 10 and the capstone start from the same).

    Parameters
    ----------
    dataset : records.Dataset or str
        A loaded or simulated dataset, or 'car_park' / 'victoria_park'.
    config : SlamConfig, optional
        None: ``SlamConfig.for_dataset(dataset.name)`` for a known name, else ``SlamConfig()``.

    Returns
    -------
    Prepared
        Damaged streams repaired and counted (``data.screening.screen``), detections of
        ``config.feature_source`` minus ``range_bias`` and ``bearing_offset``, the start
        pose (:func:`initial_pose`) and covariance (:func:`initial_covariance`), and the
        events in time order (:func:`event_schedule`).

    Raises ValueError for a configuration the dataset cannot serve (truth association
    without true ids, no odometry).
    """
    ds, screening = screen(_resolve_dataset(dataset))     # damaged streams: repaired, counted
    if config is None:
        config = SlamConfig.for_dataset(ds.name) if ds.name in filter_default_names() else SlamConfig()
    if not isinstance(config, SlamConfig):
        raise TypeError(f"config must be a SlamConfig, got {type(config).__name__}")
    cfg = config
    det = source_detections(ds, cfg.feature_source)
    if cfg.range_bias or cfg.bearing_offset:    # a calibration of the laser (SlamConfig)
        det = dataclasses.replace(det, range=det.range - cfg.range_bias,
                                  bearing=det.bearing - cfg.bearing_offset)
    if cfg.association == "truth" and np.any(det.landmark_id < 0):
        raise ValueError("SlamConfig.association = 'truth' needs detections with true "
                         "landmark ids (a simulated dataset)")
    if len(ds.odometry) < 1:
        raise ValueError("the dataset has no odometry")
    pose0, info = initial_pose(ds, cfg)
    return Prepared(ds, screening, cfg, det, pose0, initial_covariance(cfg), info,
                    event_schedule(ds.odometry.t, ds.gps.t, det.t))


def _progress(progress, total):
    if progress is None:
        progress = total > 20000 and sys.stderr.isatty()
    if not progress:
        return None
    from tqdm.auto import tqdm
    return tqdm(total=total, desc="EKF-SLAM", unit="event", mininterval=0.5)



def run(dataset, config: SlamConfig | None = None, *, progress=None,
        backend: str = "efficient", landmark_model=None, inspect=None,
        gating: str = "auto") -> SlamResult:
    """Run EKF-SLAM over a whole dataset (notebook 05; notebook 06 for Victoria Park).

    Events are processed in time order from the first odometry sample on (earlier scans
    and fixes are skipped and counted); the filter predicts to every event's time with
    the control of the last odometry sample. A scan: predict, gate and associate all its
    detections at once, one batch update with the associated ones, then add the new
    landmarks, then the tentative-landmark rule. BLAS runs on one thread meanwhile
    (:func:`one_blas_thread`).

    Parameters
    ----------
    dataset : records.Dataset or str
        A loaded or simulated dataset, or 'car_park' / 'victoria_park'.
    config : SlamConfig, optional
        None -> ``SlamConfig.for_dataset(dataset.name)`` for a known name, else
        ``SlamConfig()``.
    progress : bool or None, optional
        A tqdm bar; None = only for long runs with a terminal.
    backend : {'efficient', 'dense', 'ukf'}, optional
        'efficient' (:class:`EkfSlam`), 'dense' (the textbook reference
        ``slam.dense.DenseEkfSlam``; slow, for checks) or 'ukf' (the same state filtered
        by the unscented transform, ``slam.unscented.ukf_backend``; slow).
    landmark_model : object, optional
        With ``config.landmark_model = 'ann'``, the trained model (``ann.TrainedModel``,
        ``ann.InverseModel`` or anything with ``pseudo_measurement(pose, z, intensity,
        width)`` and ``sigmas``): its pseudo-measurements replace the detections (module
        docstring). The log keeps the detections, not the pseudo-measurements (after the
        configuration's calibration, ``SlamConfig.range_bias`` and ``bearing_offset``,
        if any).
    inspect : callable, optional
        Called with the filter once it is built, before any step (an analysis may wrap
        its methods to record what they see, e.g. ``evaluation.real_consistency``). The
        loop calls ``innovation_d2``, ``joint_prediction`` (JCBB), ``update``,
        ``augment``, ``remove``, ``gps_update``, ``health`` and the read access on either
        backend; to predict, ``predict_stretch`` on the efficient one (``slam.stretches``:
        the odometry between two events compounded beforehand) and ``predict`` step by
        step on the dense one.
    gating : {'auto', 'numpy', 'compiled'}, optional
        Efficient backend only: 'numpy' (``EkfSlam.innovation_d2`` as chapter 05 derives
        it), 'compiled' (the same formulas as one compiled loop, ``slam.compiled``; an
        error if numba is missing) or 'auto' (compiled for runs of at least
        ``slam.compiled.MIN_SCANS`` scans when available, else numpy); ``result.gating``
        says which ran.

    Returns
    -------
    SlamResult
        The trajectory after every scan, the map with its covariances, the NIS of every
        update, the counts, the covariance health and the per-detection log.

    Raises
    ------
    TypeError
        If ``dataset`` or ``config`` has the wrong type.
    ValueError
        For an unknown dataset name, backend or gating, a configuration the dataset or
        the backend cannot serve, or a landmark model that does not match the
        configuration.
    """
    if gating not in ("auto", "numpy", "compiled"):
        raise ValueError(f"gating must be 'auto', 'numpy' or 'compiled', got {gating!r}")
    with one_blas_thread():
        return _run(dataset, config, progress, backend, landmark_model, inspect, gating)


@memoize
def run_cached(dataset, config: SlamConfig | None = None, *,
               backend: str = "efficient") -> SlamResult:
    """:func:`run` (no progress bar, no landmark model), computed once per machine and then
    read back from the study cache (``annslam_lib._cache``): for the long runs a notebook
    compares, whose running time is not the lesson. ``result.runtime`` is the time of the
    run that computed it.

    Parameters
    ----------
    dataset : records.Dataset or str
        As :func:`run`.
    config : SlamConfig, optional
        As :func:`run`.
    backend : {'efficient', 'dense'}, optional
        As :func:`run`.

    Returns
    -------
    SlamResult
        The same result as ``run(dataset, config, backend=backend)``.

    Raises
    ------
    TypeError, ValueError
        As :func:`run`.
    """
    return run(dataset, config, progress=False, backend=backend)


def _landmark_model(cfg: SlamConfig, model):
    """The landmark model to use (None: the detections as measured), checked against the
    config so that a forgotten switch or a forgotten model fails loudly."""
    if cfg.landmark_model == "inverse":
        if model is not None:
            raise ValueError("a landmark_model was passed but SlamConfig.landmark_model is "
                             "'inverse'; set landmark_model='ann' to use it")
        return None
    if model is None:
        raise ValueError("SlamConfig.landmark_model = 'ann' needs the trained model: "
                         "run(dataset, config, landmark_model=model)")
    if not (callable(getattr(model, "pseudo_measurement", None)) and hasattr(model, "sigmas")):
        raise ValueError(f"landmark_model must have pseudo_measurement(pose, z, intensity, "
                         f"width) and sigmas, got {type(model).__name__}")
    sr, sb = (float(s) for s in model.sigmas)
    if not (0 < sr < math.inf and 0 < sb < math.inf):
        raise ValueError(f"landmark_model sigmas must be positive and finite, got ({sr}, {sb})")
    return model



class LandmarkBook:
    """Which landmarks the filter holds and what is known about each (the run loop's
    book-keeping): ``uids`` in state order; per uid its creation time, its sightings, and
    whether it is still tentative (``SlamConfig.landmark_min_observations`` sightings within
    ``landmark_probation`` seconds, or it is marginalised out again); with known data
    association, the simulator's landmark id of each."""

    def __init__(self, min_observations: int, probation: float) -> None:
        self.min_obs, self.probation = min_observations, probation
        self.uids: list[int] = []
        self.born: list[float] = []
        self.seen: list[int] = []
        self.tentative: set[int] = set()
        self.by_true_id: dict[int, int] = {}
        self.removed = 0

    def __len__(self) -> int:
        return len(self.uids)

    def observed(self, state_indices) -> list[int]:
        """Count one more sighting of the landmarks at these state indices; their uids."""
        out = [self.uids[j] for j in state_indices]
        for uid in out:
            self.seen[uid] += 1
        return out

    def created(self, t: float, n: int, true_ids=None) -> list[int]:
        """Register ``n`` landmarks just appended to the state; their uids."""
        first = len(self.born)
        new = list(range(first, first + n))
        self.uids += new
        self.born += [t] * n
        self.seen += [1] * n
        self.tentative.update(new)
        if true_ids is not None:
            self.by_true_id.update(zip(true_ids, new))
        return new

    def known(self, n: int, t: float) -> None:
        """Register the ``n`` landmarks of a known map (already in the state, in order):
        confirmed from the start, never pruned; the simulator's ids are their indices."""
        uids = self.created(t, n, list(range(n)))
        self.tentative.difference_update(uids)
        for uid in uids:
            self.seen[uid] = 0

    def truth_assign(self, true_ids) -> list[int]:
        """Known data association (simulator): the state index of each detection's true
        landmark, NEW (-1) for the first sighting in a scan of an unmapped one, REJECTED
        (-2) for a second one in the same scan."""
        where = {u: j for j, u in enumerate(self.uids)}
        first, out = set(), []
        for tid in true_ids:
            uid = self.by_true_id.get(tid)
            if uid is not None and uid in where:
                out.append(where[uid])
            elif tid in first:
                out.append(-2)
            else:
                first.add(tid)
                out.append(-1)
        return out

    def prune(self, filt: FilterBackend, now: float, final: bool) -> None:
        """Confirm the tentative landmarks seen often enough; marginalise out those whose
        probation is over (all remaining ones when ``final``)."""
        if not self.tentative:
            return
        drop = []
        for uid in list(self.tentative):
            if self.seen[uid] >= self.min_obs:
                self.tentative.discard(uid)
            elif final or now - self.born[uid] > self.probation:
                drop.append(uid)
                self.tentative.discard(uid)
        if drop:
            where = {u: j for j, u in enumerate(self.uids)}
            filt.remove([where[u] for u in drop])
            gone = set(drop)
            self.uids = [u for u in self.uids if u not in gone]
            self.removed += len(drop)


class _Detections:
    """The run's detections as the scan step uses them: each one's measurement, whether it
    lies inside the range (and diameter) window, and what became of it."""

    def __init__(self, det: Detections, cfg: SlamConfig) -> None:
        self.det = det
        self.z = np.column_stack([det.range, det.bearing])
        inside = (det.range >= cfg.min_range) & (det.range <= cfg.max_range)
        if cfg.min_diameter > 0:
            inside &= ~(det.diameter < cfg.min_diameter)       # NaN (unknown) is kept
        self.status = np.where(inside, STATUS["rejected"], STATUS["out_of_range"]).astype(np.int8)
        self.uid = np.full(det.count, -1, dtype=np.int64)
        self.win = np.flatnonzero(inside)               # per scan: win[off[k]:off[k + 1]]
        self.off = np.searchsorted(self.win, det.offsets).tolist()

    def of_scan(self, k: int):
        a, b = self.off[k], self.off[k + 1]
        return self.win[a:b] if b > a else None


class _ScanStep:
    """One laser scan, after the prediction to its time: gate and associate every detection
    at once, one batch update with the associated ones, the new landmarks, the tentative
    rule. Holds what does not change from scan to scan."""

    def __init__(self, filt: FilterBackend, book: LandmarkBook, dets: _Detections,
                 cfg: SlamConfig, lmodel: LandmarkModel | None, sr: float, sb: float) -> None:
        self.filt, self.book, self.dets, self.lmodel = filt, book, dets, lmodel
        self.sr, self.sb = sr, sb
        self.gate = chi2_quantile(cfg.gate_prob, 2)
        self.new_thr = chi2_quantile(cfg.new_landmark_prob, 2)
        self.truth = cfg.association == "truth"
        self.jcbb = cfg.association == "jcbb"
        self.gate_prob, self.max_nodes = cfg.gate_prob, cfg.jcbb_max_nodes
        self.R = np.diag([sr**2, sb**2])
        self.truncated = 0                        # JCBB searches stopped at their bound
        self.known = cfg.map_mode == "known"      # localisation: nothing is ever added

    def __call__(self, k: int, t: float, prior: tuple) -> tuple[float, int] | None:
        """Process scan ``k`` at time ``t`` seen from the predicted pose ``prior``; the
        (NIS, dof) of its update, or None without one."""
        use = self.dets.of_scan(k)
        if use is None:
            self.book.prune(self.filt, t, False)
            return None
        d, filt, book = self.dets, self.filt, self.book
        use_l = use.tolist()
        z = d.z[use]
        if self.lmodel is not None:            # z' = h(prior, l_ann) REPLACES z, never both
            z = np.asarray(self.lmodel.pseudo_measurement(
                np.array(prior), z, d.det.intensity[use], d.det.diameter[use]), dtype=float)
            if z.shape != (use.size, 2) or not np.all(np.isfinite(z)) or np.any(z[:, 0] <= 0):
                raise ValueError(f"landmark_model returned invalid pseudo-measurements for "
                                 f"scan {k}: need finite ({use.size}, 2) with range > 0")
        if self.truth:
            assign = book.truth_assign(d.det.landmark_id[use].tolist())
        elif len(book) and self.jcbb:
            assign = self._joint(z, filt.innovation_d2(z, self.sr, self.sb))
        elif len(book):
            assign = associate_fast(filt.innovation_d2(z, self.sr, self.sb), self.gate,
                                    self.new_thr).tolist()
        else:
            assign = [-1] * len(use_l)
        result = None
        old = [i for i, j in enumerate(assign) if j >= 0]
        if old:
            lm = [assign[i] for i in old]
            result = filt.update(z[old], lm, self.sr, self.sb)
            for i, uid in zip(old, book.observed(lm)):
                d.status[use_l[i]] = STATUS["associated"]
                d.uid[use_l[i]] = uid
        new = [i for i, j in enumerate(assign) if j == -1]
        if new and self.known:                 # matches no landmark of the known map
            for i in new:
                d.status[use_l[i]] = STATUS["rejected"]
            new = []
        if new:
            filt.augment(z[new], self.sr, self.sb)
            ids = [int(d.det.landmark_id[use_l[i]]) for i in new] if self.truth else None
            for i, uid in zip(new, book.created(t, len(new), ids)):
                d.status[use_l[i]] = STATUS["new"]
                d.uid[use_l[i]] = uid
        book.prune(filt, t, False)
        return result

    def _joint(self, z, d2) -> list[int]:
        """JCBB over the landmarks in some detection's gate; a detection JCBB leaves unpaired
        is new if it is far from every landmark (as with 'nn'), else rejected."""
        assign = np.where(d2.min(axis=1) > self.new_thr, NEW, REJECTED)
        cand = np.flatnonzero((d2 <= self.gate).any(axis=0))
        if cand.size:
            zhat, C = self.filt.joint_prediction(cand)
            res = search_checked(z, zhat, C, self.R, self.gate_prob, self.gate_prob,
                                  self.max_nodes)
            self.truncated += not res.complete
            paired = res.pairs >= 0
            assign[paired] = cand[res.pairs[paired]]
        return assign.tolist()


@dataclasses.dataclass
class _Record:
    """What the loop collects for the result, row by row."""
    counts: dict
    pose_prior: np.ndarray                         # (scans, 3) prior pose at each scan
    traj: list = dataclasses.field(default_factory=list)     # (t, x, y, phi) after each scan
    cov: list = dataclasses.field(default_factory=list)      # its covariance, 6 entries
    scans: list = dataclasses.field(default_factory=list)    # the scans processed
    nis: list = dataclasses.field(default_factory=list)      # (t, scan, kind, nis, dof, ok)
    health: list = dataclasses.field(default_factory=list)   # (scan, t, n, min_eig, asym)


def _build(prep: Prepared, backend: str, gating: str, inspect):
    """The filter and its landmark book at the start pose (the known map added if asked)."""
    cfg, ds = prep.config, prep.dataset
    if backend == "efficient":
        from .efficient import EkfSlam as make
    elif backend == "ukf":
        from .unscented import ukf_backend
        make = ukf_backend()
    else:
        from .dense import DenseEkfSlam as make
    if cfg.association == "jcbb" and backend != "efficient":
        raise ValueError("SlamConfig.association = 'jcbb' is implemented by the efficient "
                         "backend only")
    if cfg.first_estimates and backend != "efficient":
        raise ValueError("SlamConfig.first_estimates (FEJ) is implemented by the efficient "
                         "backend only")
    options = {"fej": True} if cfg.first_estimates else {}
    if backend == "efficient":
        if gating == "auto":
            gating = "compiled" if compiled.use_compiled(len(prep.detections)) else "numpy"
        options["gating"] = gating
    elif gating == "compiled":
        raise ValueError("gating='compiled' is a choice of the efficient backend only")
    filt = make(prep.pose0, prep.cov0, ds.vehicle, cfg.motion_model, **options)
    book = LandmarkBook(cfg.landmark_min_observations, cfg.landmark_probation)
    if cfg.map_mode == "known":                # EKF localisation on the surveyed map
        if ds.beacons is None:
            raise ValueError(f"SlamConfig.map_mode = 'known' needs a surveyed map, and "
                             f"dataset {ds.name!r} has none (Dataset.beacons is None)")
        filt.add_known_landmarks(ds.beacons, cfg.known_map_sigma)
        book.known(ds.beacons.shape[0], float(ds.odometry.t[0]))
    if inspect is not None:
        inspect(filt)
    return filt, book


def _run(dataset, config, progress, backend, landmark_model=None, inspect=None,
         gating="auto") -> SlamResult:
    t_start = time.perf_counter()
    if backend not in ("efficient", "dense", "ukf"):
        raise ValueError(f"backend must be 'efficient', 'dense' or 'ukf', got {backend!r}")
    prep = prepare(dataset, config)
    filt, book = _build(prep, backend, gating, inspect)
    cfg, ds, det = prep.config, prep.dataset, prep.detections
    odo = ds.odometry
    controls = control_table(odo, ds.vehicle, cfg.sigma_speed, cfg.sigma_steer,
                             cfg.steer_noise_gain, array=True)
    lmodel = _landmark_model(cfg, landmark_model)
    sr, sb = cfg.sigma_range, cfg.sigma_bearing
    if lmodel is not None:                     # the model's pseudo-measurement noise R'
        sr, sb = (float(s) for s in lmodel.sigmas)
    dets = _Detections(det, cfg)
    scan_step = _ScanStep(filt, book, dets, cfg, lmodel, sr, sb)
    rec = _Record(counts=dict(predicts=0, scans=0, scans_skipped=0, gps_updates=0,
                              gps_rejected=0, gps_skipped=0, updates=0, observations=0,
                              associated=0, new=0, rejected=0, out_of_range=0,
                              landmarks_created=0, landmarks_removed=0,
                              **prep.screening.counts()),
                  pose_prior=np.full((len(det), 3), np.nan))
    odo_traj, t_end = _loop(prep, filt, controls, scan_step, rec, backend, progress)
    book.prune(filt, t_end, True)
    _checkpoint(filt, rec, rec.scans[-1] if rec.scans else -1, t_end)
    rec.counts["landmarks_removed"] = book.removed
    if cfg.association == "jcbb":
        rec.counts["jcbb_truncated"] = scan_step.truncated
    return _assemble(filt, book, dets, prep, rec, odo_traj, t_start)


def _loop(prep: Prepared, filt, controls, scan_step, rec: _Record, backend, progress):
    """The run's events in time order (numbered as in :func:`run`'s docstring): 1. predict
    to the event, 2. a GPS fix: its update, 3. a scan: gate, associate, update, add
    landmarks; 4. after the last event, the remaining odometry. Returns the odometry-only
    poses at the odometry samples and the time the run ends."""
    cfg, ds = prep.config, prep.dataset
    odo, gps_xy = ds.odometry, ds.gps.xy
    counts, traj_rows, cov_rows = rec.counts, rec.traj, rec.cov
    scans_done, pose_prior, nis_rows = rec.scans, rec.pose_prior, rec.nis
    gps_gate = math.inf if cfg.gps_gate_prob >= 1.0 else chi2_quantile(cfg.gps_gate_prob, 2)
    t0 = float(odo.t[0])
    gps_until = {"none": -math.inf, "init": t0 + cfg.gps_init_seconds, "all": math.inf}[cfg.gps_mode]

    ev_t, ev_code, ev_idx, ev_k = prep.events
    # the predictions between events, compounded for the whole run at once (slam.stretches);
    # the dense reference replays them step by step
    legs = stretches.compound(odo.t, controls, ev_t, ev_k, ds.vehicle,
                              cfg.motion_model == "midpoint")
    starts = np.full((len(ev_t) + 1, 3), np.nan)     # the pose at each stretch's start
    if backend == "efficient":
        def advance(s: int) -> None:
            starts[s] = filt.pose_tuple()
            counts["predicts"] += filt.predict_stretch(legs.rows[s])
    else:
        rows = [tuple(r) for r in controls.tolist()]

        def advance(s: int) -> None:
            starts[s] = filt.pose_tuple()
            for h, dt in legs.steps_of(s):
                filt.predict(rows[h], dt)
                counts["predicts"] += 1
    bar = _progress(progress, len(odo.t) + len(ev_t))
    cur_t = t0
    for e, (t, code, idx, k_end) in enumerate(zip(ev_t, ev_code, ev_idx, ev_k)):
        if bar is not None:
            bar.update(k_end + e + 1 - bar.n)
        if not legs.processed[e]:          # before the first odometry sample
            counts["scans_skipped" if code == 2 else "gps_skipped"] += 1
            continue
        advance(e)                         # 1. predict
        cur_t = t
        if code == 0:                      # 2. GPS fix
            if t > gps_until:
                counts["gps_skipped"] += 1
                continue
            nis, ok = filt.gps_update(gps_xy[idx], cfg.sigma_gps, gps_gate)
            nis_rows.append((t, -1, 1, nis, 2, ok))
            counts["gps_updates" if ok else "gps_rejected"] += 1
            continue
        counts["scans"] += 1               # 3. laser scan idx
        prior = filt.pose_tuple()
        pose_prior[idx] = prior
        scans_done.append(idx)
        out = scan_step(idx, t, prior)
        if out is not None:
            nis_rows.append((t, idx, 0, out[0], out[1], True))
            counts["updates"] += 1
        traj_rows.append((t, *filt.pose_tuple()))
        cov_rows.append(filt.pose_cov_entries())
        if counts["scans"] % cfg.checkpoint_every == 0:
            _checkpoint(filt, rec, idx, t)
    advance(len(ev_t))                     # 4. odometry after the last event
    cur_t = max(cur_t, float(odo.t[-1]))
    if bar is not None:
        bar.update(bar.total - bar.n)
        bar.close()
    return legs.sample_poses(starts), cur_t


def _checkpoint(filt, rec: _Record, scan: int, t: float) -> None:
    lo, asym = filt.health()
    rec.health.append((scan, t, filt.state()[0].size, lo, asym))


def _assemble(filt, book, dets, prep: Prepared, rec: _Record, odo_traj, t_start) -> SlamResult:
    """The :class:`SlamResult` of a finished run: arrays from the rows collected, the
    per-detection log, the landmarks' histories."""
    cfg, counts, pose_prior = prep.config, rec.counts, rec.pose_prior
    det = dets.det
    n_scans = len(det)
    n_traj = len(rec.traj)
    traj = np.array(rec.traj, dtype=float).reshape(n_traj, 4)
    traj_scan = np.array(rec.scans, dtype=np.int64)
    c6 = np.array(rec.cov, dtype=float).reshape(n_traj, 6)
    traj_cov = c6[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(n_traj, 3, 3)
    processed = np.zeros(det.count, dtype=bool)
    processed[np.isin(np.repeat(np.arange(n_scans), np.diff(det.offsets)), traj_scan)] = True
    x, P = filt.state()
    x, P = x.copy(), P.copy()
    M = len(book)
    lut = np.full(len(book.born) + 1, -1, dtype=np.int64)  # uid -> final landmark index
    lut[book.uids] = np.arange(M)
    det_landmark = np.where(dets.uid >= 0, lut[dets.uid], -1)
    st = dets.status[processed]
    counts["observations"] = int(processed.sum())
    for key in ("associated", "new", "rejected", "out_of_range"):
        counts[key] = int(np.sum(st == STATUS[key]))
    counts["landmarks_created"] = len(book.born)
    counts["landmarks"] = M
    scan_of = np.repeat(np.arange(n_scans), np.diff(det.offsets))
    post = np.full((n_scans, 3), np.nan)
    post[traj_scan[:n_traj]] = traj[:n_traj, 1:]
    rows = np.flatnonzero(processed)
    log = ObservationLog(scan=scan_of[rows], t=det.t[scan_of[rows]], range=det.range[rows].copy(),
                         bearing=det.bearing[rows].copy(), intensity=det.intensity[rows].copy(),
                         diameter=det.diameter[rows].copy(), true_id=det.landmark_id[rows].copy(),
                         status=dets.status[rows], landmark=det_landmark[rows],
                         pose_prior=pose_prior[scan_of[rows]], pose=post[scan_of[rows]])
    lm_obs, lm_true = landmark_history(log, M)
    health = {k: np.array([r[i] for r in rec.health]) for i, k in
              enumerate(("scan", "t", "n", "min_eig", "asymmetry"))}
    return SlamResult(
        trajectory=traj, scan_index=traj_scan, pose_cov=traj_cov,
        odometry_trajectory=odo_traj,
        landmarks=x[3:].reshape(-1, 2).copy(), landmark_cov=diag_blocks(P).copy(),
        landmark_observations=lm_obs, landmark_true_id=lm_true, nis=nis_arrays(rec.nis),
        counts=counts, health=health, state=x, covariance=P, observations=log,
        runtime=time.perf_counter() - t_start, config=cfg, initial_pose=prep.pose0,
        initial_info=prep.initial_info, gating=getattr(filt, "gating", "numpy"))
