"""Saving and loading a trained landmark network safely (notebook 07): plain tensors and
numbers only (``torch.load(weights_only=True)``), so a model file cannot run code."""
from __future__ import annotations

import math
import pickle
import zipfile
from pathlib import Path

import numpy as np

from .network import TrainConfig, TrainedModel, require_torch

try:                                      # torch is the optional 'ann' extra
    import torch
except ImportError:                       # pragma: no cover - exercised without torch only
    torch = None

__all__ = ["UnsafeModelFile", "save", "load"]

_FORMAT = "annslam-ann-v1"
#: Largest weight magnitude a trained network plausibly has (its inputs and outputs are
#: standardised); beyond it a file is damaged or forged, not trained.
MAX_WEIGHT = 1e6


class UnsafeModelFile(ValueError):
    """A model file that is not a plain tensors-and-dicts file of this module: refused
    without running any code it may contain."""



def save(model: TrainedModel, path) -> Path:
    """Write the model (weights, normalisation, config, history, noise) as plain tensors,
    numbers, strings, lists and dicts with ``torch.save``; :func:`load` reads it back
    with ``weights_only=True``."""
    require_torch()
    if not isinstance(model, TrainedModel):
        raise TypeError(f"can only save a TrainedModel, got {type(model).__name__}")
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
    :class:`UnsafeModelFile` (no code from it runs). ValueError, naming the problem, for a
    damaged file (a zip CRC that fails, not a model file at all) or implausible values
    (NaN or huge weights, a noise sigma that is not positive and finite)."""
    require_torch()
    path = Path(path)
    _check_container(path)
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise UnsafeModelFile(f"{path}: refused, not a plain weights file (it holds objects "
                              f"that weights_only loading does not allow): {e}") from e
    except (RuntimeError, EOFError, OSError, KeyError, ValueError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not a readable model file ({type(e).__name__}: {e})") from e
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
    _check_values(path, model)
    return model


def _check_container(path: Path) -> None:
    """torch.save writes a zip archive whose CRCs torch itself never checks: check them
    (a changed byte inside the weights), and name a file that is no archive at all."""
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head[:2] == b"PK":
        try:
            with zipfile.ZipFile(path) as z:
                bad = z.testzip()
        except (zipfile.BadZipFile, OSError, EOFError) as e:
            raise ValueError(f"{path}: damaged model file (its zip archive is broken: {e}); "
                             "save the model again") from e
        if bad is not None:
            raise ValueError(f"{path}: damaged model file: {bad!r} fails its CRC check (bytes "
                             "changed after saving); save the model again")
    elif not head.startswith(b"\x80"):               # neither zip nor pickle
        raise ValueError(f"{path}: not a model file (it starts with {head!r}, neither a torch "
                         "zip archive nor a pickle); write model files with ann.save")


def _check_values(path: Path, model: TrainedModel) -> None:
    """The numbers a filter would use: finite weights of plausible size, positive finite
    measurement noise."""
    theta = model.theta.detach().numpy()
    if not np.all(np.isfinite(theta)):
        raise ValueError(f"{path}: {int(np.sum(~np.isfinite(theta)))} of {theta.size} weights "
                         "are NaN or infinite")
    if np.max(np.abs(theta), initial=0.0) > MAX_WEIGHT:
        raise ValueError(f"{path}: a weight of {np.max(np.abs(theta)):.3g} (more than "
                         f"{MAX_WEIGHT:g}): not a trained network")
    for name in ("sigma_range", "sigma_bearing"):
        v = getattr(model, name)
        if not (0.0 < v < math.inf):
            raise ValueError(f"{path}: {name} = {v!r}; the pseudo-measurement noise must be "
                             "a positive finite number")
