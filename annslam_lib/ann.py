"""The neural-network landmark model of section 4.2, made testable (notebook 07 "ANN landmarks").

What the paper says: a back-propagation network is "trained on the SLAM landmark equation
results and the true landmarks", and its output (the landmark position) is fed to the
EKF. Read literally, the network maps the inverse observation model's landmark to the
surveyed one. Here it learns the CORRECTION to that output, so that "no correction"
(the inverse model itself) is the baseline every number is compared with.

Training samples (:func:`training_set`)
    One per beacon observation the filter used (ObservationLog status 'associated' or
    'new': the first sighting initialises a landmark, where the paper uses the network
    too). Inputs, in the order of :data:`FEATURE_NAMES`:

    ====================  ================================================================
    pose_x, pose_y        the PRIOR laser pose (predicted, before the scan's update), m
    sin_phi, cos_phi      its heading as sin / cos (no jump at +-pi)
    range, bearing        the measurement z (m, rad 0..pi from the vehicle's right)
    sin_ray, cos_ray      direction of the ray in the world, phi + bearing - pi/2
    intensity             reflectivity level 0..4 (0 where the source has none)
    width                 cluster chord width or trunk diameter, m (0 where unknown,
                          e.g. the simulator's own detections)
    lm_x, lm_y            the inverse observation l = g(prior pose, z), m
    ====================  ================================================================

    Why the prior pose: the filter can only use the network BEFORE it updates with the
    scan, so at run time only the prior exists; and the posterior pose has already been
    corrected with this very measurement against the mapped landmark, so g(posterior, z)
    is pulled toward the map (which is close to the truth): training on it would leak
    the target into the input and score the network on information it cannot have.
    Target: the surveyed / true position of the beacon, Y = target - l.

Network and training (:func:`train`): an MLP (tanh hidden layers, linear output, default
one hidden layer of 10 neurons: MATLAB nntool's ``fitnet``), inputs and outputs
standardised with the TRAINING split's mean and standard deviation, trained full batch by
Levenberg-Marquardt (nntool's default ``trainlm``; the Jacobian by back-propagation) or
Adam, with nntool's early stopping: training stops after ``max_fail`` = 6 consecutive
epochs without a new best validation MSE, and the weights of the best epoch are kept.
Deterministic on CPU (seeded generator, deterministic algorithms, one thread).

Two evaluation protocols (:func:`evaluate_chronological`, :func:`evaluate_leave_beacons_out`):
with 15 beacons a network that sees its inputs' absolute positions can simply memorise
where the beacons are. A chronological split scores it on beacons it was trained on; the
leave-beacons-out split only on beacons it has never seen. The gap between the two is
the memorisation. Neither is leak-free: the chronological test scores beacons seen in
training; leave-beacons-out trains on the SAME scans (other beacons), so a network fed the
pose can learn the filter's pose error along the route at those times and apply it to the
held-out beacons of the same scans (on the Car Park that is the likely source of its small
gain: with the measurement features alone, or the pose alone, it gains nothing; notebook 07).

Use in the EKF (``ekf_slam.run(dataset, config.replace(landmark_model='ann'),
landmark_model=model)``, notebook 08): the model turns each
detection z into a pseudo-measurement z' = h(prior pose, corrected landmark), with its own
noise (:attr:`TrainedModel.sigma_range`, ``sigma_bearing``, from validation residuals).
z' REPLACES z: the network's output is computed from z, so using both would count the
same measurement twice. :class:`InverseModel` is the identity model (z' = z).

What the per-observation RMSE hides: single observations are noisy (simulator: 0.34 m RMS
from 1 degree of bearing at up to 30 m), so a learned correction that is a few centimetres
wrong barely changes their RMSE (errors add in quadrature). But that error is a smooth
function of the geometry, nearly the same for every sighting of a beacon, and the filter,
which averages a hundred sightings per beacon, cannot average it away: the map can get
worse while the observation RMSE says "no change" (tests/test_ann.py, notebook 08).
"""
from __future__ import annotations

import contextlib
import math
import numbers
import pickle
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .ekf_slam import STATUS
from .geometry import wrap_angle
from .map_metrics import match_landmarks
from .observation import inverse_observe, observe

try:                                      # torch is the optional 'ann' extra
    import torch
except ImportError:                       # pragma: no cover - exercised without torch only
    torch = None

__all__ = ["FEATURE_NAMES", "MEASUREMENT_FEATURES", "USED_STATUS", "TrainingSet", "encode",
           "training_set", "Split", "chronological_split", "beacon_folds", "TrainConfig",
           "TrainedModel", "train", "save", "load", "UnsafeModelFile", "InverseModel",
           "Evaluation", "evaluate", "evaluate_chronological", "evaluate_leave_beacons_out",
           "split_rmse", "error_histogram", "regression", "with_features", "SPLITS",
           "ALGORITHMS"]

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
#: Training algorithms of :class:`TrainConfig`.
ALGORITHMS = ("lm", "adam")
_COL = {name: i for i, name in enumerate(FEATURE_NAMES)}
_FORMAT = "annslam-ann-v1"


def _need_torch() -> None:
    if torch is None:
        raise ImportError("annslam_lib.ann needs PyTorch, the CPU build: run ./course.sh setup in "
                          "the course folder (it installs torch 2.13.0+cpu)")


# --------------------------------------------------------------------------- training set

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
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    n = z.shape[0]
    pose = np.broadcast_to(np.asarray(pose, dtype=float), (n, 3)) if np.ndim(pose) == 1 \
        else np.asarray(pose, dtype=float)
    if pose.shape != (n, 3):
        raise ValueError(f"pose must be (3,) or ({n}, 3), got {pose.shape}")
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(z))):
        raise ValueError("pose and z must be finite")
    level = np.zeros(n) if intensity is None else np.asarray(intensity, dtype=float).reshape(-1)
    w = np.zeros(n) if width is None else np.asarray(width, dtype=float).reshape(-1)
    if level.shape != (n,) or w.shape != (n,):
        raise ValueError(f"intensity and width must have {n} entries, got {level.shape}, {w.shape}")
    w = np.where(np.isnan(w), 0.0, w)
    if not np.all(np.isfinite(level)) or not np.all(np.isfinite(w)):
        raise ValueError("intensity and width must be finite (NaN width is read as 0)")
    base = inverse_observe(pose, z)[0] if n else np.empty((0, 2))
    ray = pose[:, 2] + z[:, 1] - np.pi / 2
    X = np.column_stack([pose[:, 0], pose[:, 1], np.sin(pose[:, 2]), np.cos(pose[:, 2]),
                         z[:, 0], z[:, 1], np.sin(ray), np.cos(ray), level, w, base])
    return X, base


def training_set(result, dataset, *, max_distance: float = 1.0, use_truth_ids: bool | None = None
                 ) -> TrainingSet:
    """Training samples from an EKF-SLAM run (``ekf_slam.run``) on ``dataset``.

    Every observation with status 'associated' or 'new' that belongs to a final map
    landmark becomes a sample: inputs from its PRIOR pose and measurement (``encode``),
    target the true position of its beacon. Which beacon: the simulator's true id of the
    detection (``use_truth_ids`` None -> whenever the detections carry ids); otherwise the
    surveyed beacon matched one-to-one (Hungarian, ``map_metrics.match_landmarks``) to
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


# --------------------------------------------------------------------------- splits

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


# --------------------------------------------------------------------------- network

@dataclass(frozen=True)
class TrainConfig:
    """Settings of :func:`train`.

    hidden: neurons per hidden layer (tanh), default (10,) like nntool's ``fitnet``.
    features: the input columns (names from :data:`FEATURE_NAMES`; None = all).
    algorithm: 'lm' (Levenberg-Marquardt, nntool's ``trainlm``: mu, mu_dec, mu_inc,
    mu_max) or 'adam' (full batch, learning rate ``lr``).
    max_epochs: upper bound on epochs; max_fail: consecutive epochs without a new best
    validation MSE before stopping (nntool: 6); min_grad: stop when the gradient norm of
    the (normalised) training loss falls below it. seed: weight initialisation.
    zero_output: start the output layer at zero (epoch 0 = the inverse model plus the
    training mean correction) instead of random weights as nntool (default). Either way,
    with nothing to learn the network returns a correction of a few centimetres that
    depends smoothly on the geometry: invisible in the RMSE of single observations (it
    adds in quadrature to their noise) but a systematic error per beacon that the filter
    cannot average away (notebook 08).
    """

    hidden: tuple = (10,)
    features: tuple | None = None
    algorithm: str = "lm"
    lr: float = 0.01
    mu: float = 1e-3
    mu_dec: float = 0.1
    mu_inc: float = 10.0
    mu_max: float = 1e10
    max_epochs: int = 1000
    max_fail: int = 6
    min_grad: float = 1e-7
    seed: int = 0
    zero_output: bool = False

    def __post_init__(self) -> None:
        hidden = tuple(self.hidden)
        if not hidden or any(isinstance(h, bool) or not isinstance(h, numbers.Integral) or h < 1
                             for h in hidden):
            raise ValueError(f"TrainConfig.hidden must be positive integers, got {self.hidden!r}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in hidden))
        if self.features is not None:
            feats = tuple(self.features)
            bad = [f for f in feats if f not in _COL]
            if bad or not feats or len(set(feats)) != len(feats):
                raise ValueError(f"TrainConfig.features must be distinct names from {FEATURE_NAMES}, "
                                 f"got {self.features!r}")
            object.__setattr__(self, "features", feats)
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"TrainConfig.algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        for name in ("lr", "mu", "mu_max", "min_grad"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v < 0 \
                    or (v == 0 and name != "min_grad"):
                raise ValueError(f"TrainConfig.{name} must be a positive finite number, got {v!r}")
        if not (0 < self.mu_dec < 1) or not (self.mu_inc > 1):
            raise ValueError(f"TrainConfig needs 0 < mu_dec < 1 < mu_inc, got {self.mu_dec}, {self.mu_inc}")
        if not isinstance(self.zero_output, bool):
            raise ValueError(f"TrainConfig.zero_output must be a bool, got {self.zero_output!r}")
        for name, lo in (("max_epochs", 0), ("max_fail", 1), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < lo:
                raise ValueError(f"TrainConfig.{name} must be an integer >= {lo}, got {v!r}")

    @property
    def columns(self) -> tuple:
        return FEATURE_NAMES if self.features is None else self.features

    def as_dict(self) -> dict:
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d["hidden"] = list(self.hidden)
        d["features"] = None if self.features is None else list(self.features)
        return d


@contextlib.contextmanager
def _deterministic():
    """One thread and deterministic kernels while inside (restored after): the same
    seed then gives bitwise the same numbers."""
    _need_torch()
    threads, det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(det)
        torch.set_num_threads(threads)


def _shapes(n_in: int, hidden: tuple) -> list[tuple[int, int]]:
    sizes = [n_in, *hidden, 2]
    return [(sizes[i + 1], sizes[i]) for i in range(len(sizes) - 1)]


def _forward(theta, X, shapes):
    """MLP on the flat parameter vector theta: tanh hidden layers, linear output."""
    k = 0
    h = X
    for i, (o, n) in enumerate(shapes):
        W = theta[k:k + o * n].reshape(o, n)
        k += o * n
        b = theta[k:k + o]
        k += o
        h = h @ W.T + b
        if i < len(shapes) - 1:
            h = torch.tanh(h)
    return h


def _jacobian(theta, X, shapes):
    """Jacobian (2 n, P) of the outputs (n, 2), flattened sample-major, with respect to
    theta, by back-propagation: the output deltas are pushed back through the layers
    (delta_l = (delta_{l+1} W_{l+1}) * (1 - h_l^2)) and dy/dW_l = delta_l h_{l-1}^T,
    dy/db_l = delta_l, for both outputs at once. Equals ``torch.func.jacfwd`` of
    :func:`_forward` (tests) at a fraction of its cost."""
    Ws, hs, k, h = [], [X], 0, X
    for i, (o, n) in enumerate(shapes):
        W = theta[k:k + o * n].reshape(o, n)
        b = theta[k + o * n:k + o * n + o]
        k += o * n + o
        Ws.append(W)
        h = h @ W.T + b
        if i < len(shapes) - 1:
            h = torch.tanh(h)
            hs.append(h)
    m = X.shape[0]
    delta = torch.eye(2, dtype=X.dtype).expand(m, 2, 2)          # (m, output k, units)
    blocks = []
    for i in range(len(shapes) - 1, -1, -1):
        prev = hs[i]                                             # input of layer i
        dW = delta[:, :, :, None] * prev[:, None, None, :]       # (m, 2, o, n)
        blocks.append((dW.reshape(m, 2, -1), delta))
        if i > 0:
            delta = (delta @ Ws[i]) * (1.0 - hs[i] * hs[i])[:, None, :]
    parts = []
    for dW, db in reversed(blocks):
        parts += [dW, db]
    return torch.cat(parts, dim=2).reshape(2 * m, -1)


def _init(shapes, seed: int, zero_output: bool = False):
    """Uniform(+-1/sqrt(fan_in)) weights and biases from a private seeded generator; the
    output layer zero if ``zero_output`` (drawn anyway, so the hidden layers do not
    depend on the choice)."""
    g = torch.Generator().manual_seed(seed)
    parts = []
    for o, n in shapes:
        s = 1.0 / math.sqrt(n)
        parts.append((torch.rand(o * n + o, generator=g, dtype=torch.float64) * 2 - 1) * s)
    if zero_output:
        parts[-1] = torch.zeros_like(parts[-1])
    return torch.cat(parts)


@dataclass
class TrainedModel:
    """A trained landmark network (:func:`train`, :func:`load`).

    predict(X) -> (n, 2) landmark positions = base + predicted correction, X with the
    columns of :data:`FEATURE_NAMES`. history: per-epoch arrays 'epoch', 'train', 'val',
    'test' (MSE of the position in m^2 per coordinate, nntool's performance plot; 'test'
    NaN without a test part) and 'mu' (LM damping); best_epoch; epochs (last epoch run);
    stop_reason ('max_fail', 'max_epochs', 'min_grad', 'mu_max'); seconds (wall time).
    sigma_range (m), sigma_bearing (rad): RMS of the measurement-space residuals
    h(prior pose, true beacon) - h(prior pose, predicted landmark) on the validation part
    (the pseudo-measurement noise the EKF uses; it includes the prior pose error, which the
    filter also counts through H_pose P H_pose^T, so it is conservative).
    """

    config: TrainConfig
    theta: object
    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    history: dict = field(default_factory=dict)
    best_epoch: int = 0
    epochs: int = 0
    stop_reason: str = ""
    seconds: float = 0.0
    sigma_range: float = math.nan
    sigma_bearing: float = math.nan

    def __post_init__(self) -> None:
        _need_torch()
        cols = self.config.columns
        self._cols = np.array([_COL[c] for c in cols])
        self._shapes = _shapes(len(cols), self.config.hidden)
        n_par = sum(o * n + o for o, n in self._shapes)
        theta = torch.as_tensor(self.theta, dtype=torch.float64).detach().clone().reshape(-1)
        if theta.numel() != n_par:
            raise ValueError(f"model has {theta.numel()} parameters, its configuration needs {n_par}")
        self.theta = theta
        for name, size in (("x_mean", len(cols)), ("x_std", len(cols)), ("y_mean", 2), ("y_std", 2)):
            a = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if a.shape != (size,) or not np.all(np.isfinite(a)):
                raise ValueError(f"model {name} must be {size} finite numbers, got shape {a.shape}")
            if name.endswith("std") and np.any(a <= 0):
                raise ValueError(f"model {name} must be positive")
            setattr(self, name, a)

    @property
    def feature_names(self) -> tuple:
        return self.config.columns

    def correction(self, X) -> np.ndarray:
        """Predicted correction (n, 2) to the inverse observation, m."""
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != len(FEATURE_NAMES):
            raise ValueError(f"X must be (n, {len(FEATURE_NAMES)}) with columns FEATURE_NAMES, "
                             f"got shape {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("X contains NaN or infinite values")
        xn = (X[:, self._cols] - self.x_mean) / self.x_std
        with _deterministic(), torch.no_grad():
            out = _forward(self.theta, torch.from_numpy(xn), self._shapes).numpy()
        return out * self.y_std + self.y_mean

    def predict(self, X) -> np.ndarray:
        """Landmark positions (n, 2): the inverse observation (X's lm_x, lm_y) corrected."""
        X = np.asarray(X, dtype=float)
        c = self.correction(X)
        return X[:, [_COL["lm_x"], _COL["lm_y"]]] + c

    def pseudo_measurement(self, pose, z, intensity=None, width=None) -> np.ndarray:
        """The EKF's pseudo-measurements z' (n, 2) = h(pose, predicted landmark) for
        detections z (n, 2) seen from the prior ``pose`` (3,)."""
        X, _ = encode(pose, z, intensity, width)
        if X.shape[0] == 0:
            return np.empty((0, 2))
        return observe(np.asarray(pose, dtype=float), self.predict(X))[0]

    @property
    def sigmas(self) -> tuple[float, float]:
        return self.sigma_range, self.sigma_bearing


class InverseModel:
    """The identity landmark model: z' = z (the plain inverse observation), with the given
    noise. With the sensor's own sigmas the ANN-enhanced filter must equal the plain one."""

    def __init__(self, sigma_range: float, sigma_bearing: float) -> None:
        for name, v in (("sigma_range", sigma_range), ("sigma_bearing", sigma_bearing)):
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (0 < v < math.inf):
                raise ValueError(f"InverseModel.{name} must be a positive finite number, got {v!r}")
        self.sigma_range, self.sigma_bearing = float(sigma_range), float(sigma_bearing)

    def predict(self, X) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        return X[:, [_COL["lm_x"], _COL["lm_y"]]].copy()

    def pseudo_measurement(self, pose, z, intensity=None, width=None) -> np.ndarray:
        return np.asarray(z, dtype=float).reshape(-1, 2).copy()

    @property
    def sigmas(self) -> tuple[float, float]:
        return self.sigma_range, self.sigma_bearing


def _residual_sigmas(model, ts: TrainingSet, index) -> tuple[float, float]:
    if ts.pose is None or index.size == 0:
        return math.nan, math.nan
    pose = ts.pose[index]
    pred = model.predict(ts.X[index])
    z_true = observe(pose, ts.target[index])[0]
    z_pred = observe(pose, pred)[0]
    d = z_true - z_pred
    d[:, 1] = wrap_angle(d[:, 1])
    return float(np.sqrt(np.mean(d[:, 0] ** 2))), float(np.sqrt(np.mean(d[:, 1] ** 2)))


def train(train_set: TrainingSet, split: Split, config: TrainConfig | None = None) -> TrainedModel:
    """Train the landmark network on ``split.train``, early-stopping on ``split.val``;
    ``split.test`` is only recorded (module docstring; :class:`TrainConfig`).

    Epoch 0 is the initial network. Each epoch: one full-batch LM step (the damping mu is
    raised until the training loss decreases; beyond mu_max training stops) or one Adam
    step; then the validation MSE. A new best is a strictly lower validation MSE; after
    ``max_fail`` epochs without one, training stops and the best epoch's weights are
    returned. Deterministic (same data and seed -> bitwise the same model).
    """
    _need_torch()
    cfg = TrainConfig() if config is None else config
    if not isinstance(cfg, TrainConfig):
        raise ValueError(f"config must be a TrainConfig, got {type(cfg).__name__}")
    if not isinstance(train_set, TrainingSet):
        raise ValueError(f"train_set must be a TrainingSet, got {type(train_set).__name__}")
    if not isinstance(split, Split):
        raise ValueError(f"split must be a Split, got {type(split).__name__}")
    n = len(train_set)
    for part in SPLITS:
        idx = split.part(part)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"split part {part!r} indexes outside the {n} samples")
    t_start = time.perf_counter()
    cols = np.array([_COL[c] for c in cfg.columns])
    X = train_set.X[:, cols]
    Y = train_set.Y
    tr = split.train
    x_mean, x_std = X[tr].mean(axis=0), X[tr].std(axis=0)
    x_std = np.where(x_std > 1e-12, x_std, 1.0)            # constant input: centred to 0
    y_mean, y_std = Y[tr].mean(axis=0), Y[tr].std(axis=0)
    y_std = np.where(y_std > 1e-12, y_std, 1.0)
    Xn = torch.from_numpy((X - x_mean) / x_std)
    Yn = torch.from_numpy((Y - y_mean) / y_std)
    ys = torch.from_numpy(y_std)
    shapes = _shapes(cols.size, cfg.hidden)
    parts = {p: torch.from_numpy(split.part(p)) for p in SPLITS}

    with _deterministic():
        theta = _init(shapes, cfg.seed, cfg.zero_output)
        Xtr, Ytr = Xn[parts["train"]], Yn[parts["train"]]

        def mse_m2(th) -> dict:
            """Position MSE in m^2 per coordinate, per part (corrections de-normalised)."""
            with torch.no_grad():
                err = (_forward(th, Xn, shapes) - Yn) * ys
                sq = err * err
                return {p: (float(sq[parts[p]].mean()) if parts[p].numel() else math.nan)
                        for p in SPLITS}

        def loss(th):
            r = _forward(th, Xtr, shapes) - Ytr
            return (r * r).mean()

        hist = {p: [] for p in SPLITS}
        hist["mu"] = []
        perf = mse_m2(theta)
        for p in SPLITS:
            hist[p].append(perf[p])
        hist["mu"].append(cfg.mu)
        best, best_val, best_epoch = theta.clone(), perf["val"], 0
        fails, epoch, reason = 0, 0, "max_epochs"
        mu = cfg.mu
        opt = None
        if cfg.algorithm == "adam":
            theta = theta.clone().requires_grad_(True)
            opt = torch.optim.Adam([theta], lr=cfg.lr)
        n_res = Ytr.numel()
        while epoch < cfg.max_epochs:
            if cfg.algorithm == "lm":
                res = (_forward(theta, Xtr, shapes) - Ytr).reshape(-1)
                J = _jacobian(theta, Xtr, shapes)
                g = J.T @ res
                if float(torch.linalg.vector_norm(2.0 * g / n_res)) < cfg.min_grad:
                    reason = "min_grad"
                    break
                JTJ = J.T @ J
                f0 = float(res @ res)
                eye = torch.eye(theta.numel(), dtype=torch.float64)
                while True:
                    step = torch.linalg.solve(JTJ + mu * eye, g)
                    cand = theta - step
                    r1 = _forward(cand, Xtr, shapes).reshape(-1) - Ytr.reshape(-1)
                    if float(r1 @ r1) < f0:
                        theta = cand
                        mu = max(mu * cfg.mu_dec, 1e-20)
                        break
                    mu *= cfg.mu_inc
                    if mu > cfg.mu_max:
                        break
                if mu > cfg.mu_max:
                    reason = "mu_max"
                    break
            else:
                opt.zero_grad()
                lo = loss(theta)
                lo.backward()
                if float(torch.linalg.vector_norm(theta.grad)) < cfg.min_grad:
                    reason = "min_grad"
                    break
                opt.step()
            epoch += 1
            th = theta.detach()
            perf = mse_m2(th)
            for p in SPLITS:
                hist[p].append(perf[p])
            hist["mu"].append(mu)
            if perf["val"] < best_val:
                best, best_val, best_epoch, fails = th.clone(), perf["val"], epoch, 0
            else:
                fails += 1
                if fails >= cfg.max_fail:
                    reason = "max_fail"
                    break
    history = {p: np.array(v) for p, v in hist.items()}
    history["epoch"] = np.arange(history["train"].size)
    model = TrainedModel(config=cfg, theta=best, x_mean=x_mean, x_std=x_std, y_mean=y_mean,
                         y_std=y_std, history=history, best_epoch=best_epoch, epochs=epoch,
                         stop_reason=reason)
    model.sigma_range, model.sigma_bearing = _residual_sigmas(model, train_set, split.val)
    model.seconds = time.perf_counter() - t_start
    return model


# --------------------------------------------------------------------------- save / load

class UnsafeModelFile(ValueError):
    """A model file that is not a plain tensors-and-dicts file of this module: refused
    without running any code it may contain."""


def save(model: TrainedModel, path) -> Path:
    """Write the model (weights, normalisation, config, history, noise) as plain tensors,
    numbers, strings, lists and dicts with ``torch.save``; :func:`load` reads it back
    with ``weights_only=True``."""
    _need_torch()
    if not isinstance(model, TrainedModel):
        raise ValueError(f"can only save a TrainedModel, got {type(model).__name__}")
    t = lambda a: torch.as_tensor(np.asarray(a, dtype=float))  # noqa: E731
    payload = {
        "format": _FORMAT,
        "config": model.config.as_dict(),
        "theta": model.theta.detach().clone(),
        "x_mean": t(model.x_mean), "x_std": t(model.x_std),
        "y_mean": t(model.y_mean), "y_std": t(model.y_std),
        "history": {k: t(v) for k, v in model.history.items()},
        "best_epoch": int(model.best_epoch), "epochs": int(model.epochs),
        "stop_reason": str(model.stop_reason), "seconds": float(model.seconds),
        "sigma_range": float(model.sigma_range), "sigma_bearing": float(model.sigma_bearing),
    }
    path = Path(path)
    torch.save(payload, path)
    return path


def load(path) -> TrainedModel:
    """Read a model written by :func:`save`. Uses ``torch.load(weights_only=True)``, which
    never unpickles arbitrary objects: a file holding anything else raises
    :class:`UnsafeModelFile` (no code from it runs). ValueError for a damaged file."""
    _need_torch()
    path = Path(path)
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise UnsafeModelFile(f"{path}: refused, not a plain weights file (it holds objects "
                              f"that weights_only loading does not allow): {e}") from e
    except (RuntimeError, EOFError, OSError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not a readable model file ({e})") from e
    if not isinstance(d, dict) or d.get("format") != _FORMAT:
        raise ValueError(f"{path}: not an annslam ANN model file (format {_FORMAT!r} expected)")
    try:
        cfg = dict(d["config"])
        cfg["hidden"] = tuple(cfg["hidden"])
        if cfg["features"] is not None:
            cfg["features"] = tuple(cfg["features"])
        model = TrainedModel(
            config=TrainConfig(**cfg), theta=d["theta"],
            x_mean=d["x_mean"].numpy(), x_std=d["x_std"].numpy(),
            y_mean=d["y_mean"].numpy(), y_std=d["y_std"].numpy(),
            history={k: v.numpy() for k, v in d["history"].items()},
            best_epoch=int(d["best_epoch"]), epochs=int(d["epochs"]),
            stop_reason=str(d["stop_reason"]), seconds=float(d["seconds"]),
            sigma_range=float(d["sigma_range"]), sigma_bearing=float(d["sigma_bearing"]))
    except (KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path}: model file is missing or has malformed field ({e!r})") from e
    return model


# --------------------------------------------------------------------------- evaluation

def split_rmse(model, ts: TrainingSet, split: Split) -> dict:
    """Per part: n, RMSE (m) of the inverse observation (baseline) and of the ANN-corrected
    position against the true beacon (Euclidean error)."""
    out = {}
    for p in SPLITS:
        idx = split.part(p)
        if idx.size == 0:
            out[p] = dict(n=0, rmse_base=math.nan, rmse_ann=math.nan)
            continue
        eb = np.hypot(*(ts.base[idx] - ts.target[idx]).T)
        ea = np.hypot(*(model.predict(ts.X[idx]) - ts.target[idx]).T)
        out[p] = dict(n=int(idx.size), rmse_base=_rms(eb), rmse_ann=_rms(ea))
    return out


def _rms(e) -> float:
    return float(np.sqrt(np.mean(np.square(e)))) if np.size(e) else math.nan


@dataclass
class Evaluation:
    """Held-out errors of one protocol.

    protocol: 'chronological' or 'leave_beacons_out'; index (n,): the scored (test) samples,
    fold (n,): the fold each was scored in; error_base, error_ann (n,): Euclidean errors (m)
    of the inverse observation and of the ANN against the true beacon; rmse_base, rmse_ann;
    folds: per fold dict (name, beacons tested, n, rmse_base, rmse_ann, best_epoch, epochs,
    seconds, parts = :func:`split_rmse`); models: the trained models; splits.
    """

    protocol: str
    index: np.ndarray
    fold: np.ndarray
    error_base: np.ndarray
    error_ann: np.ndarray
    rmse_base: float
    rmse_ann: float
    folds: list
    models: list
    splits: list

    @property
    def improvement(self) -> float:
        """Relative RMSE reduction, 1 - rmse_ann / rmse_base (negative: the ANN is worse)."""
        return 1.0 - self.rmse_ann / self.rmse_base

    def summary(self) -> str:
        return (f"{self.protocol}: {self.index.size} held-out samples in {len(self.folds)} "
                f"fold(s); RMSE inverse model {self.rmse_base:.3f} m, ANN {self.rmse_ann:.3f} m "
                f"({100 * self.improvement:+.1f} %)")


def evaluate(ts: TrainingSet, splits, config: TrainConfig | None = None, *,
             protocol: str = "") -> Evaluation:
    """Train one model per split and score it on that split's test part."""
    splits = list(splits)
    if not splits:
        raise ValueError("no splits to evaluate")
    idx, fold, eb, ea, folds, models = [], [], [], [], [], []
    for k, sp in enumerate(splits):
        if sp.test.size == 0:
            raise ValueError(f"split {sp.name!r} has no test samples")
        m = train(ts, sp, config)
        e_b = np.hypot(*(ts.base[sp.test] - ts.target[sp.test]).T)
        e_a = np.hypot(*(m.predict(ts.X[sp.test]) - ts.target[sp.test]).T)
        idx.append(sp.test)
        fold.append(np.full(sp.test.size, k))
        eb.append(e_b)
        ea.append(e_a)
        models.append(m)
        folds.append(dict(name=sp.name, beacons=np.unique(ts.beacon[sp.test]), n=int(sp.test.size),
                          rmse_base=_rms(e_b), rmse_ann=_rms(e_a), best_epoch=m.best_epoch,
                          epochs=m.epochs, seconds=m.seconds, parts=split_rmse(m, ts, sp)))
    eb, ea = np.concatenate(eb), np.concatenate(ea)
    return Evaluation(protocol=protocol, index=np.concatenate(idx), fold=np.concatenate(fold),
                      error_base=eb, error_ann=ea, rmse_base=_rms(eb), rmse_ann=_rms(ea),
                      folds=folds, models=models, splits=splits)


def evaluate_chronological(ts: TrainingSet, config: TrainConfig | None = None,
                           fractions=(0.7, 0.15, 0.15)) -> Evaluation:
    """Protocol 1: train on the first 70 % of the run, stop early on the next 15 %, score on
    the last 15 % (:func:`chronological_split`). The test beacons were seen in training."""
    return evaluate(ts, [chronological_split(ts, fractions)], config, protocol="chronological")


def evaluate_leave_beacons_out(ts: TrainingSet, config: TrainConfig | None = None,
                               n_folds: int = 5, seed: int = 0) -> Evaluation:
    """Protocol 2: leave-beacons-out cross-validation (:func:`beacon_folds`): every sample
    is scored once, by a network that never saw its beacon."""
    return evaluate(ts, beacon_folds(ts, n_folds, seed), config, protocol="leave_beacons_out")


# --------------------------------------------------------------------------- figures' data

def _outputs(model, ts: TrainingSet, idx, kind: str):
    if kind == "position":
        return model.predict(ts.X[idx]), ts.target[idx]
    if kind == "correction":
        return model.predict(ts.X[idx]) - ts.base[idx], ts.Y[idx]
    raise ValueError(f"kind must be 'position' or 'correction', got {kind!r}")


def error_histogram(model, ts: TrainingSet, split: Split, bins: int = 20) -> dict:
    """nntool's error histogram (paper Figure 6): errors = target - output per coordinate
    (m), ``bins`` equal bins over the range of all parts together. Returns dict(edges
    (bins + 1,), centres, counts = {part: (bins,)}, errors = {part: (2 n,)})."""
    if isinstance(bins, bool) or not isinstance(bins, numbers.Integral) or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    errors = {}
    for p in SPLITS:
        out, tgt = _outputs(model, ts, split.part(p), "position")
        errors[p] = (tgt - out).ravel()
    allerr = np.concatenate(list(errors.values()))
    lo, hi = (float(allerr.min()), float(allerr.max())) if allerr.size else (-1.0, 1.0)
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    edges = np.linspace(lo, hi, bins + 1)
    counts = {p: np.histogram(e, bins=edges)[0] for p, e in errors.items()}
    return dict(edges=edges, centres=0.5 * (edges[1:] + edges[:-1]), counts=counts, errors=errors)


def regression(model, ts: TrainingSet, split: Split, kind: str = "position") -> dict:
    """nntool's regression plot (paper Figure 8) per part and for all parts: outputs vs
    targets (both coordinates pooled), least-squares line output = slope * target +
    intercept and the correlation R. kind 'position': landmark positions (what the paper
    plots: R is close to 1 for ANY sensible estimate, the positions span tens of metres);
    'correction': the correction alone (what the network adds; R near 0 = nothing learned).
    Returns {part or 'all': dict(outputs, targets, slope, intercept, r, n)}."""
    res = {}
    parts = {p: split.part(p) for p in SPLITS}
    parts["all"] = np.concatenate([split.train, split.val, split.test])
    for p, idx in parts.items():
        out, tgt = _outputs(model, ts, idx, kind)
        o, g = out.ravel(), tgt.ravel()
        if o.size >= 2 and np.ptp(g) > 0:
            slope, intercept = np.polyfit(g, o, 1)
            r = float(np.corrcoef(g, o)[0, 1]) if np.ptp(o) > 0 else math.nan
        else:
            slope = intercept = r = math.nan
        res[p] = dict(outputs=o, targets=g, slope=float(slope), intercept=float(intercept), r=r,
                      n=int(idx.size))
    return res


def with_features(config: TrainConfig, features) -> TrainConfig:
    """``config`` with another input column set (e.g. :data:`MEASUREMENT_FEATURES`)."""
    return replace(config, features=None if features is None else tuple(features))
