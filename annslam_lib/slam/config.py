"""Settings of an EKF-SLAM run (notebook 05 "EKF-SLAM"; :func:`annslam_lib.slam.runner.run`).

:class:`SlamConfig` holds every choice of a run: motion and process noise, observation
noise and range window, data association, landmark book-keeping, GPS use, the initial pose.
Per-dataset defaults are registered with each dataset (:func:`annslam_lib.data.
filter_defaults`), so adding a dataset never touches this module.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .. import _checks
from ..data import filter_defaults
from ..perception.association import NEW_LANDMARK_PROB

__all__ = ["SlamConfig", "GPS_MODES", "ASSOCIATIONS", "MAP_MODES", "MOTION_MODELS", "LANDMARK_MODELS"]

#: GPS use: 'none'; 'init' = GPS updates only for the first ``gps_init_seconds``; 'all'.
GPS_MODES = ("none", "init", "all")

#: Data association: 'nn' = chi-square gated nearest neighbour (``association``);
#: 'jcbb' = joint compatibility branch and bound (``perception.jcbb``);
#: 'truth' = the detections' true landmark ids (simulator only).
ASSOCIATIONS = ("nn", "jcbb", "truth")

#: What the filter knows of the map (``SlamConfig.map_mode``): 'slam' = nothing, it builds
#: the map; 'known' = the dataset's surveyed map, held fixed (EKF localisation, chapter 04a).
MAP_MODES = ("slam", "known")

#: Discretisations of the motion model (``SlamConfig.motion_model``).
MOTION_MODELS = ("euler", "midpoint")

#: Landmark measurement models (``SlamConfig.landmark_model``): 'inverse' = the detections
#: as measured (inverse observation at initialisation); 'ann' = a trained landmark
#: network's pseudo-measurements (module docstring, ``annslam_lib.ann``).
LANDMARK_MODELS = ("inverse", "ann")


# --------------------------------------------------------------------------- configuration

@dataclass(frozen=True)
class SlamConfig:
    """Settings of :func:`run`. Use :meth:`for_dataset` for per-dataset defaults.

    Motion and process noise (per odometry sample; see the module docstring)
        sigma_speed: standard deviation of the encoder speed error, m/s (ACFR: 0.7).
        sigma_steer: standard deviation of the steering angle error, rad (ACFR: 7 deg).
        steer_noise_gain: a steering error that grows in turns: the standard deviation
        at steering alpha is sigma_steer + steer_noise_gain |alpha| (rad per rad; 0, the
        default, is ACFR's constant noise). Notebook 05 "the systematic errors, modelled".
        motion_model: 'midpoint' (the default: ``motion.predict``'s step with the rate
        evaluated at the mid-step heading phi + dt w / 2, and its F, G there: second-order
        accurate) or 'euler' (``motion.predict``, the ACFR discrete model the paper uses).
        Euler's position error in turns, about 5 cm per half lap of the simulator's loop,
        is larger than the filter's own uncertainty there: over 50 seeds its average pose
        NEES leaves the per-scan band on more than a third of the scans and its final map
        NEES per dof is 1.2 (band 0.93-1.07); the midpoint model passes the per-scan rules
        on the loop, with a map NEES per dof at the band's upper edge (1.07), and its map is
        about 9 % over-confident on the hairpin (notebook 05, ``tests/test_consistency.py``).
    Observations
        sigma_range: range noise, m (ACFR: 0.1). sigma_bearing: bearing noise, rad (1 deg).
        range_bias (m), bearing_offset (rad): a calibration subtracted from every laser
        detection before use (``evaluation.calibration.laser_calibration`` estimates them
        against a surveyed map); 0 by default.
        min_range, max_range: detections outside [min_range, max_range] m are not used
        (logged with status 'out_of_range'); so are those with a known diameter (trunk,
        cluster width) below min_diameter, m (0 keeps all).
        feature_source: passed to ``perception.beacons.detections_for`` ('auto': the dataset's own
        detections, else beacons extracted from its raw laser).
        landmark_model: 'inverse' (the detections as measured) or 'ann' (the trained
        network passed as ``run(..., landmark_model=model)`` turns every detection into a
        pseudo-measurement with the model's noise, which replaces sigma_range and
        sigma_bearing; module docstring).
    Data association
        association: 'nn' (gated nearest neighbour, ``association.associate``), 'jcbb'
        (the scan's jointly compatible hypothesis with the most pairings,
        ``perception.jcbb``: the same gate for each pairing, the joint NIS below
        chi2.ppf(gate_prob, 2k); a search stopped at ``jcbb_max_nodes`` keeps its best
        hypothesis so far and is counted in ``counts['jcbb_truncated']``; the efficient
        backend only) or 'truth' (simulator's landmark ids: known data association).
        jcbb_max_nodes: the JCBB search's bound per scan.
        gate_prob: an observation is associated only if its squared Mahalanobis distance
        d2 to the landmark is below chi2.ppf(gate_prob, 2).
        new_landmark_prob: an observation whose d2 to EVERY landmark exceeds
        chi2.ppf(new_landmark_prob, 2) starts a new landmark; one between the two
        thresholds is ambiguous and rejected. Must be >= gate_prob.
        landmark_min_observations: tentative landmarks. A new landmark joins the state at
        once (so it is tracked and associated like any other), but it is deleted again
        (marginalised: its rows and columns dropped) unless it has been observed at
        least this many times (counting the first sighting) within
        ``landmark_probation`` seconds of its creation; at the end of the run the
        still-tentative ones below the count are dropped too. 1 keeps every landmark.
        landmark_probation: the probation period, s.
        first_estimates: False (the default, the standard EKF: every Jacobian at the current
        estimate) or True, first-estimates Jacobians (FEJ; Huang, Mourikis & Roumeliotis
        2008): the observation Jacobians at each landmark's first estimate (the one it was
        added with) and the motion Jacobian at the pose predicted before the last update, so
        that the filter's linearised model keeps the three unobservable directions of SLAM
        (global translation and rotation) and gains no information along them (``evaluation.consistency.monte_carlo``
        measures both).
        The innovations still use the current estimates. The efficient backend only.
    The map
        map_mode: 'slam' (the default: the filter builds the map from nothing) or 'known'
        (EKF localisation, chapter 04a: the dataset's surveyed map ``Dataset.beacons``, the
        simulator's true one, is in the state from the start with covariance
        known_map_sigma^2 I per landmark; detections are associated with it only, and one
        that matches no landmark is rejected and counted, never added).
        known_map_sigma: m, the known map's standard deviation per axis; 0 (the default)
        holds the map exactly (its rows of the gain are then exactly zero).
    GPS (the antenna is the laser point, so GPS measures the state's (x, y))
        gps_mode: 'none', 'init' (updates only during the first ``gps_init_seconds`` of
        the run: anchors the map in the GPS frame) or 'all'.
        gps_init_seconds: s. sigma_gps: m, per axis (ACFR: 0.05).
        gps_gate_prob: a fix whose NIS exceeds chi2.ppf(gps_gate_prob, 2) is rejected
        and counted (``counts['gps_rejected']``; GPS jumps); default 0.9999 on every run,
        1.0 accepts every fix.
    Initial pose (at the first odometry sample; the filter starts there)
        initial_pose: 'gps' (``slam.dead_reckoning.initial_pose_from_gps``: position = first
        GPS fix kept, heading = robust least-squares fit of the dead-reckoned path of the
        first ``initial_window`` seconds to the GPS track: no hand-tuned heading; raises
        when its residual is implausible), 'truth'
        (simulator), 'auto' ('truth' if the dataset has it, else 'gps'), or an explicit
        (x, y, phi).
        initial_window: s, the fit window of 'gps'.
        initial_sigma_xy (m), initial_sigma_phi (rad): initial standard deviations.
    Bookkeeping
        checkpoint_every: covariance health (min eigenvalue, asymmetry) is recorded every
        this many scans and at the end.
    """

    sigma_speed: float = 0.7
    sigma_steer: float = math.radians(7.0)
    steer_noise_gain: float = 0.0
    motion_model: str = "midpoint"
    sigma_range: float = 0.1
    sigma_bearing: float = math.radians(1.0)
    range_bias: float = 0.0
    bearing_offset: float = 0.0
    min_range: float = 1.0
    max_range: float = 30.0
    min_diameter: float = 0.0
    feature_source: str = "auto"
    landmark_model: str = "inverse"
    association: str = "nn"
    jcbb_max_nodes: int = 10_000
    gate_prob: float = 0.99
    new_landmark_prob: float = NEW_LANDMARK_PROB
    landmark_min_observations: int = 1
    landmark_probation: float = 2.0
    first_estimates: bool = False
    map_mode: str = "slam"
    known_map_sigma: float = 0.0
    gps_mode: str = "init"
    gps_init_seconds: float = 10.0
    sigma_gps: float = 0.05
    gps_gate_prob: float = 0.9999
    initial_pose: object = "auto"
    initial_window: float = 10.0
    initial_sigma_xy: float = 0.1
    initial_sigma_phi: float = math.radians(2.0)
    checkpoint_every: int = 500

    def __post_init__(self) -> None:
        o = "SlamConfig."
        for name in ("sigma_speed", "sigma_steer", "sigma_range", "sigma_bearing", "sigma_gps",
                     "min_range", "min_diameter", "gps_init_seconds", "initial_sigma_xy",
                     "initial_sigma_phi", "landmark_probation", "steer_noise_gain",
                     "known_map_sigma"):
            _checks.real(o + name, getattr(self, name), lo=0.0)
        for name in ("range_bias", "bearing_offset"):
            _checks.real(o + name, getattr(self, name))
        if abs(self.bearing_offset) > math.radians(10.0) or abs(self.range_bias) > 1.0:
            raise ValueError("SlamConfig.bearing_offset beyond 10 deg or range_bias beyond 1 m is no "
                             f"calibration (got {self.bearing_offset!r} rad, {self.range_bias!r} m)")
        for name in ("max_range", "initial_window"):
            _checks.real(o + name, getattr(self, name), lo=0.0, strict=True)
        if self.max_range <= self.min_range:
            raise ValueError(f"SlamConfig.max_range ({self.max_range}) must exceed min_range "
                             f"({self.min_range})")
        for name in ("gate_prob", "new_landmark_prob"):
            _checks.probability(o + name, getattr(self, name))
        _checks.probability(o + "gps_gate_prob", self.gps_gate_prob, closed_top=True)
        if self.new_landmark_prob < self.gate_prob:
            raise ValueError(f"SlamConfig.new_landmark_prob ({self.new_landmark_prob}) must be >= "
                             f"gate_prob ({self.gate_prob})")
        _checks.integer(o + "landmark_min_observations", self.landmark_min_observations, lo=1)
        _checks.integer(o + "checkpoint_every", self.checkpoint_every, lo=1)
        _checks.integer(o + "jcbb_max_nodes", self.jcbb_max_nodes, lo=1)
        _checks.flag(o + "first_estimates", self.first_estimates)
        _checks.choice(o + "gps_mode", self.gps_mode, GPS_MODES)
        _checks.choice(o + "map_mode", self.map_mode, MAP_MODES)
        _checks.choice(o + "motion_model", self.motion_model, MOTION_MODELS)
        _checks.choice(o + "association", self.association, ASSOCIATIONS)
        _checks.choice(o + "landmark_model", self.landmark_model, LANDMARK_MODELS)
        _checks.instance(o + "feature_source", self.feature_source, str, "string")
        pose = self.initial_pose
        if isinstance(pose, str):
            _checks.choice(o + "initial_pose", pose, ("auto", "gps", "truth"))
        else:
            arr = _checks.array(o + "initial_pose", pose)
            if arr.shape != (3,):
                raise ValueError("SlamConfig.initial_pose must be 'auto', 'gps', 'truth' or a "
                                 f"finite (x, y, phi), got {pose!r}")
            object.__setattr__(self, "initial_pose", tuple(float(v) for v in arr))

    @classmethod
    def for_dataset(cls, name: str, **overrides) -> SlamConfig:
        """Defaults for 'car_park', 'victoria_park' or 'simulated', with ``overrides``.

        car_park: the original ACFR program's noise values (0.7 m/s, 7 deg, 0.1 m, 1 deg,
        GPS 0.05 m), GPS for the first 10 s, initial pose fitted to GPS.
        victoria_park: trees are less precise than poles (sigma_range 0.5 m, 2 deg),
        GPS for the first 20 s with a 99.99 % gate (the receiver jumps), tentative
        landmarks (a tree must be seen twice within 2 s).
        simulated: the simulator's own noise (SimConfig defaults), true initial pose,
        no GPS: a pure SLAM run whose consistency can be checked against the truth;
        tentative landmarks (3 sightings within 2 s), so that a rare 5-sigma bearing
        error, which exceeds the new-landmark threshold, does not leave a duplicate.
        The values live with each dataset (``data.filter_defaults``: the registry for the
        real runs, ``data.simulate`` for the simulator).

        Parameters
        ----------
        name : str
            'car_park', 'victoria_park' or 'simulated'.
        **overrides
            Fields to set instead of the dataset's defaults.

        Returns
        -------
        SlamConfig
            The dataset's defaults with ``overrides``.

        Raises
        ------
        TypeError
            For a field value of the wrong type.
        ValueError
            For an unknown name, an unknown field or a field value out of its range.
        """
        base = filter_defaults(name)
        unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise ValueError(f"unknown SlamConfig field(s): {', '.join(unknown)}")
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> SlamConfig:
        """A copy with ``changes`` (ValueError for unknown fields)."""
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise ValueError(f"unknown SlamConfig field(s): {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)
