"""The landmark network and its training (notebook 07; design in :mod:`annslam_lib.ann`):
an MLP like MATLAB nntool's ``fitnet``, trained by Levenberg-Marquardt or Adam with
nntool's early stopping; the pieces the chapter derives (:func:`forward`,
:func:`train_loop`, :func:`mapminmax`) as the references of its exercises.
"""
from __future__ import annotations

import contextlib
import math
import numbers
import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..models.geometry import wrap_angle
from ..models.observation import observe, observe_values
from .samples import COLUMN, FEATURE_NAMES, SPLITS, Split, TrainingSet, encode

try:                                      # torch is the optional 'ann' extra
    import torch
except ImportError:                       # pragma: no cover - exercised without torch only
    torch = None

__all__ = ["ALGORITHMS", "TrainConfig", "TrainedModel", "InverseModel", "train",
           "with_features", "forward", "train_loop", "mapminmax", "mapminmax_reverse",
           "one_torch_thread"]

#: Training algorithms of :class:`TrainConfig`.
ALGORITHMS = ("lm", "adam")


def require_torch() -> None:
    if torch is None:
        raise ImportError("annslam_lib.ann needs PyTorch, the CPU build: run ./course.sh setup in "
                          "the course folder (it installs torch 2.13.0+cpu)")



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
            bad = [f for f in feats if f not in COLUMN]
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
            raise TypeError(f"TrainConfig.zero_output must be a bool, got {self.zero_output!r}")
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
    require_torch()
    threads, det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(1)
    _set_deterministic(True)
    try:
        yield
    finally:
        _set_deterministic(det)
        torch.set_num_threads(threads)


def _set_deterministic(mode: bool) -> None:
    """``torch.use_deterministic_algorithms(mode)`` without its import of
    ``torch._inductor.config``, which loads torch._dynamo (1.2 s on the first call, more
    than the training it guards). The course never compiles, so only the eager flag
    matters; where inductor is already loaded, or the private setter is gone in another
    torch, the public call is made."""
    setter = getattr(torch._C, "_set_deterministic_algorithms", None)
    if setter is None or "torch._inductor.config" in sys.modules:
        torch.use_deterministic_algorithms(mode)
    else:
        setter(mode, warn_only=False)



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



def _forward_numpy(theta: np.ndarray, X: np.ndarray, shapes) -> np.ndarray:
    """:func:`_forward` in numpy, for inference: the filter asks for one scan's few
    detections at a time, where torch's per-call overhead is most of the cost (notebook 08's
    transfers: 0.6 ms a call before). Same operations in the same order, float64."""
    k, h = 0, X
    for i, (o, n) in enumerate(shapes):
        W = theta[k:k + o * n].reshape(o, n)
        k += o * n
        h = h @ W.T + theta[k:k + o]
        k += o
        if i < len(shapes) - 1:
            h = np.tanh(h)
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
        require_torch()
        cols = self.config.columns
        self._cols = np.array([COLUMN[c] for c in cols])
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
        return _forward_numpy(self.theta.detach().numpy(), xn, self._shapes) * self.y_std + self.y_mean

    def predict(self, X) -> np.ndarray:
        """Landmark positions (n, 2): the inverse observation (X's lm_x, lm_y) corrected."""
        X = np.asarray(X, dtype=float)
        c = self.correction(X)
        return X[:, [COLUMN["lm_x"], COLUMN["lm_y"]]] + c

    def pseudo_measurement(self, pose, z, intensity=None, width=None) -> np.ndarray:
        """The EKF's pseudo-measurements z' (n, 2) = h(pose, predicted landmark) for
        detections z (n, 2) seen from the prior ``pose`` (3,)."""
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (3,):
            raise ValueError(f"pose must be one laser pose (3,), got shape {pose.shape}")
        X, _ = encode(pose, z, intensity, width)
        if X.shape[0] == 0:
            return np.empty((0, 2))
        return observe_values(pose, self.predict(X))

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
        return X[:, [COLUMN["lm_x"], COLUMN["lm_y"]]].copy()

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
    require_torch()
    cfg = TrainConfig() if config is None else config
    if not isinstance(cfg, TrainConfig):
        raise TypeError(f"config must be a TrainConfig, got {type(cfg).__name__}")
    if not isinstance(train_set, TrainingSet):
        raise TypeError(f"train_set must be a TrainingSet, got {type(train_set).__name__}")
    if not isinstance(split, Split):
        raise TypeError(f"split must be a Split, got {type(split).__name__}")
    n = len(train_set)
    for part in SPLITS:
        idx = split.part(part)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"split part {part!r} indexes outside the {n} samples")
    if split.train.size < 2:
        raise ValueError(f"the training part has {split.train.size} sample(s): at least 2 are "
                         "needed (their mean and spread normalise the inputs and outputs); "
                         "a smaller training set cannot train a network")
    t_start = time.perf_counter()
    cols = np.array([COLUMN[c] for c in cfg.columns])
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



def with_features(config: TrainConfig, features) -> TrainConfig:
    """``config`` with another input column set (e.g. :data:`MEASUREMENT_FEATURES`)."""
    return replace(config, features=None if features is None else tuple(features))



# ------------------------------------------------------------ the chapter's references

@contextlib.contextmanager
def one_torch_thread():
    """One torch thread while inside (restored after), so that runs repeat to the bit."""
    require_torch()

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)



def forward(X, W1, b1, W2, b2, x_mean, x_std, y_mean, y_std) -> np.ndarray:
    """The landmark network's output (n, 2), the correction in metres (notebook 07,
    section 1): x~ = (x - x_mean) / x_std, y~ = W2 tanh(W1 x~ + b1) + b2, y = y~ y_std +
    y_mean. X (n, 12) with the columns of ``FEATURE_NAMES``; W1 (h, 12), b1 (h,),
    W2 (2, h), b2 (2,). Computed by ``ann.TrainedModel.correction`` with these weights
    (its flat parameter vector is W1, b1, W2, b2 in that order, row-major)."""
    W1, W2 = np.asarray(W1, dtype=float), np.asarray(W2, dtype=float)
    b1, b2 = np.asarray(b1, dtype=float).ravel(), np.asarray(b2, dtype=float).ravel()
    h = W1.shape[0]
    if W1.shape != (h, len(FEATURE_NAMES)) or b1.shape != (h,) or W2.shape != (2, h) \
            or b2.shape != (2,):
        raise ValueError(f"weights must be W1 (h, {len(FEATURE_NAMES)}), b1 (h,), W2 (2, h), "
                         f"b2 (2,); got {W1.shape}, {b1.shape}, {W2.shape}, {b2.shape}")
    require_torch()
    theta = np.concatenate([W1.ravel(), b1, W2.ravel(), b2])
    model = TrainedModel(config=TrainConfig(hidden=(h,)), theta=theta, x_mean=x_mean,
                             x_std=x_std, y_mean=y_mean, y_std=y_std)
    # model.correction(X), minus its switch to deterministic kernels: the first switch imports
    # half of torch (seconds), and a forward pass on the CPU is deterministic anyway
    # (tests/test_grading_ann.py compares the two)
    X = np.asarray(X, dtype=float)
    xn = (X[:, model._cols] - model.x_mean) / model.x_std
    with one_torch_thread(), torch.no_grad():
        out = _forward(model.theta, torch.from_numpy(xn), model._shapes).numpy()
    return out * model.y_std + model.y_mean



def _minmax_args(x, xmin, xmax):
    x = np.asarray(x, dtype=float)
    xmin, xmax = np.asarray(xmin, dtype=float), np.asarray(xmax, dtype=float)
    if x.ndim != 2 or xmin.shape != (x.shape[1],) or xmax.shape != (x.shape[1],):
        raise ValueError(f"x must be (n, F) and xmin, xmax (F,); got {x.shape}, {xmin.shape}, "
                         f"{xmax.shape}")
    if not (np.all(np.isfinite(xmin)) and np.all(np.isfinite(xmax))) or np.any(xmax < xmin):
        raise ValueError("xmin and xmax must be finite with xmin <= xmax")
    return x, xmin, xmax



def mapminmax(x, xmin, xmax) -> np.ndarray:
    """nntool's default input/output processing ``mapminmax('apply', x, PS)`` (notebook 07,
    exercise 7.3): each column j of x (n, F) mapped linearly so that xmin[j] -> -1 and
    xmax[j] -> +1, y = 2 (x - xmin) / (xmax - xmin) - 1, with the bounds of the TRAINING
    part (later inputs may fall outside [-1, 1]; nothing is clipped). A constant column
    (xmax = xmin) passes through unchanged, as MATLAB documents (y = x)."""
    x, xmin, xmax = _minmax_args(x, xmin, xmax)
    span = xmax - xmin
    const = span == 0
    y = 2.0 * (x - xmin) / np.where(const, 1.0, span) - 1.0
    return np.where(const, x, y)



def mapminmax_reverse(y, xmin, xmax) -> np.ndarray:
    """The inverse of :func:`mapminmax` (``mapminmax('reverse', y, PS)``):
    x = (y + 1) (xmax - xmin) / 2 + xmin; constant columns unchanged."""
    y, xmin, xmax = _minmax_args(y, xmin, xmax)
    span = xmax - xmin
    return np.where(span == 0, y, (y + 1.0) * span / 2.0 + xmin)



def train_loop(net, X, Y, optimizer, epochs: int) -> list[float]:
    """The training loop (notebook 07, exercise 7.2; ``ann.train`` with ``algorithm='adam'``
    runs the same loop on its flat parameter vector): per epoch zero the gradients, forward
    pass, mean squared error over all outputs (nntool's ``mse``), back-propagate, step.
    Returns the loss of every epoch, computed before its step."""
    losses = []
    for _ in range(epochs):
        optimizer.zero_grad()
        loss = ((net(X) - Y) ** 2).mean()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    return losses
