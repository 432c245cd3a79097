"""Which detections a run's filter uses (notebooks 04, 05, 08): the dataset's own
(Victoria Park's trees, the simulator's beacons) or beacons extracted from its raw laser,
with their measurement noise.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..data.records import Dataset, Detections
from .beacons import BeaconConfig, simulator_config, beacon_config_for, extract_beacons
from .trees import TreeFilter, trees_filter

__all__ = ["SOURCES", "detections_for", "measurement_sigmas", "with_detections"]

#: Accepted values of ``source`` in :func:`detections_for`.
SOURCES = ("auto", "laser", "detections")


def _resolve(dataset: Dataset, source: str) -> str:
    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be an annslam_lib.data.records.Dataset, got {type(dataset).__name__}")
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r}; choose one of {SOURCES}")
    if source == "auto":
        if dataset.detections is not None:
            return "detections"
        if dataset.laser is not None:
            return "laser"
        raise ValueError(f"dataset {dataset.name!r} has neither detections nor raw laser scans")
    if source == "laser" and dataset.laser is None:
        raise ValueError(f"dataset {dataset.name!r} has no raw laser scans to extract beacons "
                         "from (source='laser'); use source='detections'")
    if source == "detections" and dataset.detections is None:
        raise ValueError(f"dataset {dataset.name!r} has no provided detections "
                         "(source='detections'); use source='laser'")
    return source



def detections_for(dataset: Dataset, source: str = "auto", *, config: BeaconConfig | None = None,
                   tree_filter: TreeFilter | None = None) -> Detections:
    """The point-landmark measurements a filter consumes for ``dataset``.

    source: 'auto' = the provided detections if the dataset has them (Victoria Park's
    trees, the simulator's beacons), else beacons extracted from the raw laser (Car
    Park); 'laser' forces extraction (e.g. the simulator's raw laser); 'detections'
    forces the provided ones. ``config`` (extraction only) defaults to BeaconConfig(),
    with the simulator's ``pole_radius`` for a simulated run. ``tree_filter``, if given,
    is applied to provided tree detections (see :func:`trees_filter`); by default
    nothing is filtered. Raises ValueError if the requested source is unavailable.
    """
    src = _resolve(dataset, source)
    if src == "laser":
        return extract_beacons(dataset.laser, beacon_config_for(dataset) if config is None else config)
    det = dataset.detections
    if tree_filter is not None and dataset.landmark_kind == "trees":
        det = trees_filter(det, tree_filter)
    return det



def measurement_sigmas(dataset: Dataset, source: str = "auto", *,
                       config: BeaconConfig | None = None) -> tuple[float, float]:
    """(sigma_range m, sigma_bearing rad) that goes with :func:`detections_for`.

    Extracted beacons: the config's (default BeaconConfig()). The simulator's own
    detections: the simulator's true noise. Victoria Park's trees: TreeFilter's
    sigma_range and sigma_bearing defaults (see there).
    """
    src = _resolve(dataset, source)
    if src == "laser":
        cfg = beacon_config_for(dataset) if config is None else config
        return cfg.sigma_range, cfg.sigma_bearing
    sim = simulator_config(dataset)
    if sim is not None:
        return float(sim.sigma_range), float(sim.sigma_bearing)
    if dataset.landmark_kind == "trees":
        t = TreeFilter()
        return t.sigma_range, t.sigma_bearing
    cfg = BeaconConfig() if config is None else config
    return cfg.sigma_range, cfg.sigma_bearing



def with_detections(dataset: Dataset, detections: Detections, kind: str = "points") -> Dataset:
    """A copy of ``dataset`` whose point detections are ``detections`` (use with
    ``SlamConfig(feature_source='detections')``); the raw laser, GPS and true map stay."""
    if not isinstance(dataset, Dataset) or not isinstance(detections, Detections):
        raise TypeError("with_detections needs a records.Dataset and a records.Detections")
    if detections.t.shape != dataset.scan_times.shape or np.any(detections.t != dataset.scan_times):
        raise ValueError("detections must have one entry per scan of the dataset, same times")
    return dataclasses.replace(dataset, detections=detections, landmark_kind=kind)
