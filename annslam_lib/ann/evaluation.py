"""How good is a landmark network? Per-split RMSE, the two evaluation protocols, the
paper's figures' data (error histogram, regression) and the hidden-size grid (notebook 07).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from .._cache import memoize
from .network import TrainConfig, train
from .samples import SPLITS, Split, TrainingSet, beacon_folds, chronological_split

__all__ = ["split_rmse", "Evaluation", "evaluate", "evaluate_chronological",
           "evaluate_leave_beacons_out", "error_histogram", "regression", "regression_line",
           "HiddenSizeGrid", "hidden_size_grid", "grid_summary"]


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



@memoize
def evaluate(ts: TrainingSet, splits, config: TrainConfig | None = None, *,
             protocol: str = "") -> Evaluation:
    """Train one model per split and score it on that split's test part. Computed once per
    machine, then read from the study cache (``annslam_lib._cache``)."""
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



def _outputs(model, ts: TrainingSet, idx, kind: str):
    if kind == "position":
        return model.predict(ts.X[idx]), ts.target[idx]
    if kind == "correction":
        return model.predict(ts.X[idx]) - ts.base[idx], ts.Y[idx]
    raise ValueError(f"kind must be 'position' or 'correction', got {kind!r}")



def error_histogram(model, ts: TrainingSet, split: Split, bins: int = 20, *,
                    span: float | None = None) -> dict:
    """nntool's error histogram (paper Figure 6, chapter 07): errors = target - output per
    coordinate (m), in ``bins`` equal bins stacked by part.

    Parameters
    ----------
    span : None or float in (0, 1)
        None: the bins cover the range of all errors, as nntool's do (one stray error can
        squash the rest into a few bins). A share such as 0.99: the bins cover the central
        ``span`` of all errors (their quantiles (1 - span) / 2 and (1 + span) / 2), and each
        error beyond is counted in the end bin on its side.

    Returns
    -------
    dict
        edges (bins + 1,), centres, counts {part: (bins,)} (every error counted once),
        errors {part: (2 n,)} and beyond {part: int}, the errors counted in an end bin
        although they lie outside it (0 when ``span`` is None).
    """
    if isinstance(bins, bool) or not isinstance(bins, numbers.Integral) or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    if span is not None and not (isinstance(span, numbers.Real) and 0.0 < span < 1.0):
        raise ValueError(f"span must be None or a share strictly between 0 and 1, got {span!r}")
    errors = {}
    for p in SPLITS:
        out, tgt = _outputs(model, ts, split.part(p), "position")
        errors[p] = (tgt - out).ravel()
    allerr = np.concatenate(list(errors.values()))
    if not allerr.size:
        lo, hi = -1.0, 1.0
    elif span is None:
        lo, hi = float(allerr.min()), float(allerr.max())
    else:
        lo, hi = (float(q) for q in np.quantile(allerr, [(1 - span) / 2, (1 + span) / 2]))
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    edges = np.linspace(lo, hi, bins + 1)
    counts = {p: np.histogram(np.clip(e, lo, hi), bins=edges)[0] for p, e in errors.items()}
    beyond = {p: int(np.count_nonzero((e < lo) | (e > hi))) for p, e in errors.items()}
    return dict(edges=edges, centres=0.5 * (edges[1:] + edges[:-1]), counts=counts, errors=errors,
                beyond=beyond)



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



def regression_line(outputs, targets) -> tuple[float, float, float]:
    """nntool's regression plot (paper Figure 8; ``ann.regression`` per part): both
    coordinates pooled, the least-squares line output = slope * target + intercept and the
    correlation coefficient R of outputs and targets. outputs, targets (n, 2) or (n,);
    returns (slope, intercept, R). Raises ValueError for mismatched shapes, fewer than 2
    values, or constant targets or outputs (R undefined)."""
    o = np.asarray(outputs, dtype=float)
    g = np.asarray(targets, dtype=float)
    if o.shape != g.shape:
        raise ValueError(f"outputs and targets must have the same shape, got {o.shape} and {g.shape}")
    o, g = o.ravel(), g.ravel()
    if o.size < 2 or not (np.all(np.isfinite(o)) and np.all(np.isfinite(g))):
        raise ValueError("need at least 2 finite values")
    if np.ptp(g) == 0 or np.ptp(o) == 0:
        raise ValueError("constant targets or outputs: the correlation R is undefined")
    do, dg = o - o.mean(), g - g.mean()
    slope = float(dg @ do / (dg @ dg))
    r = float(dg @ do / math.sqrt((dg @ dg) * (do @ do)))
    return slope, float(o.mean() - slope * g.mean()), r


@dataclass
class HiddenSizeGrid:
    """Results of :func:`hidden_size_grid`.

    hidden (H,), seeds (S,): the grid axes. chrono (H, S): test RMSE (m) of the network on
    the chronological split; lbo (H, S): leave-beacons-out RMSE (m) (NaN if not computed);
    chrono_base, lbo_base: the inverse model's RMSE on the same samples; models: {(h, s):
    the chronological TrainedModel} (for its history); n_params (H,): weights and biases.
    """

    hidden: tuple
    seeds: tuple
    chrono: np.ndarray
    lbo: np.ndarray
    chrono_base: float
    lbo_base: float
    n_params: np.ndarray
    models: dict = field(default_factory=dict)

    def index(self, hidden: int, seed: int) -> tuple[int, int]:
        if hidden not in self.hidden:
            raise ValueError(f"hidden size {hidden!r} is not in the grid {self.hidden}")
        if seed not in self.seeds:
            raise ValueError(f"seed {seed!r} is not in the grid {self.seeds}")
        return self.hidden.index(hidden), self.seeds.index(seed)



def _int_tuple(name: str, values, lo: int) -> tuple:
    vals = tuple(values)
    if not vals or any(isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < lo
                       for v in vals) or len(set(vals)) != len(vals):
        raise ValueError(f"{name} must be distinct integers >= {lo}, got {values!r}")
    return tuple(int(v) for v in vals)



@memoize
def hidden_size_grid(ts: TrainingSet, hidden=(1, 2, 5, 10, 20, 40), seeds=range(5), *,
                     config: TrainConfig | None = None, leave_beacons_out: bool = True,
                     n_folds: int = 5) -> HiddenSizeGrid:
    """Train one network per (hidden size, seed) on ``ts`` (``config`` with ``hidden``
    and ``seed`` replaced): on the chronological split, and, if ``leave_beacons_out``,
    in leave-beacons-out cross-validation with ``n_folds`` folds. Computed once per machine,
    then read from the study cache (``annslam_lib._cache``)."""
    if not isinstance(ts, TrainingSet):
        raise TypeError(f"ts must be an TrainingSet, got {type(ts).__name__}")
    hidden = _int_tuple("hidden", hidden, 1)
    seeds = _int_tuple("seeds", seeds, 0)
    base_cfg = TrainConfig() if config is None else config
    if not isinstance(base_cfg, TrainConfig):
        raise TypeError(f"config must be an TrainConfig, got {type(base_cfg).__name__}")
    sp = chronological_split(ts)
    folds = beacon_folds(ts, n_folds) if leave_beacons_out else None
    chrono = np.full((len(hidden), len(seeds)), np.nan)
    lbo = np.full_like(chrono, np.nan)
    models = {}
    chrono_base = lbo_base = np.nan
    for i, h in enumerate(hidden):
        for j, s in enumerate(seeds):
            cfg = dataclasses.replace(base_cfg, hidden=(h,), seed=s)
            m = train(ts, sp, cfg)
            models[(h, s)] = m
            r = split_rmse(m, ts, sp)["test"]
            chrono[i, j], chrono_base = r["rmse_ann"], r["rmse_base"]
            if folds is not None:
                ev = evaluate(ts, folds, cfg, protocol="leave_beacons_out")
                lbo[i, j], lbo_base = ev.rmse_ann, ev.rmse_base
    n_in = len(base_cfg.columns)
    n_params = np.array([n_in * h + h + 2 * h + 2 for h in hidden])
    return HiddenSizeGrid(hidden=hidden, seeds=seeds, chrono=chrono, lbo=lbo,
                          chrono_base=float(chrono_base), lbo_base=float(lbo_base),
                          n_params=n_params, models=models)



def grid_summary(grid: HiddenSizeGrid, hidden: int, seed: int) -> dict:
    """What the explorer shows for (hidden, seed): the network's best epoch, epochs run,
    parameters, its chronological-test and leave-beacons-out RMSE, the means over seeds
    at this size and the baselines (all RMSE in m)."""
    i, j = grid.index(hidden, seed)
    m = grid.models[(hidden, seed)]
    return {"hidden": int(hidden), "seed": int(seed), "n_params": int(grid.n_params[i]),
            "best_epoch": int(m.best_epoch), "epochs": int(m.epochs),
            "best_val_mse": float(m.history["val"][m.best_epoch]),
            "chrono_rmse": float(grid.chrono[i, j]), "lbo_rmse": float(grid.lbo[i, j]),
            "chrono_mean": float(np.mean(grid.chrono[i])), "lbo_mean": float(np.mean(grid.lbo[i])),
            "chrono_base": grid.chrono_base, "lbo_base": grid.lbo_base}
