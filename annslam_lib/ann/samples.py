"""The ANN's training samples and their splits (notebook 07; the samples are described in
:mod:`annslam_lib.ann`)."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ..evaluation.map import match_landmarks
from ..models.observation import inverse_observe_values
from ..slam.results import STATUS

__all__ = ["FEATURE_NAMES", "MEASUREMENT_FEATURES", "USED_STATUS", "SPLITS", "TrainingSet",
           "encode", "training_set", "Split", "chronological_split", "beacon_folds",
           "time_fold_edges", "time_folds", "beacon_holdout_sizes"]

#: Columns of ``TrainingSet.X`` (module docstring).
FEATURE_NAMES = ("pose_x", "pose_y", "sin_phi", "cos_phi", "range", "bearing", "sin_ray",
                 "cos_ray", "intensity", "width", "lm_x", "lm_y")

#: The features that do not reveal WHERE the car is: a model on these alone cannot
#: memorise beacon positions (for ``TrainConfig.features``).
MEASUREMENT_FEATURES = ("range", "bearing", "sin_ray", "cos_ray", "intensity", "width")

#: ObservationLog status codes that become training samples.
USED_STATUS = (STATUS["associated"], STATUS["new"])

#: Names of the three parts of a :class:`Split`.
SPLITS = ("train", "val", "test")

COLUMN = {name: i for i, name in enumerate(FEATURE_NAMES)}


@dataclass(frozen=True)
class TrainingSet:
    """Samples for the landmark network (module docstring).

    X (n, F): features, columns ``feature_names`` (= :data:`FEATURE_NAMES`);
    Y (n, 2): target correction = target - base; base (n, 2): inverse observation
    g(prior pose, z); target (n, 2): the true beacon; beacon (n,): its index into the
    dataset's beacons; t (n,): scan time, s; scan (n,): scan index; pose (n, 3) the prior
    pose and z (n, 2) the measurement (the raw values behind X).
    """

    X: np.ndarray
    Y: np.ndarray
    base: np.ndarray
    target: np.ndarray
    beacon: np.ndarray
    t: np.ndarray
    scan: np.ndarray
    feature_names: tuple = FEATURE_NAMES
    pose: np.ndarray | None = None
    z: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.X)[0]
        if tuple(self.feature_names) != FEATURE_NAMES:
            raise ValueError(f"feature_names must be {FEATURE_NAMES}, got {self.feature_names}")
        shapes = dict(X=(n, len(FEATURE_NAMES)), Y=(n, 2), base=(n, 2), target=(n, 2),
                      beacon=(n,), t=(n,), scan=(n,), pose=(n, 3), z=(n, 2))
        for name, shape in shapes.items():
            a = getattr(self, name)
            if a is None and name in ("pose", "z"):
                continue
            a = np.asarray(a)
            if a.shape != shape:
                raise ValueError(f"TrainingSet.{name} must have shape {shape}, got {a.shape}")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"TrainingSet.{name} contains NaN or infinite values")
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return self.X.shape[0]

    def subset(self, index) -> TrainingSet:
        """The samples ``index`` (integer indices or a boolean mask)."""
        index = np.asarray(index)
        return TrainingSet(**{f: (getattr(self, f)[index] if f != "feature_names" and
                                  getattr(self, f) is not None else getattr(self, f))
                              for f in ("X", "Y", "base", "target", "beacon", "t", "scan",
                                        "feature_names", "pose", "z")})



def encode(pose, z, intensity=None, width=None) -> tuple[np.ndarray, np.ndarray]:
    """Features X (n, F) and the inverse observation base (n, 2) for laser poses
    ``pose`` (n, 3) or (3,) and measurements ``z`` (n, 2) (module docstring table).
    ``intensity``, ``width`` (n,) default to 0; NaN width (unknown) becomes 0.
    The same function serves the training set and the filter at run time."""
    z = np.asarray(z, dtype=float)
    if z.ndim > 2 or (z.ndim >= 1 and z.shape[-1] != 2) or z.ndim == 0:
        raise ValueError(f"z must be (n, 2) range-bearing pairs or one pair (2,), got shape {z.shape}")
    z = z.reshape(-1, 2)
    n = z.shape[0]
    if not np.all(np.isfinite(np.asarray(pose, dtype=float))):   # before broadcasting to n = 0
        raise ValueError("pose and z must be finite")
    pose = np.broadcast_to(np.asarray(pose, dtype=float), (n, 3)) if np.ndim(pose) == 1 \
        else np.asarray(pose, dtype=float)
    if pose.shape != (n, 3):
        raise ValueError(f"pose must be (3,) or ({n}, 3), got {pose.shape}")
    if not np.all(np.isfinite(z)):                 # the pose was checked above
        raise ValueError("pose and z must be finite")
    level = np.zeros(n) if intensity is None else np.asarray(intensity, dtype=float).reshape(-1)
    w = np.zeros(n) if width is None else np.asarray(width, dtype=float).reshape(-1)
    if level.shape != (n,) or w.shape != (n,):
        raise ValueError(f"intensity and width must have {n} entries, got {level.shape}, {w.shape}")
    w = np.where(np.isnan(w), 0.0, w)
    if not np.all(np.isfinite(level)) or not np.all(np.isfinite(w)):
        raise ValueError("intensity and width must be finite (NaN width is read as 0)")
    base = inverse_observe_values(pose, z) if n else np.empty((0, 2))
    ray = pose[:, 2] + z[:, 1] - np.pi / 2
    X = np.column_stack([pose[:, 0], pose[:, 1], np.sin(pose[:, 2]), np.cos(pose[:, 2]),
                         z[:, 0], z[:, 1], np.sin(ray), np.cos(ray), level, w, base])
    return X, base



def training_set(result, dataset, *, max_distance: float = 1.0, use_truth_ids: bool | None = None
                 ) -> TrainingSet:
    """Training samples from an EKF-SLAM run (``slam.runner.run``) on ``dataset``.

    Every observation with status 'associated' or 'new' that belongs to a final map
    landmark becomes a sample: inputs from its PRIOR pose and measurement (``encode``),
    target the true position of its beacon. Which beacon: the simulator's true id of the
    detection (``use_truth_ids`` None -> whenever the detections carry ids); otherwise the
    surveyed beacon matched one-to-one (Hungarian, ``evaluation.map.match_landmarks``) to
    the filter's final landmark within ``max_distance`` m; observations of unmatched
    landmarks are dropped. Raises ValueError without surveyed beacons or samples.
    """
    beacons = getattr(dataset, "beacons", None)
    if beacons is None:
        raise ValueError(f"dataset {getattr(dataset, 'name', '?')!r} has no surveyed beacons: "
                         "no targets for the landmark network")
    log = result.observations
    used = np.isin(log.status, USED_STATUS) & (log.landmark >= 0)
    if use_truth_ids is None:
        use_truth_ids = bool(np.all(log.true_id[used] >= 0)) and used.any()
    if use_truth_ids:
        if np.any(log.true_id[used] < 0):
            raise ValueError("use_truth_ids=True but some detections have no true id")
        beacon = log.true_id.astype(np.int64)
    else:
        i_map, j_true = match_landmarks(result.landmarks, beacons, max_distance)
        lut = np.full(result.landmarks.shape[0], -1, dtype=np.int64)
        lut[i_map] = j_true
        beacon = np.where(log.landmark >= 0, lut[np.maximum(log.landmark, 0)], -1)
    keep = np.flatnonzero(used & (beacon >= 0))
    if keep.size == 0:
        raise ValueError("no observation of a matched beacon: empty training set")
    pose = np.asarray(log.pose_prior[keep], dtype=float)
    z = np.column_stack([log.range[keep], log.bearing[keep]])
    X, base = encode(pose, z, log.intensity[keep], log.diameter[keep])
    target = beacons[beacon[keep]]
    return TrainingSet(X=X, Y=target - base, base=base, target=target, beacon=beacon[keep],
                       t=np.asarray(log.t[keep], dtype=float), scan=np.asarray(log.scan[keep]),
                       pose=pose, z=z)



@dataclass(frozen=True)
class Split:
    """Sample indices of the training, validation and test parts; ``name`` says how."""

    train: np.ndarray
    val: np.ndarray
    test: np.ndarray
    name: str = ""

    def __post_init__(self) -> None:
        for part in SPLITS:
            object.__setattr__(self, part, np.asarray(getattr(self, part), dtype=np.int64).ravel())
        if self.train.size == 0 or self.val.size == 0:
            raise ValueError(f"split {self.name!r}: the training and validation parts must not "
                             "be empty")
        allidx = np.concatenate([self.train, self.val, self.test])
        if np.unique(allidx).size != allidx.size:
            raise ValueError(f"split {self.name!r}: a sample is in two parts (or twice in one)")

    def part(self, name: str) -> np.ndarray:
        if name not in SPLITS:
            raise ValueError(f"unknown split part {name!r}; parts: {SPLITS}")
        return getattr(self, name)



def chronological_split(ts: TrainingSet, fractions=(0.7, 0.15, 0.15)) -> Split:
    """First 70 % of the SCANS (in time) for training, the next 15 % for validation, the
    last 15 % for testing (``fractions``). Samples of one scan stay together, so no part
    overlaps another in time."""
    f = np.asarray(fractions, dtype=float)
    if f.shape != (3,) or np.any(f < 0) or not math.isclose(f.sum(), 1.0) or f[0] <= 0 or f[1] <= 0:
        raise ValueError(f"fractions must be three non-negative numbers summing to 1 with "
                         f"train, val > 0, got {fractions!r}")
    times = np.unique(ts.t)
    if times.size < 3:
        raise ValueError(f"need samples from at least 3 scans for a chronological split, "
                         f"got {times.size}")
    c1 = max(1, int(round(f[0] * times.size)))
    c2 = min(times.size, max(c1 + 1, int(round((f[0] + f[1]) * times.size))))
    rank = np.searchsorted(times, ts.t)
    order = np.argsort(ts.t, kind="stable")
    r = rank[order]
    return Split(order[r < c1], order[(r >= c1) & (r < c2)], order[r >= c2],
                 name="chronological")



def beacon_folds(ts: TrainingSet, n_folds: int = 5, seed: int = 0) -> list[Split]:
    """Leave-beacons-out cross-validation. The beacons are shuffled (``seed``) and dealt
    into ``n_folds`` groups; fold k tests on group k, validates (early stopping) on group
    k + 1 and trains on the rest, so neither early stopping nor training ever sees a
    tested beacon, and early stopping itself rewards generalising to unseen beacons."""
    if isinstance(n_folds, bool) or not isinstance(n_folds, numbers.Integral) or n_folds < 3:
        raise ValueError(f"n_folds must be an integer >= 3 (test, validation, training groups), "
                         f"got {n_folds!r}")
    ids = np.unique(ts.beacon)
    if ids.size < n_folds:
        raise ValueError(f"{ids.size} beacons cannot make {n_folds} folds")
    groups = np.array_split(np.random.default_rng(seed).permutation(ids), n_folds)
    folds = []
    for k in range(n_folds):
        test_b, val_b = groups[k], groups[(k + 1) % n_folds]
        test = np.flatnonzero(np.isin(ts.beacon, test_b))
        val = np.flatnonzero(np.isin(ts.beacon, val_b))
        train_ = np.flatnonzero(~np.isin(ts.beacon, np.concatenate([test_b, val_b])))
        folds.append(Split(train_, val, test, name=f"beacons fold {k}: test {sorted(test_b.tolist())}"))
    return folds



def time_fold_edges(ts: TrainingSet, n_folds: int = 5) -> np.ndarray:
    """Edges (n_folds + 1,) of ``n_folds`` contiguous time windows holding equal numbers
    of samples: quantiles of the samples' scan times, s (blocked cross-validation over
    time, notebook 08 section 4)."""
    if isinstance(n_folds, bool) or not isinstance(n_folds, numbers.Integral) or n_folds < 2:
        raise ValueError(f"n_folds must be an integer >= 2, got {n_folds!r}")
    if np.unique(ts.t).size < 2 * n_folds:
        raise ValueError(f"{np.unique(ts.t).size} scans cannot make {n_folds} time folds")
    return np.quantile(ts.t, np.linspace(0.0, 1.0, n_folds + 1))



def time_folds(ts: TrainingSet, n_folds: int = 5, *, gap: float = 2.0,
               val_fraction: float = 0.15, seed: int = 0) -> list[Split]:
    """Blocked cross-validation over time. Fold k tests on the samples inside window k
    (:func:`time_fold_edges`); it trains and stops early on the samples more than ``gap``
    seconds outside the window (consecutive scans see the same beacons from nearly the same
    pose: the gap keeps the window's neighbours out of training), the validation part a
    random ``val_fraction`` of those (generator seeded with 100 k + ``seed``).

    The window's beacons are NOT held out: on a run where every beacon is seen again and
    again, holding them out leaves too few samples (:func:`beacon_holdout_sizes`). So
    these folds test generalisation over TIME (new poses, new sightings of known
    beacons); :func:`beacon_folds` tests it over beacons."""
    edges = time_fold_edges(ts, n_folds)
    gap = float(gap)
    if not math.isfinite(gap) or gap < 0:
        raise ValueError(f"gap must be a finite number of seconds >= 0, got {gap!r}")
    vf = float(val_fraction)
    if not 0.0 < vf < 1.0:
        raise ValueError(f"val_fraction must lie in (0, 1), got {val_fraction!r}")
    folds = []
    for k in range(n_folds):
        lo, hi = edges[k], edges[k + 1]
        inside = (ts.t >= lo) & (ts.t <= hi) if k == n_folds - 1 else (ts.t >= lo) & (ts.t < hi)
        outside = np.flatnonzero((ts.t < lo - gap) | (ts.t > hi + gap))
        perm = np.random.default_rng(100 * k + int(seed)).permutation(outside)
        n_val = int(round(vf * perm.size))
        folds.append(Split(np.sort(perm[n_val:]), np.sort(perm[:n_val]), np.flatnonzero(inside),
                           name=f"time fold {k}: {lo:.1f}-{hi:.1f} s"))
    return folds



def beacon_holdout_sizes(ts: TrainingSet, n_folds: int = 5, *, gap: float = 2.0) -> np.ndarray:
    """Per time fold, how many samples would remain for training and validation if the
    beacons seen inside the window were held out as well (outside the window +- ``gap``,
    of beacons never seen inside it): what makes that design infeasible on a small map."""
    edges = time_fold_edges(ts, n_folds)
    sizes = []
    for k in range(n_folds):
        lo, hi = edges[k], edges[k + 1]
        inside = (ts.t >= lo) & (ts.t <= hi)
        seen = np.unique(ts.beacon[inside])
        keep = ((ts.t < lo - gap) | (ts.t > hi + gap)) & ~np.isin(ts.beacon, seen)
        sizes.append(int(keep.sum()))
    return np.array(sizes)
