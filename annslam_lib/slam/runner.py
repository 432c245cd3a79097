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

import math
import sys
import time

import numpy as np

from ..data import filter_default_names
from ..data.records import Dataset, Detections
from ..evaluation.consistency import chi2_quantile
from ..models.motion import control_table
from ..perception.association import associate_fast, mahalanobis_fast
from .config import SlamConfig
from .results import STATUS, ObservationLog, SlamResult, _landmark_history, _nis_arrays
from .efficient import diag_blocks
from .threads import one_blas_thread

__all__ = ["run"]


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



def _detections(dataset: Dataset, source: str) -> Detections:
    from ..perception import sources          # beacon extraction, only when needed
    return sources.detections_for(dataset, source=source)



def _initial(dataset: Dataset, cfg: SlamConfig) -> tuple[np.ndarray, dict]:
    policy = cfg.initial_pose
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
                                        window=cfg.initial_window)
        except ValueError as e:
            raise ValueError(f"initial pose from GPS failed ({e}); pass "
                             "SlamConfig.initial_pose = (x, y, phi)") from e
        return fit.pose.copy(), {"policy": "gps", "fixes": fit.fixes, "travel": fit.travel,
                                 "rms": fit.rms, "window": fit.window}
    return np.array(policy, dtype=float), {"policy": "given"}



def _event_table(odo_t, gps_t, scan_t):
    ts = [gps_t, odo_t, scan_t]
    t = np.concatenate(ts)
    code = np.concatenate([np.full(x.size, c, dtype=np.int64) for x, c in zip(ts, (0, 1, 2))])
    idx = np.concatenate([np.arange(x.size) for x in ts])
    order = np.lexsort((code, t))
    return t[order].tolist(), code[order].tolist(), idx[order].tolist()



def _progress(progress, total):
    if progress is None:
        progress = total > 20000 and sys.stderr.isatty()
    if not progress:
        return None
    from tqdm.auto import tqdm
    return tqdm(total=total, desc="EKF-SLAM", unit="event", mininterval=0.5)



def run(dataset, config: SlamConfig | None = None, *, progress=None,
        backend: str = "efficient", landmark_model=None) -> SlamResult:
    """Run EKF-SLAM over a whole dataset (notebook 05; notebook 06 for Victoria Park).

    dataset: a ``records.Dataset`` (loaded or simulated) or 'car_park' / 'victoria_park'.
    config: :class:`SlamConfig`; None -> ``SlamConfig.for_dataset(dataset.name)`` for a
    known name, else ``SlamConfig()``. progress: tqdm bar; None = only for long runs
    with a terminal. backend: 'efficient' (:class:`EkfSlam`) or 'dense' (the textbook
    reference ``slam.dense.DenseEkfSlam``; slow, for checks).

    Events are processed in time order from the first odometry sample on (earlier scans
    and fixes are skipped and counted); the filter predicts to every event's time with
    the control of the last odometry sample. A scan: predict, gate and associate all its
    detections at once, one batch update with the associated ones, then add the new
    landmarks, then the tentative-landmark rule. BLAS runs on one thread meanwhile
    (:func:`one_blas_thread`).

    landmark_model: with ``config.landmark_model = 'ann'``, the trained model
    (``ann.TrainedModel``, ``ann.InverseModel`` or anything with ``pseudo_measurement(pose,
    z, intensity, width)`` and ``sigmas``): its pseudo-measurements replace the detections
    (module docstring). The log keeps the raw detections.
    """
    with one_blas_thread():
        return _run(dataset, config, progress, backend, landmark_model)



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



def _run(dataset, config, progress, backend, landmark_model=None) -> SlamResult:
    t_start = time.perf_counter()
    ds = _resolve_dataset(dataset)
    if config is None:
        config = SlamConfig.for_dataset(ds.name) if ds.name in filter_default_names() else SlamConfig()
    if not isinstance(config, SlamConfig):
        raise TypeError(f"config must be a SlamConfig, got {type(config).__name__}")
    cfg = config
    if backend == "efficient":
        from .efficient import EkfSlam as make
    elif backend == "dense":
        from .dense import DenseEkfSlam as make
    else:
        raise ValueError(f"backend must be 'efficient' or 'dense', got {backend!r}")
    det = _detections(ds, cfg.feature_source)
    if cfg.association == "truth" and np.any(det.landmark_id < 0):
        raise ValueError("SlamConfig.association = 'truth' needs detections with true "
                         "landmark ids (a simulated dataset)")
    odo = ds.odometry
    if len(odo) < 1:
        raise ValueError("the dataset has no odometry")
    pose0, init_info = _initial(ds, cfg)
    P0 = np.diag([cfg.initial_sigma_xy**2, cfg.initial_sigma_xy**2, cfg.initial_sigma_phi**2])
    filt = make(pose0, P0, ds.vehicle, cfg.motion_model)
    controls = control_table(odo, ds.vehicle, cfg.sigma_speed, cfg.sigma_steer)

    sr, sb = cfg.sigma_range, cfg.sigma_bearing
    lmodel = _landmark_model(cfg, landmark_model)
    if lmodel is not None:                     # the model's pseudo-measurement noise R'
        sr, sb = (float(s) for s in lmodel.sigmas)
    gate = chi2_quantile(cfg.gate_prob, 2)
    new_thr = chi2_quantile(cfg.new_landmark_prob, 2)
    gps_gate = math.inf if cfg.gps_gate_prob >= 1.0 else chi2_quantile(cfg.gps_gate_prob, 2)
    t0 = float(odo.t[0])
    gps_until = {"none": -math.inf, "init": t0 + cfg.gps_init_seconds, "all": math.inf}[cfg.gps_mode]
    gps_xy = ds.gps.xy

    ev_t, ev_code, ev_idx = _event_table(odo.t, ds.gps.t, det.t)
    n_scans = len(det)
    traj_rows: list[tuple] = []            # pose after each processed scan
    cov_rows: list[list] = []              # its covariance (6 unique entries)
    scans_done: list[int] = []
    pose_prior = np.full((n_scans, 3), np.nan)
    odo_traj = np.full((len(odo), 4), np.nan)
    nis_rows = []                          # (t, scan, kind, nis, dof, accepted)
    health_rows = []
    counts = dict(predicts=0, scans=0, scans_skipped=0, gps_updates=0, gps_rejected=0,
                  gps_skipped=0, updates=0, observations=0, associated=0, new=0, rejected=0,
                  out_of_range=0, landmarks_created=0, landmarks_removed=0)
    # Per detection: measurement, whether it is inside the range window, and what became of it.
    z_det = np.column_stack([det.range, det.bearing])
    in_window = (det.range >= cfg.min_range) & (det.range <= cfg.max_range)
    if cfg.min_diameter > 0:
        in_window &= ~(det.diameter < cfg.min_diameter)          # NaN (unknown) is kept
    status = np.where(in_window, STATUS["rejected"], STATUS["out_of_range"]).astype(np.int8)
    det_uid = np.full(det.count, -1, dtype=np.int64)
    win = np.flatnonzero(in_window)                        # per scan: win[win_off[k]:win_off[k+1]]
    win_off = np.searchsorted(win, det.offsets).tolist()
    ASSOCIATED, NEW = STATUS["associated"], STATUS["new"]
    # Landmarks: ``uids`` in state order; creation time and sightings indexed by uid.
    uids: list[int] = []
    born: list[float] = []
    seen: list[int] = []
    tentative: set[int] = set()
    truth_to_uid: dict[int, int] = {}
    min_obs, probation = cfg.landmark_min_observations, cfg.landmark_probation
    bar = _progress(progress, len(ev_t))

    def prune(now: float, final: bool) -> None:
        drop = []
        for uid in list(tentative):
            if seen[uid] >= min_obs:
                tentative.discard(uid)
            elif final or now - born[uid] > probation:
                drop.append(uid)
                tentative.discard(uid)
        if drop:
            where = {u_: j for j, u_ in enumerate(uids)}
            filt.remove([where[u_] for u_ in drop])
            gone = set(drop)
            uids[:] = [u_ for u_ in uids if u_ not in gone]
            counts["landmarks_removed"] += len(drop)

    def checkpoint(scan: int, t: float) -> None:
        lo, asym = filt.health()
        health_rows.append((scan, t, filt.x.size, lo, asym))

    cur_t = t0
    u = None
    predict = filt.predict
    truth = cfg.association == "truth"
    n_ev = len(ev_t)
    for i_ev in range(n_ev):
        t, code, idx = ev_t[i_ev], ev_code[i_ev], ev_idx[i_ev]
        if bar is not None and i_ev % 2000 == 0:
            bar.update(min(2000, n_ev - i_ev))
        if code == 1:                                          # odometry: new held control
            if t < t0:
                continue
            if t > cur_t:
                predict(u, t - cur_t)
                counts["predicts"] += 1
                cur_t = t
            u = controls[idx]
            odo_traj[idx] = (t, filt._px, filt._py, filt._pphi)
            continue
        if t < t0 or u is None:                                # before the first odometry
            counts["scans_skipped" if code == 2 else "gps_skipped"] += 1
            continue
        if t > cur_t:
            predict(u, t - cur_t)
            counts["predicts"] += 1
            cur_t = t
        if code == 0:                                          # GPS fix
            if t > gps_until:
                counts["gps_skipped"] += 1
                continue
            nis, ok = filt.gps_update(gps_xy[idx], cfg.sigma_gps, gps_gate)
            nis_rows.append((t, -1, 1, nis, 2, ok))
            counts["gps_updates" if ok else "gps_rejected"] += 1
            continue
        # ---- laser scan idx
        counts["scans"] += 1
        pose_prior[idx] = (filt._px, filt._py, filt._pphi)
        scans_done.append(idx)
        a_, b_ = win_off[idx], win_off[idx + 1]
        if b_ > a_:
            use = win[a_:b_]
            use_l = use.tolist()
            z = z_det[use]
            if lmodel is not None:             # z' = h(prior, l_ann) REPLACES z, never both
                z = np.asarray(lmodel.pseudo_measurement(
                    pose_prior[idx], z, det.intensity[use], det.diameter[use]), dtype=float)
                if z.shape != (use.size, 2) or not np.all(np.isfinite(z)) or np.any(z[:, 0] <= 0):
                    raise ValueError(f"landmark_model returned invalid pseudo-measurements for "
                                     f"scan {idx}: need finite ({use.size}, 2) with range > 0")
            if truth:
                where = {u_: j for j, u_ in enumerate(uids)}
                first = set()
                assign = []
                for tid in det.landmark_id[use].tolist():
                    if tid in truth_to_uid and truth_to_uid[tid] in where:
                        assign.append(where[truth_to_uid[tid]])
                    elif tid in first:     # seen twice in one scan before it exists: once
                        assign.append(-2)
                    else:
                        first.add(tid)
                        assign.append(-1)
            elif uids:
                zhat, S = filt.observation_model(sr, sb)
                assign = associate_fast(mahalanobis_fast(z, zhat, S), gate, new_thr).tolist()
            else:
                assign = [-1] * len(use_l)
            old = [i for i, j in enumerate(assign) if j >= 0]
            if old:
                lm = [assign[i] for i in old]
                nis, dof = filt.update(z[old], lm, sr, sb)
                nis_rows.append((t, idx, 0, nis, dof, True))
                counts["updates"] += 1
                for i, j in zip(old, lm):
                    uid = uids[j]
                    seen[uid] += 1
                    status[use_l[i]] = ASSOCIATED
                    det_uid[use_l[i]] = uid
            new = [i for i, j in enumerate(assign) if j == -1]
            if new:
                filt.augment(z[new], sr, sb)
                for i in new:
                    uid = len(born)
                    uids.append(uid)
                    born.append(t)
                    seen.append(1)
                    tentative.add(uid)
                    status[use_l[i]] = NEW
                    det_uid[use_l[i]] = uid
                    if truth:
                        truth_to_uid[int(det.landmark_id[use_l[i]])] = uid
        if tentative:
            prune(t, False)
        traj_rows.append((t, filt._px, filt._py, filt._pphi))
        cov_rows.append(filt._p)
        if counts["scans"] % cfg.checkpoint_every == 0:
            checkpoint(idx, t)
    if bar is not None:
        bar.close()
    prune(cur_t, True)
    checkpoint(scans_done[-1] if scans_done else -1, cur_t)
    n_traj = len(traj_rows)
    traj = np.array(traj_rows, dtype=float).reshape(n_traj, 4)
    traj_scan = np.array(scans_done, dtype=np.int64)
    c6 = np.array(cov_rows, dtype=float).reshape(n_traj, 6)
    traj_cov = c6[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(n_traj, 3, 3)
    processed = np.zeros(det.count, dtype=bool)
    processed[np.isin(np.repeat(np.arange(n_scans), np.diff(det.offsets)), traj_scan)] = True

    x, P = filt.state()
    x, P = x.copy(), P.copy()
    M = len(uids)
    lut = np.full(len(born) + 1, -1, dtype=np.int64)      # uid -> final landmark index
    lut[uids] = np.arange(M)
    det_landmark = np.where(det_uid >= 0, lut[det_uid], -1)
    st = status[processed]
    counts["observations"] = int(processed.sum())
    counts["associated"] = int(np.sum(st == STATUS["associated"]))
    counts["new"] = int(np.sum(st == STATUS["new"]))
    counts["rejected"] = int(np.sum(st == STATUS["rejected"]))
    counts["out_of_range"] = int(np.sum(st == STATUS["out_of_range"]))
    counts["landmarks_created"] = len(born)
    counts["landmarks"] = M
    scan_of = np.repeat(np.arange(n_scans), np.diff(det.offsets))
    post = np.full((n_scans, 3), np.nan)
    post[traj_scan[:n_traj]] = traj[:n_traj, 1:]
    rows = np.flatnonzero(processed)
    log = ObservationLog(scan=scan_of[rows], t=det.t[scan_of[rows]], range=det.range[rows].copy(),
                         bearing=det.bearing[rows].copy(), intensity=det.intensity[rows].copy(),
                         diameter=det.diameter[rows].copy(), true_id=det.landmark_id[rows].copy(),
                         status=status[rows], landmark=det_landmark[rows],
                         pose_prior=pose_prior[scan_of[rows]], pose=post[scan_of[rows]])
    lm_obs, lm_true = _landmark_history(log, M)
    nis = _nis_arrays(nis_rows)
    health = {k: np.array([r[i] for r in health_rows]) for i, k in
              enumerate(("scan", "t", "n", "min_eig", "asymmetry"))}
    return SlamResult(
        trajectory=traj[:n_traj].copy(), scan_index=traj_scan[:n_traj].copy(),
        pose_cov=traj_cov[:n_traj].copy(),
        odometry_trajectory=odo_traj[np.isfinite(odo_traj[:, 0])],
        landmarks=x[3:].reshape(-1, 2).copy(), landmark_cov=diag_blocks(P).copy(),
        landmark_observations=lm_obs, landmark_true_id=lm_true, nis=nis, counts=counts,
        health=health, state=x, covariance=P, observations=log,
        runtime=time.perf_counter() - t_start, config=cfg, initial_pose=pose0,
        initial_info=init_info)
