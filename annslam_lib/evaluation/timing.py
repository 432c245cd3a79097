"""Cost per step of EKF-SLAM as the map grows: the efficient filter (``slam.efficient.EkfSlam``)
against the dense textbook reference (``slam.dense.DenseEkfSlam``) (notebook 06 "cost per
step"; the same measurement as benchmarks/bench_ekf_slam.py, whose code is not part of the
library).

One *step* is what the filter does most often on a real run: one odometry prediction
(for the efficient filter including its deferred cross-covariance work, ``flush``) and
one update with one observation of a random landmark. Both filters start from the same
state built by :func:`random_filter` and see the same controls and measurements, so they
do the same arithmetic in two ways (``tests/test_timing.py`` checks they end in the
same state). Timings depend on the machine and its load: print them, never compare them
digit for digit.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..slam.dense import DenseEkfSlam
from ..slam.efficient import EkfSlam
from ..models.motion import control_table
from ..slam.threads import one_blas_thread
from .. import _checks
from ..models.observation import observe
from ..data.records import Odometry
from ..models.vehicle import ACFR_UTE, Vehicle

__all__ = ["SIGMA_RANGE", "SIGMA_BEARING", "random_filter", "step_controls", "StepTimes",
           "time_steps", "StepCost", "step_costs", "loglog_slope"]

#: Measurement noise of the timed updates (m, rad): the Car Park values.
SIGMA_RANGE, SIGMA_BEARING = 0.1, math.radians(1.0)
#: A step's prediction interval (s): the odometry period.
DT = 0.025


def random_filter(cls, n_landmarks: int, *, seed: int = 0, vehicle: Vehicle = ACFR_UTE):
    """A filter of class ``cls`` (``EkfSlam``, ``DenseEkfSlam`` or a subclass) holding ``n_landmarks``
    landmarks: pose (0, 0, 0.3) with a small covariance, then one augmentation with
    ranges 3..40 m and bearings 0.05..3.1 rad drawn from ``seed`` (the same seed gives the
    same state for both classes).

    Parameters
    ----------
    cls : type
        ``EkfSlam``, ``DenseEkfSlam`` or a subclass.
    n_landmarks : int
        Landmarks in the state, >= 1.
    seed : int, optional
        Seed of the drawn measurements.
    vehicle : Vehicle, optional
        The car of the filter.

    Returns
    -------
    EkfSlam or DenseEkfSlam
        The filter, an instance of ``cls``, with state size 3 + 2 n_landmarks.

    Raises
    ------
    TypeError
        If ``cls`` is not one of the filter classes, or ``n_landmarks`` not an integer.
    ValueError
        If ``n_landmarks`` < 1.
    """
    if not (isinstance(cls, type) and issubclass(cls, (EkfSlam, DenseEkfSlam))):
        raise TypeError(f"cls must be slam.efficient.EkfSlam or slam.dense.DenseEkfSlam (or a "
                         f"subclass), got {cls!r}")
    n_landmarks = _checks.integer("n_landmarks", n_landmarks, lo=1)
    rng = np.random.default_rng(seed)
    f = cls(np.array([0.0, 0.0, 0.3]), np.diag([0.01, 0.01, 0.001]), vehicle)
    z = np.column_stack([rng.uniform(3.0, 40.0, n_landmarks), rng.uniform(0.05, 3.1, n_landmarks)])
    f.augment(z, SIGMA_RANGE, SIGMA_BEARING)
    return f


def step_controls(n: int = 200, vehicle: Vehicle = ACFR_UTE) -> list:
    """``n`` control rows (``models.motion.control_table``) of a car at 2 m/s with a slowly
    swinging steering angle, odometry every 25 ms, ACFR process noise.

    Parameters
    ----------
    n : int, optional
        Number of rows, >= 2.
    vehicle : Vehicle, optional
        The car.

    Returns
    -------
    list of tuple
        ``n`` rows of ``models.motion.control_table``.

    Raises
    ------
    TypeError, ValueError
        If ``n`` is not an integer >= 2.
    """
    n = _checks.integer("n", n, lo=2)
    k = np.arange(n)
    odo = Odometry(t=k * DT, speed=np.full(n, 2.0), steering=0.2 * np.sin(k / 20))
    return control_table(odo, vehicle, 0.7, math.radians(7.0))


@dataclass(frozen=True)
class StepTimes:
    """Mean wall-clock seconds per step of :func:`time_steps`: predict (with flush),
    update (one observation), and their sum; ``steps`` timed."""

    predict: float
    update: float
    steps: int

    @property
    def step(self) -> float:
        return self.predict + self.update


def time_steps(f, steps: int, controls: list, *, seed: int = 0) -> StepTimes:
    """Run ``steps`` steps on filter ``f`` (modified in place) and time them.

    Step k: predict with ``controls[k % len(controls)]`` over 25 ms and flush; then one
    update with a measurement of landmark j (drawn from ``seed``) made from the filter's
    own prediction plus noise of (SIGMA_RANGE, SIGMA_BEARING). Only the predict/flush and
    the update are inside the timers (not the making of the measurement).

    Parameters
    ----------
    f : EkfSlam or DenseEkfSlam
        A filter holding at least one landmark (:func:`random_filter`).
    steps : int
        Number of steps, >= 1.
    controls : list of tuple
        Control rows (:func:`step_controls`), used in turn.
    seed : int, optional
        Seed of the landmarks observed and the measurement noise.

    Returns
    -------
    StepTimes
        Mean wall-clock seconds per step of the prediction and of the update.

    Raises
    ------
    ValueError
        For no control rows, a filter without landmarks, or ``steps`` < 1.
    """
    steps = _checks.integer("steps", steps, lo=1)
    if not controls:
        raise ValueError("controls must hold at least one control row (models.motion.control_table)")
    N = f.n_landmarks
    if N < 1:
        raise ValueError("the filter holds no landmark to observe")
    rng = np.random.default_rng(seed)
    t_pred = t_upd = 0.0
    clock = time.perf_counter
    for k in range(steps):
        u = controls[k % len(controls)]
        j = int(rng.integers(N))
        noise = rng.normal(0.0, [SIGMA_RANGE, SIGMA_BEARING])
        t0 = clock()
        f.predict(u, DT)
        f.flush()
        t1 = clock()
        zhat, _, _ = observe(f.pose, f.landmarks()[j])
        z = zhat + noise
        t2 = clock()
        f.update(z[None], [j], SIGMA_RANGE, SIGMA_BEARING)
        t3 = clock()
        t_pred += t1 - t0
        t_upd += t3 - t2
    return StepTimes(predict=t_pred / steps, update=t_upd / steps, steps=steps)


@dataclass(frozen=True)
class StepCost:
    """One row of :func:`step_costs`: N landmarks (state size n = 3 + 2N), the efficient
    filter's times and the dense filter's (None if not measured at this N)."""

    N: int
    efficient: StepTimes
    dense: StepTimes | None

    @property
    def n(self) -> int:
        return 3 + 2 * self.N

    @property
    def ratio(self) -> float | None:
        """Dense step time over efficient step time."""
        return None if self.dense is None else self.dense.step / self.efficient.step


def step_costs(sizes=(50, 150, 300), *, dense_sizes=None, efficient_steps: int = 1000,
               dense_budget: float = 60.0, seed: int = 0) -> list[StepCost]:
    """Time both filters at each map size in ``sizes`` (landmarks).

    The efficient filter runs ``efficient_steps`` steps at every size; the dense one only
    at the sizes in ``dense_sizes`` (default: all) and for max(3, dense_budget (50/N)^2)
    steps, since its cost grows about as N^3 (60 steps at N = 50, 3 at N = 300). Each
    filter first runs a few untimed warm-up steps. BLAS runs on one thread, as in
    ``slam.runner.run``.

    Parameters
    ----------
    sizes : sequence of int, optional
        Map sizes N (landmarks), each >= 1.
    dense_sizes : sequence of int, optional
        The sizes at which the dense filter is timed too (default: all).
    efficient_steps : int, optional
        Timed steps of the efficient filter per size.
    dense_budget : float, optional
        Timed steps of the dense filter at N = 50, scaled by (50/N)^2 at other sizes.
    seed : int, optional
        Seed of the states and measurements.

    Returns
    -------
    list of StepCost
        One per size, in the order given.

    Raises
    ------
    ValueError
        For no sizes or a setting out of range.
    """
    sizes = [_checks.integer("sizes entry", N, lo=1) for N in sizes]
    if not sizes:
        raise ValueError("sizes must name at least one map size")
    dense_sizes = set(sizes if dense_sizes is None else
                      [_checks.integer("dense_sizes entry", N, lo=1) for N in dense_sizes])
    efficient_steps = _checks.integer("efficient_steps", efficient_steps, lo=1)
    if not (isinstance(dense_budget, (int, float)) and math.isfinite(dense_budget)
            and dense_budget > 0):
        raise ValueError(f"dense_budget must be a positive number, got {dense_budget!r}")
    controls = step_controls()
    with one_blas_thread():
        return [_step_cost(N, N in dense_sizes, controls, efficient_steps, dense_budget, seed)
                for N in sizes]


def _step_cost(N, with_dense, controls, efficient_steps, dense_budget, seed) -> StepCost:
    eff = random_filter(EkfSlam, N, seed=seed)
    time_steps(eff, 20, controls, seed=seed + 1)                          # warm-up
    t_eff = time_steps(eff, efficient_steps, controls, seed=seed + 2)
    t_dense = None
    if with_dense:
        dense = random_filter(DenseEkfSlam, N, seed=seed)
        time_steps(dense, 2, controls, seed=seed + 1)
        t_dense = time_steps(dense, max(3, int(dense_budget * (50 / N) ** 2)), controls,
                             seed=seed + 2)
    return StepCost(N=N, efficient=t_eff, dense=t_dense)


def loglog_slope(x, y) -> float:
    """Least-squares slope of log(y) against log(x): the exponent p of y ~ c x^p.

    Parameters
    ----------
    x : array_like, shape (K,)
        Positive finite values, K >= 2, not all equal.
    y : array_like, shape (K,)
        Positive finite values.

    Returns
    -------
    float
        The exponent p.

    Raises
    ------
    ValueError
        For shapes that differ, fewer than 2 values, values that are not positive and
        finite, or x all equal.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 1 or x.shape != y.shape or x.size < 2:
        raise ValueError(f"x and y must be 1-D of the same length >= 2, got {x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(x > 0) and np.all(y > 0)):
        raise ValueError("x and y must be positive and finite (logarithms are taken)")
    lx = np.log(x)
    if np.ptp(lx) == 0:
        raise ValueError("x values are all equal: no slope")
    return float(np.polyfit(lx, np.log(y), 1)[0])
