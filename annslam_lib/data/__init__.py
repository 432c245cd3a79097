"""Data layer: the runs a filter consumes, real and simulated.

- ``records``: the dataset object (odometry, GPS, laser, detections, truth) and its checks
- ``registry``: each real run's files, hashes, sources, citation and EKF-SLAM defaults
- ``fetch``: the data folder, download and sha256 verification
- ``loaders``: the real runs parsed into records (``load('car_park')``)
- ``simulate``: a seeded simulator of the same car with ground truth
- ``screening``: damaged sensor streams repaired by stated rules and counted (on entry to a run)

Adding a dataset: its entry in ``registry`` and its parser in ``loaders``.
"""
from __future__ import annotations

from .._lazy import attach

__getattr__, __dir__, _names = attach(
    __name__, ["records", "registry", "fetch", "loaders", "simulate", "screening"],
    {"load": "loaders", "load_car_park": "loaders", "load_victoria_park": "loaders",
     "DataError": "fetch", "Dataset": "records"})
__all__ = _names + ["filter_defaults", "filter_default_names"]


def filter_defaults(name: str) -> dict:
    """The SlamConfig fields that differ from their defaults on dataset ``name``: a real run
    of the registry, or 'simulated' (``simulate.FILTER_DEFAULTS``). ValueError otherwise."""
    from . import registry

    if name == "simulated":
        from .simulate import FILTER_DEFAULTS
        return dict(FILTER_DEFAULTS)
    if name in registry.DATASETS and not registry.DATASETS[name].optional:
        return dict(registry.DATASETS[name].filter_defaults)
    raise ValueError(f"no SlamConfig defaults for dataset {name!r}; known: "
                     f"{', '.join(filter_default_names())}")


def filter_default_names() -> tuple[str, ...]:
    """Datasets with EKF-SLAM defaults: the core real runs and 'simulated'."""
    from . import registry

    return (*registry.core(), "simulated")
