"""EKF-SLAM for the car-like vehicle, written to scale (notebook 05 "EKF-SLAM", notebook 06
"Victoria Park at scale").

State and covariance
    x = [x, y, phi, l1x, l1y, l2x, l2y, ...]: the LASER pose (``kinematics``) and the
    landmarks in the world frame; P its (n, n) covariance, n = 3 + 2 N, kept as ONE
    C-contiguous array whose UPPER triangle holds the symmetric P (symmetric by
    construction; the lower triangle is filled in only when P is handed out). Its
    transpose is Fortran-contiguous, which lets the BLAS rank-k correction work in place
    (:meth:`EkfSlam._correct`).

Cost (measured facts: /work/shared/notes/PERFORMANCE.md; benchmarks/bench_ekf_slam.py)
    - Prediction touches only the 3x3 vehicle block and the 3 x 2N cross covariance.
      The motion Jacobian of one Euler step is F = [[1, 0, f0], [0, 1, f1], [0, 0, 1]], and a
      product of such matrices is again of that form with f0, f1 summed, so consecutive
      odometry steps are COMPOUNDED exactly: each step updates the pose and the 3x3 block
      (plain ``math``, a few microseconds), the sums (f0, f1) accumulate, and the cross
      covariance is multiplied by F_total once, when something next reads it (a scan, a
      GPS fix, a checkpoint). ``tests/test_ekf_slam.py`` proves it equal to step-by-step
      prediction.
    - An update touches only the columns its Jacobian touches: the vehicle and the
      observed landmarks. With H_c (2m x c) the nonzero columns of H,

          HP = H_c P[c, :]                  (2m x n; the rows of P, P symmetric)
          S  = HP[:, c] H_c^T + R,  symmetrised, S = L L^T (Cholesky)
          W^T = L^{-1} HP,  x += W (L^{-1} nu),  P -= W W^T

      The last line is the optimal-gain covariance update P - P H^T S^{-1} H P written as
      a symmetric rank-2m correction, done in place on the upper triangle by BLAS
      ``dsyrk`` (no n x n temporary, no n x n Jacobian; half the memory traffic of a
      full ``dgemm``, which matters because the update is memory-bound). All
      observations of a scan go into ONE update.
    - Landmark augmentation (``observation.inverse_observe``): for new landmarks
      l = g(pose, z), P_ll = J_pose P_vv J_pose^T + J_z R J_z^T, P_l* = J_pose P_v*.

Process noise (notebook 05 "process noise")
    The odometry sample k, taken at t_k, is the control held over [t_k, t_{k+1})
    (``dead_reckoning`` convention). Its error is modelled on what is measured: the
    encoder speed (``sigma_speed``) and the steering angle (``sigma_steer``), mapped to
    the controls (v_c, alpha) by the Jacobian of ``kinematics.axle_speed``:
    Q_c = M diag(sigma_speed^2, sigma_steer^2) M^T. A full Euler step of length
    Delta_k = t_{k+1} - t_k adds G Q_c G^T = Delta_k^2 B Q_c B^T (B = d rate / d control),
    the ACFR discrete model. Scans and GPS fixes fall inside odometry intervals, so the
    filter predicts to every event time in partial steps tau; each partial step adds
    tau Delta_k B Q_c B^T, so the noise added over one odometry interval does not depend
    on how many events split it (and equals the ACFR value when none does).

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
    (``dead_reckoning.initial_pose_from_gps``; Car Park: -127 deg, where the original
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

import contextlib
import ctypes
import dataclasses
import math
import numbers
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import eigh
from scipy.linalg.blas import dsyrk, dtrsm
from scipy.linalg.lapack import dpotrf, dtrtrs
from scipy.stats import chi2

from . import association, kinematics
from .geometry import wrap_angle
from .observation import inverse_observe
from .records import Dataset, Detections
from .vehicle import Vehicle

__all__ = ["SlamConfig", "SlamResult", "ObservationLog", "EkfSlam", "InnovationError",
           "run", "control_table", "pose_nees", "one_blas_thread", "GPS_MODES", "MOTION_MODELS", "ASSOCIATIONS",
           "DATASET_NAMES", "STATUS", "LANDMARK_MODELS"]

#: GPS use: 'none'; 'init' = GPS updates only for the first ``gps_init_seconds``; 'all'.
GPS_MODES = ("none", "init", "all")
#: Data association: 'nn' = chi-square gated nearest neighbour (``association``);
#: 'truth' = the detections' true landmark ids (simulator only).
ASSOCIATIONS = ("nn", "truth")
#: Discretisations of the motion model (``SlamConfig.motion_model``).
MOTION_MODELS = ("euler", "midpoint")
#: Datasets with their own defaults in :meth:`SlamConfig.for_dataset`.
DATASET_NAMES = ("car_park", "victoria_park", "simulated")
#: Landmark measurement models (``SlamConfig.landmark_model``): 'inverse' = the detections
#: as measured (inverse observation at initialisation); 'ann' = a trained landmark
#: network's pseudo-measurements (module docstring, ``annslam_lib.ann``).
LANDMARK_MODELS = ("inverse", "ann")
#: Codes of ``ObservationLog.status``.
STATUS = {"associated": 0, "new": 1, "rejected": 2, "out_of_range": 3}
_PI, _TWO_PI = math.pi, 2.0 * math.pi


class InnovationError(ValueError):
    """The innovation covariance S of an update is not positive definite (singular):
    no gain exists. Typically zero measurement noise on a perfectly known state."""


# --------------------------------------------------------------------------- configuration

@dataclass(frozen=True)
class SlamConfig:
    """Settings of :func:`run`. Use :meth:`for_dataset` for per-dataset defaults.

    Motion and process noise (per odometry sample; see the module docstring)
        sigma_speed: standard deviation of the encoder speed error, m/s (ACFR: 0.7).
        sigma_steer: standard deviation of the steering angle error, rad (ACFR: 7 deg).
        motion_model: 'euler' (``kinematics.predict``, the ACFR discrete model) or
        'midpoint' (the same step with the rate evaluated at the mid-step heading
        phi + dt w / 2, and its F, G there: second-order accurate. Euler's position
        error in turns, about 5 cm per half lap of the simulator's loop, is larger than
        the filter's own uncertainty there and shows in the NEES; notebook 05).
    Observations
        sigma_range: range noise, m (ACFR: 0.1). sigma_bearing: bearing noise, rad (1 deg).
        min_range, max_range: detections outside [min_range, max_range] m are not used
        (logged with status 'out_of_range'); so are those with a known diameter (trunk,
        cluster width) below min_diameter, m (0 keeps all).
        feature_source: passed to ``features.detections_for`` ('auto': the dataset's own
        detections, else beacons extracted from its raw laser).
        landmark_model: 'inverse' (the detections as measured) or 'ann' (the trained
        network passed as ``run(..., landmark_model=model)`` turns every detection into a
        pseudo-measurement with the model's noise, which replaces sigma_range and
        sigma_bearing; module docstring).
    Data association
        association: 'nn' (gated nearest neighbour, ``association.associate``) or
        'truth' (simulator's landmark ids: known data association).
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
    GPS (the antenna is the laser point, so GPS measures the state's (x, y))
        gps_mode: 'none', 'init' (updates only during the first ``gps_init_seconds`` of
        the run: anchors the map in the GPS frame) or 'all'.
        gps_init_seconds: s. sigma_gps: m, per axis (ACFR: 0.05).
        gps_gate_prob: a fix whose NIS exceeds chi2.ppf(gps_gate_prob, 2) is rejected
        (GPS jumps); 1.0 accepts every fix.
    Initial pose (at the first odometry sample; the filter starts there)
        initial_pose: 'gps' (``dead_reckoning.initial_pose_from_gps``: position = first
        GPS fix, heading = least-squares fit of the dead-reckoned path of the first
        ``initial_window`` seconds to the GPS track: no hand-tuned heading), 'truth'
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
    motion_model: str = "euler"
    sigma_range: float = 0.1
    sigma_bearing: float = math.radians(1.0)
    min_range: float = 1.0
    max_range: float = 30.0
    min_diameter: float = 0.0
    feature_source: str = "auto"
    landmark_model: str = "inverse"
    association: str = "nn"
    gate_prob: float = 0.99
    new_landmark_prob: float = 0.99999
    landmark_min_observations: int = 1
    landmark_probation: float = 2.0
    gps_mode: str = "init"
    gps_init_seconds: float = 10.0
    sigma_gps: float = 0.05
    gps_gate_prob: float = 1.0
    initial_pose: object = "auto"
    initial_window: float = 10.0
    initial_sigma_xy: float = 0.1
    initial_sigma_phi: float = math.radians(2.0)
    checkpoint_every: int = 500

    def __post_init__(self) -> None:
        for name in ("sigma_speed", "sigma_steer", "sigma_range", "sigma_bearing", "sigma_gps",
                     "min_range", "min_diameter", "gps_init_seconds", "initial_sigma_xy",
                     "initial_sigma_phi", "landmark_probation"):
            _real(name, getattr(self, name), lo=0.0)
        for name in ("max_range", "initial_window"):
            _real(name, getattr(self, name), lo=0.0, strict=True)
        if self.max_range <= self.min_range:
            raise ValueError(f"SlamConfig.max_range ({self.max_range}) must exceed min_range "
                             f"({self.min_range})")
        for name in ("gate_prob", "new_landmark_prob"):
            p = getattr(self, name)
            _real(name, p, lo=0.0, strict=True)
            if p >= 1.0:
                raise ValueError(f"SlamConfig.{name} must be a probability in (0, 1), got {p!r}")
        _real("gps_gate_prob", self.gps_gate_prob, lo=0.0, strict=True)
        if self.gps_gate_prob > 1.0:
            raise ValueError(f"SlamConfig.gps_gate_prob must be in (0, 1], got {self.gps_gate_prob!r}")
        if self.new_landmark_prob < self.gate_prob:
            raise ValueError(f"SlamConfig.new_landmark_prob ({self.new_landmark_prob}) must be >= "
                             f"gate_prob ({self.gate_prob})")
        _int("landmark_min_observations", self.landmark_min_observations, 1)
        _int("checkpoint_every", self.checkpoint_every, 1)
        _choice("gps_mode", self.gps_mode, GPS_MODES)
        _choice("motion_model", self.motion_model, MOTION_MODELS)
        _choice("association", self.association, ASSOCIATIONS)
        _choice("landmark_model", self.landmark_model, LANDMARK_MODELS)
        if not isinstance(self.feature_source, str):
            raise ValueError(f"SlamConfig.feature_source must be a string, got {self.feature_source!r}")
        pose = self.initial_pose
        if isinstance(pose, str):
            _choice("initial_pose", pose, ("auto", "gps", "truth"))
        else:
            try:
                arr = np.asarray(pose, dtype=float)
            except (TypeError, ValueError):
                arr = np.empty(0)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
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
        Raises ValueError for an unknown name or an unknown field.
        """
        if name not in DATASET_NAMES:
            raise ValueError(f"no SlamConfig defaults for dataset {name!r}; known: "
                             f"{', '.join(DATASET_NAMES)}")
        base = dict(_DEFAULTS[name])
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


_DEFAULTS = {
    "car_park": dict(),
    "victoria_park": dict(sigma_speed=0.7, sigma_steer=math.radians(7.0), sigma_range=0.5,
                          sigma_bearing=math.radians(2.0), min_range=1.0, max_range=30.0,
                          gate_prob=0.99, new_landmark_prob=0.99999,
                          landmark_min_observations=2, landmark_probation=2.0,
                          gps_mode="init", gps_init_seconds=20.0, gps_gate_prob=0.9999,
                          initial_sigma_xy=0.5, initial_sigma_phi=math.radians(3.0)),
    "simulated": dict(sigma_speed=0.05, sigma_steer=math.radians(1.0), sigma_range=0.1,
                      sigma_bearing=math.radians(1.0), min_range=1.0, max_range=30.0,
                      landmark_min_observations=3, landmark_probation=2.0,
                      gps_mode="none", initial_pose="auto", initial_sigma_xy=0.0,
                      initial_sigma_phi=0.0),
}


def _real(name, value, *, lo=None, strict=False) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"SlamConfig.{name} must be a finite number, got {value!r}")
    if lo is not None and (value <= lo if strict else value < lo):
        raise ValueError(f"SlamConfig.{name} must be {'>' if strict else '>='} {lo}, got {value!r}")


def _int(name, value, lo) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise ValueError(f"SlamConfig.{name} must be an integer >= {lo}, got {value!r}")


def _choice(name, value, options) -> None:
    if not isinstance(value, str) or value not in options:
        raise ValueError(f"SlamConfig.{name} must be one of {options}, got {value!r}")


# --------------------------------------------------------------------------- controls

def control_table(odometry, vehicle: Vehicle, sigma_speed: float, sigma_steer: float) -> list:
    """Per odometry sample k, the tuple (v_c, alpha, tan alpha, w, dw/dalpha, q00, q01, q11,
    Delta_k) the predictions use: axle speed (``kinematics.axle_speed``), yaw rate
    w = v_c tan(alpha) / L and its steering derivative, the control covariance Q_c
    (see the module docstring) and the nominal length Delta_k = t_{k+1} - t_k of the
    interval the sample is held over (the last sample: the median interval).

    Precomputed once, vectorised: the scalar per-step code then only needs cos/sin(phi).
    """
    v_c, J = kinematics.axle_speed(odometry.speed, odometry.steering, vehicle)
    v_c, J = np.atleast_1d(v_c), np.atleast_2d(J)
    alpha = odometry.steering
    ta = np.tan(alpha)
    w = v_c * ta / vehicle.L
    dw = v_c * (1.0 + ta * ta) / vehicle.L
    sv2, sa2 = sigma_speed**2, sigma_steer**2
    q00 = J[:, 0] ** 2 * sv2 + J[:, 1] ** 2 * sa2
    q01 = J[:, 1] * sa2
    q11 = np.full(v_c.shape, sa2)
    dt = np.diff(odometry.t)
    last = float(np.median(dt)) if dt.size else 0.0
    span = np.append(dt, last)
    cols = np.column_stack([v_c, alpha, ta, w, dw, q00, q01, q11, span])
    return [tuple(row) for row in cols.tolist()]


# --------------------------------------------------------------------------- the filter

def _observe(pose, lms):
    """Range/bearing of landmarks lms (N, 2) from the laser pose (3,) and the Jacobians
    H_pose (N, 2, 3), H_lm (N, 2, 2): ``observation.observe`` (same formulas), inlined
    without its input checks because it runs every scan."""
    dx = lms[:, 0] - pose[0]
    dy = lms[:, 1] - pose[1]
    q = dx * dx + dy * dy
    if q.size and q.min() < 1e-18:
        raise ValueError("a landmark coincides with the sensor position (range < 1e-9 m)")
    r = np.sqrt(q)
    b = np.arctan2(dy, dx) - pose[2] + _PI / 2
    b = np.where((b > -_PI) & (b <= _PI), b, _PI - np.mod(_PI - b, _TWO_PI))
    Hl = np.empty((lms.shape[0], 2, 2))
    Hl[:, 0, 0] = dx / r
    Hl[:, 0, 1] = dy / r
    Hl[:, 1, 0] = -dy / q
    Hl[:, 1, 1] = dx / q
    Hp = np.zeros((lms.shape[0], 2, 3))
    Hp[:, :, :2] = -Hl
    Hp[:, 1, 2] = -1.0
    return np.column_stack([r, b]), Hp, Hl


def _wrap(a):
    """Angle differences to [-pi, pi): a - 2 pi floor((a + pi) / 2 pi), five cheap array
    operations (``np.mod`` costs ten times more). Used for predicted bearings and
    innovations, where only the size of the difference matters; the state's heading is
    wrapped to (-pi, pi] as ``geometry.wrap_angle`` does."""
    return a - _TWO_PI * np.floor((a + _PI) / _TWO_PI)


def check_initial(x0, P0, vehicle: Vehicle, motion_model: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate a filter's start (shared by :class:`EkfSlam` and the dense reference):
    x0 (3,) and P0 (3, 3) finite, P0 symmetric PSD, a Vehicle, a known motion model.
    Returns float copies of x0 and P0."""
    if motion_model not in MOTION_MODELS:
        raise ValueError(f"motion_model must be one of {MOTION_MODELS}, got {motion_model!r}")
    x0 = np.array(x0, dtype=float)
    P0 = np.array(P0, dtype=float)
    if x0.shape != (3,) or P0.shape != (3, 3):
        raise ValueError(f"x0 must be (3,) and P0 (3, 3), got {x0.shape} and {P0.shape}")
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(P0))):
        raise ValueError("initial state or covariance contains NaN or infinite values")
    if np.max(np.abs(P0 - P0.T)) > 1e-12 * max(1.0, np.max(np.abs(P0))):
        raise ValueError("initial covariance P0 must be symmetric")
    if np.min(np.linalg.eigvalsh(P0)) < -1e-12:
        raise ValueError("initial covariance P0 must be positive semi-definite")
    if not isinstance(vehicle, Vehicle):
        raise ValueError(f"vehicle must be a Vehicle, got {type(vehicle).__name__}")
    return x0, P0


class EkfSlam:
    """The efficient EKF-SLAM state (x, P) and its operations (module docstring).

    x0 (3,): initial laser pose; P0 (3, 3): its covariance (symmetric, PSD, finite);
    motion_model: 'euler' or 'midpoint' (:class:`SlamConfig`).
    ``ekf_dense.DenseEkfSlam`` has the same interface with textbook dense algebra.
    Read the state through :meth:`state` (or ``pose``, ``pose_cov``,
    :meth:`landmark_covs`): between calls the vehicle block lives in Python floats, the
    cross covariance may await its compounded prediction, and ``self.P`` holds only
    its upper triangle up to date.
    """

    def __init__(self, x0, P0, vehicle: Vehicle, motion_model: str = "euler") -> None:
        x0, P0 = check_initial(x0, P0, vehicle, motion_model)
        self._mid = motion_model == "midpoint"
        self.vehicle = vehicle
        self._a, self._b, self._L = vehicle.a, vehicle.b, vehicle.L
        self.x = x0.copy()
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = np.ascontiguousarray(0.5 * (P0 + P0.T))
        # The landmarks' 2x2 marginal blocks, kept compact beside P for gating (the
        # diagonal of P's landmark part, and the x-y covariances): gathering them from P
        # after each update (a cache miss per row) cost more than the rest of the gating.
        self._ld = np.empty(0)
        self._lo = np.empty(0)
        self._load_vehicle()

    # ---- vehicle block held as Python floats between flushes
    def _load_vehicle(self) -> None:
        self._px, self._py, self._pphi = self.x[:3].tolist()
        b = self.P[:3, :3].ravel().tolist()
        self._p = [b[0], b[1], b[2], b[4], b[5], b[8]]
        self._f0 = self._f1 = 0.0
        self._dirty = False
        self._om = None                    # cached gating Jacobians are stale

    def flush(self) -> None:
        """Write the compounded prediction into (x, P): the pose, the 3x3 block, and
        the cross covariance multiplied ONCE by F_total = [[1,0,f0],[0,1,f1],[0,0,1]]."""
        if not self._dirty:
            return
        P, x = self.P, self.x
        x[:3] = (self._px, self._py, self._pphi)
        f0, f1 = self._f0, self._f1
        if P.shape[0] > 3:                 # the upper triangle holds P (see _correct)
            P[:2, 3:] += np.multiply.outer((f0, f1), P[2, 3:])
        p00, p01, p02, p11, p12, p22 = self._p
        n = P.shape[0]
        P.reshape(-1)[[0, 1, 2, n, n + 1, n + 2, 2 * n, 2 * n + 1, 2 * n + 2]] = (
            p00, p01, p02, p01, p11, p12, p02, p12, p22)
        self._f0 = self._f1 = 0.0
        self._dirty = False

    def predict(self, u, dt: float) -> None:
        """One Euler step of ``kinematics.predict`` of length ``dt`` with the control row
        ``u`` of :func:`control_table`, process noise dt * Delta B Q_c B^T (scalar code:
        the vehicle block only; the cross covariance waits for :meth:`flush`)."""
        if dt <= 0.0:
            return
        v, _, ta, w, dw, q00, q01, q11, span = u
        a, b, L = self._a, self._b, self._L
        phi = self._pphi
        if self._mid:
            c, s = math.cos(phi + 0.5 * dt * w), math.sin(phi + 0.5 * dt * w)
        else:
            c, s = math.cos(phi), math.sin(phi)
        lx = a * s + b * c
        ly = a * c - b * s
        vx = v * c - w * lx
        vy = v * s + w * ly
        f0 = dt * (-v * s - w * ly)
        f1 = dt * vx
        self._px += dt * vx
        self._py += dt * vy
        phi += dt * w
        if not -_PI < phi <= _PI:
            phi = _PI - (_PI - phi) % _TWO_PI
        self._pphi = phi
        # B = d rate / d (v_c, alpha); noise N = k B Q_c B^T with k = dt * Delta.
        tl = ta / L
        b00, b01 = c - tl * lx, -dw * lx
        b10, b11 = s + tl * ly, dw * ly
        b20, b21 = tl, dw
        k = dt * span
        g00, g01 = b00 * q00 + b01 * q01, b00 * q01 + b01 * q11      # row 0 of B Q
        g10, g11 = b10 * q00 + b11 * q01, b10 * q01 + b11 * q11
        g20, g21 = b20 * q00 + b21 * q01, b20 * q01 + b21 * q11
        p00, p01, p02, p11, p12, p22 = self._p
        self._p = [p00 + 2.0 * f0 * p02 + f0 * f0 * p22 + k * (g00 * b00 + g01 * b01),
                   p01 + f0 * p12 + f1 * p02 + f0 * f1 * p22 + k * (g00 * b10 + g01 * b11),
                   p02 + f0 * p22 + k * (g00 * b20 + g01 * b21),
                   p11 + 2.0 * f1 * p12 + f1 * f1 * p22 + k * (g10 * b10 + g11 * b11),
                   p12 + f1 * p22 + k * (g10 * b20 + g11 * b21),
                   p22 + k * (g20 * b20 + g21 * b21)]
        self._f0 += f0
        self._f1 += f1
        self._dirty = True

    # ---- read access
    @property
    def n_landmarks(self) -> int:
        return (self.x.size - 3) // 2

    @property
    def pose(self) -> np.ndarray:
        return np.array([self._px, self._py, self._pphi])

    @property
    def pose_cov(self) -> np.ndarray:
        p00, p01, p02, p11, p12, p22 = self._p
        return np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, P) after a flush, P made whole (the arrays themselves, not copies)."""
        self.flush()
        self._symmetrize()
        return self.x, self.P

    def landmarks(self) -> np.ndarray:
        return self.x[3:].reshape(-1, 2)

    def landmark_covs(self) -> np.ndarray:
        """(N, 2, 2) marginal covariances of the landmarks (a strided view of P)."""
        self.flush()
        self._symmetrize()
        return _diag_blocks(self.P)

    # ---- observations
    def _sync_blocks(self) -> None:
        """Refresh the compact landmark blocks from P (they drift from it only by rounding)."""
        self._ld = np.diagonal(self.P)[3:].copy()
        self._lo = np.diagonal(self.P, 1)[3::2].copy()

    def observation_model(self, sigma_range: float, sigma_bearing: float):
        """Predicted (range, bearing) of every landmark, zhat (N, 2), and the innovation
        covariances S (N, 2, 2) for gating, elementwise over the landmarks.

        With u = (dx, dy) / r the unit vector to the landmark and w = (-u_y, u_x), the
        Jacobians are H_landmark = J = [u^T; w^T / r] = -H_pose[:, :2] and a heading
        column (0, -1), so H e = J (e_l - e_p) - (0, e_phi) and

            S = [[u'Mu, u'Mw / r - u'm], [., w'Mw / r^2 - 2 w'm / r + P_phiphi]] + R

        with M = Cov(l - p) and m = Cov(l - p, phi). In terms of cos 2theta = u_x^2 - u_y^2
        and sin 2theta = 2 u_x u_y: u'Mu, w'Mw = tr M / 2 -+ A, u'Mw = B with
        A = cos2 (m11 - m00) / 2 - sin2 m01, B = sin2 (m11 - m00) / 2 + cos2 m01.
        About fifty vector operations over the N landmarks instead of N small matrix
        products; the Jacobians are kept for an :meth:`update` from the same state."""
        self.flush()
        P, N = self.P, self.n_landmarks
        if N == 0:
            return np.empty((0, 2)), np.empty((0, 2, 2))
        d = self.x[3:].reshape(N, 2) - (self._px, self._py)
        dx, dy = d[:, 0], d[:, 1]
        q = dx * dx + dy * dy
        if q.min() < 1e-18:
            raise ValueError("a landmark coincides with the sensor position (range < 1e-9 m)")
        r = np.sqrt(q)
        zhat = np.empty((N, 2))
        zhat[:, 0] = r
        zhat[:, 1] = _wrap(np.arctan2(dy, dx) + (_PI / 2 - self._pphi))
        ir = 1.0 / r
        ux, uy = dx * ir, dy * ir
        cx, cy, cphi = P[0, 3:], P[1, 3:], P[2, 3:]        # Cov(x | y | phi, landmarks)
        p00, p01, p02, p11, p12, p22 = self._p
        ld = self._ld
        m00 = ld[0::2] - 2.0 * cx[0::2] + p00              # M = Cov(l - p)
        m01 = self._lo - cx[1::2] - cy[0::2] + p01
        m11 = ld[1::2] - 2.0 * cy[1::2] + p11
        v0 = cphi[0::2] - p02                              # m = Cov(l - p, phi)
        v1 = cphi[1::2] - p12
        cos2 = ux * ux - uy * uy
        sin2 = 2.0 * ux * uy
        half_diff = 0.5 * (m11 - m00)
        half_tr = 0.5 * (m00 + m11)
        A = cos2 * half_diff - sin2 * m01
        S = np.empty((N, 2, 2))
        S[:, 0, 0] = half_tr - A + sigma_range**2
        S[:, 0, 1] = S[:, 1, 0] = (sin2 * half_diff + cos2 * m01) * ir - (ux * v0 + uy * v1)
        S[:, 1, 1] = ((half_tr + A) * ir - 2.0 * (ux * v1 - uy * v0)) * ir \
            + (p22 + sigma_bearing**2)
        self._om = (self._px, self._py, self._pphi, N, zhat, (ux, uy, -uy * ir, ux * ir))
        return zhat, S

    def update(self, z, lm, sigma_range: float, sigma_bearing: float) -> tuple[float, int]:
        """One batch update with observations z (m, 2) of landmarks lm (m,) (indices;
        a landmark may appear twice). Returns (NIS, dof = 2m)."""
        self.flush()
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        lm_list = lm if type(lm) is list else np.asarray(lm, dtype=np.int64).ravel().tolist()
        m = len(lm_list)
        if m != z.shape[0]:
            raise ValueError(f"update: {z.shape[0]} observations but {m} landmark indices")
        if m and not 0 <= min(lm_list) <= max(lm_list) < self.n_landmarks:
            raise ValueError(f"update: landmark index out of range 0..{self.n_landmarks - 1}")
        if m == 0:
            return 0.0, 0
        uniq = list(dict.fromkeys(lm_list))                # first-seen order
        pos = [uniq.index(j) for j in lm_list] if len(uniq) < m else list(range(m))
        cols = [0, 1, 2]
        for j in uniq:
            cols += (3 + 2 * j, 4 + 2 * j)
        lm = np.array(lm_list)
        om = self._om
        if om is not None and om[:4] == (self._px, self._py, self._pphi, self.n_landmarks):
            zhat = om[4][lm]                               # from observation_model, same state
            Hl = np.empty((m, 2, 2))
            for i, jac in enumerate(om[5]):
                Hl[:, i // 2, i % 2] = jac[lm]
        else:
            zhat, _, Hl = _observe(self.x[:3], self.landmarks()[lm])
        k, c = 2 * m, len(cols)
        Hc = np.zeros((k, c))
        Hc[:, :2] = -Hl.reshape(k, 2)
        Hc[1::2, 2] = -1.0
        blocks = Hc[:, 3:].reshape(m, 2, c - 3)            # (obs, row, landmark column)
        p2 = 2 * np.array(pos)
        blocks[np.arange(m), :, p2] = Hl[:, :, 0]
        blocks[np.arange(m), :, p2 + 1] = Hl[:, :, 1]
        nu = z - zhat
        nu[:, 1] = [(b + _PI) % _TWO_PI - _PI for b in nu[:, 1].tolist()]
        return self._correct(np.array(cols), Hc, nu.ravel(),
                             np.array([sigma_range**2, sigma_bearing**2] * m))

    def gps_update(self, xy, sigma_gps: float, gate: float = math.inf) -> tuple[float, bool]:
        """Position fix of the laser point: H = [I2 0 ...]. Rejected (no change) if its NIS
        exceeds ``gate``. Returns (NIS, accepted)."""
        self.flush()
        nu = np.asarray(xy, dtype=float) - self.x[:2]
        nis, _ = self._correct(np.array([0, 1]), np.eye(2), nu, np.full(2, sigma_gps**2), gate)
        return nis, nis <= gate

    def _rows(self, cols) -> np.ndarray:
        """Full rows ``cols`` of the symmetric P from its upper triangle: row c is the
        column above the diagonal, P[:c, c], then the row from the diagonal on, P[c, c:]."""
        P = self.P
        G = np.empty((len(cols), P.shape[0]))
        for r, c in enumerate(cols):
            G[r, :c] = P[:c, c]
            G[r, c:] = P[c, c:]
        return G

    def _symmetrize(self) -> None:
        """Copy the upper triangle (the stored covariance) into the lower one, so that P
        can be read as a whole (checkpoints and results; O(n^2), never per scan)."""
        P = self.P
        lower = np.tril_indices(P.shape[0], -1)
        P[lower] = P.T[lower]

    def _correct(self, cols, Hc, nu, Rd, gate: float = math.inf):
        P = self.P
        HP = Hc @ self._rows(cols)                         # (k, n) = H P
        S = HP[:, cols] @ Hc.T
        S = 0.5 * (S + S.T)
        S.flat[::S.shape[0] + 1] += Rd
        Lc, info = dpotrf(S, lower=1, clean=1)             # S = L L^T
        if info != 0:
            raise InnovationError(
                "innovation covariance S is not positive definite (singular): eigenvalues "
                f"{np.linalg.eigvalsh(S)}; check for zero measurement noise")
        e, info = dtrtrs(Lc, nu, lower=1)                  # e = L^-1 nu
        nis = float(e @ e)
        if not math.isfinite(nis):
            raise ValueError("update produced a non-finite innovation (NaN in the state?)")
        if nis > gate:
            return nis, nu.size
        # W = P H^T L^-T (n, k), Fortran-contiguous: solve W L^T = (HP)^T in place.
        W = dtrsm(1.0, Lc, HP.T, side=1, lower=1, trans_a=1, overwrite_b=1)
        self.x += W @ e
        # P -= W W^T in place, on the upper triangle only (half the memory traffic of a
        # full dgemm; the update is memory-bound): P.T is Fortran-contiguous, so dsyrk
        # writes into P itself, and the Fortran lower triangle of P.T is P's upper one.
        out = dsyrk(-1.0, W, beta=1.0, c=P.T, lower=1, overwrite_c=1)
        if not np.may_share_memory(out, P):       # the silent-copy pitfall: never let it pass
            raise RuntimeError("in-place covariance update worked on a copy")
        if self._lo.size:                                  # the compact landmark blocks too
            Wl = W[3:]
            self._ld -= np.einsum("ij,ij->i", Wl, Wl)
            self._lo -= np.einsum("ij,ij->i", Wl[0::2], Wl[1::2])
        x2 = float(self.x[2])
        if not -_PI < x2 <= _PI:
            self.x[2] = _PI - (_PI - x2) % _TWO_PI
        self._load_vehicle()
        return nis, nu.size

    def augment(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """Add landmarks for observations z (k, 2) from the current pose
        (``observation.inverse_observe``). Returns their indices."""
        self.flush()
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        k = z.shape[0]
        N0 = self.n_landmarks
        if k == 0:
            return np.empty(0, dtype=np.int64)
        lm, Jp, Jz = inverse_observe(self.x[:3], z)
        n = self.x.size
        P = self.P
        Jp2 = Jp.reshape(2 * k, 3)
        A = Jp2 @ self._rows((0, 1, 2))                   # (2k, n) = J_pose P_v*
        Pn = np.empty((n + 2 * k, n + 2 * k))
        Pn[:n, :n] = P
        Pn[n:, :n] = A
        Pn[:n, n:] = A.T
        Pnn = A[:, :3] @ Jp2.T
        R = np.diag([sigma_range**2, sigma_bearing**2])
        JRJ = Jz @ R @ Jz.transpose(0, 2, 1)
        for i in range(k):
            Pnn[2 * i:2 * i + 2, 2 * i:2 * i + 2] += JRJ[i]
        Pn[n:, n:] = 0.5 * (Pnn + Pnn.T)
        self.P = Pn
        self._ld = np.concatenate([self._ld, np.diagonal(Pn)[n:]])
        self._lo = np.concatenate([self._lo, np.diagonal(Pn, 1)[n::2]])
        self.x = np.concatenate([self.x, lm.ravel()])
        self._om = None
        return np.arange(N0, N0 + k)

    def remove(self, idx) -> None:
        """Delete landmarks ``idx`` (marginalise them out: drop their rows and columns).
        Copied block by block between the removed rows: about one copy of P."""
        idx = np.unique(np.asarray(idx, dtype=np.int64).ravel())
        if idx.size == 0:
            return
        self.flush()
        n = self.x.size
        drop = np.sort(np.concatenate([3 + 2 * idx, 4 + 2 * idx]))
        keep = np.ones(n, dtype=bool)
        keep[drop] = False
        starts = np.concatenate([[0], drop + 1])
        ends = np.concatenate([drop, [n]])
        runs = [(a, b) for a, b in zip(starts.tolist(), ends.tolist()) if b > a]
        m = n - drop.size
        Pn = np.empty((m, m))
        P = self.P
        r0 = 0
        for a, b in runs:
            c0 = 0
            for c, d in runs:
                Pn[r0:r0 + b - a, c0:c0 + d - c] = P[a:b, c:d]
                c0 += d - c
            r0 += b - a
        self.P = Pn
        self.x = self.x[keep]
        self._ld = self._ld[keep[3:]]
        self._lo = np.delete(self._lo, idx)
        self._om = None

    def health(self) -> tuple[float, float]:
        """(smallest eigenvalue of P, max |P - P^T|). P is stored as its upper triangle
        (symmetric by construction), so the asymmetry is that of the matrix made whole,
        i.e. zero; the dense reference's is a real measurement."""
        self.flush()
        self._symmetrize()
        self._sync_blocks()
        P = self.P
        lo = float(eigh(P, eigvals_only=True, subset_by_index=[0, 0], check_finite=False)[0])
        return lo, float(np.max(np.abs(P - P.T)))


def _diag_blocks(P) -> np.ndarray:
    """The landmarks' 2x2 diagonal blocks of the C-contiguous P as a (N, 2, 2) strided view."""
    n = P.shape[0]
    N = (n - 3) // 2
    s = P.strides[1]
    return np.lib.stride_tricks.as_strided(P[3:, 3:], shape=(N, 2, 2),
                                           strides=((2 * n + 2) * s, n * s, s), writeable=False)


# --------------------------------------------------------------------------- results

@dataclass
class ObservationLog:
    """One row per detection of every processed scan (for the ANN chapters).

    scan: scan index (into the detections); t: scan time (s); range (m), bearing (rad),
    intensity (0..4), diameter (m, cluster width / trunk diameter, NaN if none);
    true_id: the simulator's landmark id (else -1); status: see :data:`STATUS`;
    landmark: index into ``SlamResult.landmarks`` of the landmark it was associated with
    or created (-1: none, or a tentative landmark later deleted); pose_prior (n, 3): the
    predicted pose the association used; pose (n, 3): the pose after the scan's update.
    """

    scan: np.ndarray
    t: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    intensity: np.ndarray
    diameter: np.ndarray
    true_id: np.ndarray
    status: np.ndarray
    landmark: np.ndarray
    pose_prior: np.ndarray
    pose: np.ndarray

    def __len__(self) -> int:
        return self.scan.size


@dataclass
class SlamResult:
    """What :func:`run` returns.

    trajectory (K, 4): (t, x, y, phi) of the laser pose AFTER the update of every
    processed scan; scan_index (K,): the scan of each row; pose_cov (K, 3, 3).
    odometry_trajectory (J, 4): the filtered pose at every odometry sample (predicted to
    that time, i.e. using all data before it): the dense track for errors against GPS.
    landmarks (M, 2), landmark_cov (M, 2, 2): the final map (tentative landmarks that
    failed their probation removed); landmark_observations: list of M arrays, the scans
    that observed each landmark; landmark_true_id (M,): majority vote of the
    simulator's ids of those observations (-1 where unknown).
    nis: dict of arrays, one entry per update: t, scan (-1 for GPS), kind (0 laser batch,
    1 GPS), nis, dof (2 x observations), accepted (False: a GPS fix beyond its gate).
    counts: predicts (prediction steps), scans, scans_skipped (before the first odometry
    sample), updates (laser batch updates), gps_updates, gps_rejected, gps_skipped
    (outside the GPS mode's window), observations, associated, new, rejected,
    out_of_range (per detection, summing to observations), landmarks_created,
    landmarks_removed (tentative ones deleted), landmarks (final).
    health: dict of arrays scan, t, n (state size), min_eig (smallest eigenvalue of P),
    asymmetry (max |P - P^T|), at every ``checkpoint_every`` scans and at the end.
    state, covariance: final x and P. observations: :class:`ObservationLog`.
    runtime: seconds of the whole call (features included); config, initial_pose (3,)
    at the first odometry time, initial_info (policy, and the GPS fit's numbers).
    """

    trajectory: np.ndarray
    scan_index: np.ndarray
    pose_cov: np.ndarray
    odometry_trajectory: np.ndarray
    landmarks: np.ndarray
    landmark_cov: np.ndarray
    landmark_observations: list
    landmark_true_id: np.ndarray
    nis: dict
    counts: dict
    health: dict
    state: np.ndarray
    covariance: np.ndarray
    observations: ObservationLog
    runtime: float
    config: SlamConfig
    initial_pose: np.ndarray
    initial_info: dict = field(default_factory=dict)

    def summary(self) -> str:
        c = self.counts
        return (f"{c['scans']} scans, {c['landmarks']} landmarks, {c['associated']} associated / "
                f"{c['new']} new / {c['rejected']} rejected observations, min eigenvalue "
                f"{np.min(self.health['min_eig']):.2e}, {self.runtime:.2f} s")


# --------------------------------------------------------------------------- the run

def _resolve_dataset(dataset) -> Dataset:
    if isinstance(dataset, str):
        from . import datasets
        if dataset not in ("car_park", "victoria_park"):
            raise ValueError(f"unknown dataset {dataset!r}: pass 'car_park', 'victoria_park' or "
                             "a records.Dataset (e.g. from simulate.simulate())")
        return datasets.load(dataset)
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be a records.Dataset or a dataset name, got "
                         f"{type(dataset).__name__}")
    return dataset


def _detections(dataset: Dataset, source: str) -> Detections:
    from . import features                   # beacon extraction, only when needed
    return features.detections_for(dataset, source=source)


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


def _openblas_thread_controls() -> list:
    """(set, get) thread-count functions of every OpenBLAS loaded in this process (NumPy
    and SciPy each bundle one), found through /proc/self/maps; empty elsewhere."""
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh
                     if "openblas" in line.lower() and ".so" in line.rsplit("/", 1)[-1]}
    except OSError:
        return []
    out = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    get.restype, put.argtypes = ctypes.c_int, [ctypes.c_int]
                    out.append((put, get))
    return out


@contextlib.contextmanager
def one_blas_thread():
    """Run the enclosed code with single-threaded BLAS, then restore the thread counts.

    The filter's BLAS calls are small (rank-2m updates, n <= ~700): a second thread
    helps little and, when the other core is busy, OpenBLAS's spinning threads make a
    Victoria Park run many times slower (measured: 54 s instead of 4 s). ``run`` uses this
    whatever OMP_NUM_THREADS says. Uses threadpoolctl if installed, else the OpenBLAS
    libraries' own setters (Linux); elsewhere it changes nothing."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
        return
    saved = []
    try:
        for put, get in _openblas_thread_controls():
            saved.append((put, get()))
            put(1)
        yield
    finally:
        for put, n in saved:
            put(n)


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
    reference ``ekf_dense.DenseEkfSlam``; slow, for checks).

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
        config = SlamConfig.for_dataset(ds.name) if ds.name in DATASET_NAMES else SlamConfig()
    if not isinstance(config, SlamConfig):
        raise ValueError(f"config must be a SlamConfig, got {type(config).__name__}")
    cfg = config
    if backend == "efficient":
        make = EkfSlam
    elif backend == "dense":
        from .ekf_dense import DenseEkfSlam as make
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
    gate = float(chi2.ppf(cfg.gate_prob, 2))
    new_thr = float(chi2.ppf(cfg.new_landmark_prob, 2))
    gps_gate = math.inf if cfg.gps_gate_prob >= 1.0 else float(chi2.ppf(cfg.gps_gate_prob, 2))
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
                assign = _associate(_mahalanobis(z, zhat, S), gate, new_thr).tolist()
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
        landmarks=x[3:].reshape(-1, 2).copy(), landmark_cov=_diag_blocks(P).copy(),
        landmark_observations=lm_obs, landmark_true_id=lm_true, nis=nis, counts=counts,
        health=health, state=x, covariance=P, observations=log,
        runtime=time.perf_counter() - t_start, config=cfg, initial_pose=pose0,
        initial_info=init_info)


def _mahalanobis(z, zhat, S) -> np.ndarray:
    """d2 (n, N) of observations z (n, 2) to predictions zhat (N, 2) with covariances S:
    ``association.mahalanobis`` (same formula: explicit inverse of the symmetric 2x2 S,
    bearing difference wrapped) without its input checks, which cost more than the
    arithmetic when run every scan; tests/test_ekf_slam.py checks the two agree. An S
    that is not positive definite still raises (the module's own error)."""
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    det = a * c - b * b
    if det.min() <= 0.0 or a.min() <= 0.0:
        association.mahalanobis(z, zhat, S)                # raises, naming the landmark
    nu_r = z[:, 0, None] - zhat[:, 0]
    nu_b = _wrap(z[:, 1, None] - zhat[:, 1])
    return (c * nu_r * nu_r - 2.0 * b * nu_r * nu_b + a * nu_b * nu_b) / det


def _associate(d2, gate: float, new_landmark: float) -> np.ndarray:
    """``association.associate`` (gated nearest neighbour with mutual exclusion), with a
    fast path for the common scan where no two observations compete: every observation
    has at most one landmark in its gate and every landmark at most one observation.
    Then the greedy assignment is simply those pairs, and the rest is new
    (d2 > new_landmark to every landmark) or rejected. Otherwise the general function."""
    i, j = np.nonzero(d2 <= gate)
    il, jl = i.tolist(), j.tolist()
    if len(set(il)) == len(il) and len(set(jl)) == len(jl):
        out = np.where(d2.min(axis=1) > new_landmark, association.NEW, association.REJECTED)
        out[i] = j
        return out.astype(np.int64)
    return np.asarray(association.associate(d2, gate=gate, new_landmark=new_landmark),
                      dtype=np.int64)


def _nis_arrays(rows) -> dict:
    names = ("t", "scan", "kind", "nis", "dof", "accepted")
    types = (float, np.int64, np.int8, float, np.int64, bool)
    return {n: np.array([r[i] for r in rows], dtype=ty) for i, (n, ty) in enumerate(zip(names, types))}


def _landmark_history(log: ObservationLog, M: int):
    ok = log.landmark >= 0
    lm, scan, tid = log.landmark[ok], log.scan[ok], log.true_id[ok]
    order = np.argsort(lm, kind="stable")
    lm, scan, tid = lm[order], scan[order], tid[order]
    bounds = np.searchsorted(lm, np.arange(M + 1))
    history = [scan[bounds[j]:bounds[j + 1]] for j in range(M)]
    true = np.full(M, -1, dtype=np.int64)
    for j in range(M):
        ids = tid[bounds[j]:bounds[j + 1]]
        ids = ids[ids >= 0]
        if ids.size:
            vals, cnt = np.unique(ids, return_counts=True)
            true[j] = vals[np.argmax(cnt)]
    return history, true


def pose_nees(result: SlamResult, dataset: Dataset) -> np.ndarray:
    """Normalised estimation error squared of the pose at every trajectory row (3 dof),
    e^T P^-1 e with e = estimate - truth (heading wrapped), against the simulator's true
    laser poses at the scan times (``dataset.info['scan_poses']``). Notebook 05."""
    if dataset.truth is None or "scan_poses" not in dataset.info:
        raise ValueError("pose_nees needs a simulated dataset (with info['scan_poses'])")
    truth = np.asarray(dataset.info["scan_poses"])[result.scan_index]
    e = result.trajectory[:, 1:4] - truth
    e[:, 2] = wrap_angle(e[:, 2])
    return np.einsum("ki,ki->k", e, np.linalg.solve(result.pose_cov, e[..., None])[..., 0])
