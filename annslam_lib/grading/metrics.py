"""Checks of notebook 06's graded exercises (Victoria Park): the track's error against GPS
(section 3, :func:`annslam_lib.evaluation.trajectory.trajectory_errors`) and the GPS fixes no car could
have reached (section 3, :func:`annslam_lib.evaluation.trajectory.gps_outliers`).

The cases are synthetic drives at the ACFR rates (odometry-rate track at 40 Hz, GPS at
5 Hz on a clock offset from the odometry's) with what Victoria Park's GPS does: gaps of
seconds to a minute, fixes before the first and after the last track sample, a one-fix
spike, a jump after which the receiver stays off, jitter, and legitimate long moves across
a gap. Optionally the real run is added as one more case.

Every case is named in words in a failure (``case='#2: 60 s drive, ...'``), never printed
as its thousands of numbers.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..evaluation.trajectory import trajectory_errors
from ..data.records import Gps
from ..evaluation.trajectory import gps_outliers
from .core import (forbids, GradingError, Mistake, Passed, call, check_function, check_raises, fmt,
                   labelled)

__all__ = ["check_track_rmse", "check_gps_outliers"]


# ------------------------------------------------------------------------------ drives

def _path(rng, duration: float):
    """A smooth drive: position (x, y) and heading as functions of time (exact arcs of a
    slowly varying speed and turn rate), sampled finely enough to interpolate exactly."""
    t = np.arange(0.0, duration + 1e-9, 0.005)
    v = rng.uniform(2.0, 4.0) + rng.uniform(0.5, 2.0) * np.sin(t / rng.uniform(4, 9))
    w = rng.uniform(-0.3, 0.3) * np.sin(t / rng.uniform(3, 7) + rng.uniform(0, 6))
    phi = rng.uniform(-math.pi, math.pi) + np.concatenate([[0.0], np.cumsum(w[:-1]) * 0.005])
    x = np.concatenate([[0.0], np.cumsum(v[:-1] * np.cos(phi[:-1])) * 0.005])
    y = np.concatenate([[0.0], np.cumsum(v[:-1] * np.sin(phi[:-1])) * 0.005])
    origin = rng.uniform(-50, 50, 2)
    return t, x + origin[0], y + origin[1], phi


def _drive(rng, duration: float, *, gaps=(), before: float = 1.0, after: float = 0.6,
           spike_at: float | None = None):
    """(traj (K, 4) at 40 Hz with a slow drift, gps_t, gps_xy at 5 Hz with noise)."""
    t, x, y, phi = _path(rng, duration)
    t0 = rng.uniform(100.0, 1000.0)                 # the run's clock does not start at 0
    tk = np.arange(0.0, duration + 1e-9, 0.025)
    drift = np.c_[0.02 * tk + 0.3 * np.sin(tk / 7.0), -0.015 * tk + 0.2 * np.cos(tk / 5.0)]
    traj = np.c_[tk + t0, np.interp(tk, t, x) + drift[:, 0], np.interp(tk, t, y) + drift[:, 1],
                 (np.interp(tk, t, phi) + math.pi) % (2 * math.pi) - math.pi]
    offset = rng.uniform(0.003, 0.022)              # GPS clock not on the odometry grid
    gt = np.arange(-before + offset, duration + after, 0.2)
    keep = np.ones(gt.size, bool)
    for a, b in gaps:
        keep &= ~((gt > a) & (gt < b))
    gt = gt[keep]
    inside = np.clip(gt, 0.0, duration)             # the car stands still outside the drive
    gxy = np.c_[np.interp(inside, t, x), np.interp(inside, t, y)] + rng.normal(0, 0.3, (gt.size, 2))
    if spike_at is not None:
        k = int(np.argmin(np.abs(gt - spike_at)))
        gxy[k] += (120.0, -40.0)
    return traj, gt + t0, gxy


# ------------------------------------------------------------------------------ track RMSE

def _rmse_ref(traj, gps_t, gps_xy) -> float:
    gps = Gps(t=gps_t, east=gps_xy[:, 0], north=gps_xy[:, 1])
    return trajectory_errors(traj, gps).rmse


def _inside(traj, gps_t):
    return (gps_t >= traj[0, 0]) & (gps_t <= traj[-1, 0])


def _rmse_wrong(kind: str):
    def wrong(traj, gps_t, gps_xy):
        tt = traj[:, 0]
        ins = _inside(traj, gps_t)
        t, xy = gps_t[ins], gps_xy[ins]
        if kind == "clamped":                       # np.interp holds the end values outside
            t, xy = gps_t, gps_xy
        if kind == "nearest":
            k = np.clip(np.searchsorted(tt, t), 1, tt.size - 1)
            k = np.where(np.abs(tt[k - 1] - t) <= np.abs(tt[k] - t), k - 1, k)
            est = traj[k, 1:3]
        elif kind == "previous":
            est = traj[np.searchsorted(tt, t, side="right") - 1, 1:3]
        elif kind == "gps-interp":                  # GPS interpolated to the track's times
            s = (tt >= gps_t[0]) & (tt <= gps_t[-1])
            g = np.c_[np.interp(tt[s], gps_t, gps_xy[:, 0]), np.interp(tt[s], gps_t, gps_xy[:, 1])]
            return float(np.sqrt(np.mean(np.sum((traj[s, 1:3] - g)**2, axis=1))))
        else:
            est = np.c_[np.interp(t, tt, traj[:, 1]), np.interp(t, tt, traj[:, 2])]
        d = est - xy
        e = np.hypot(d[:, 0], d[:, 1])
        if kind == "mean":
            return float(np.mean(e))
        if kind == "mse":
            return float(np.mean(e**2))
        if kind == "per-axis":
            return float(np.sqrt(np.mean(d**2)))
        if kind == "median":
            return float(np.median(e))
        return float(np.sqrt(np.mean(e**2)))
    return wrong


# (kind, message, answer): the answer is shown only in the instructor's feedback.
_RMSE_MISTAKES = [
    ("mean", "this is the MEAN error, not the root-mean-square. (The RMS weighs large errors "
             "more; the chapter reports both it and the median because of that.)",
     "Square the errors, average, then take the square root."),
    ("mse", "this is the mean SQUARED error (m^2): take its square root to get metres.", ""),
    ("per-axis", "this is the RMS over the 2N coordinates (dx and dy averaged separately), "
                 "smaller by a factor sqrt(2): the error at a fix is a DISTANCE.",
     "The error at a fix is sqrt(dx^2 + dy^2), and the RMSE is the root of the mean of its "
     "square."),
    ("median", "this is the median error, not the RMSE.", ""),
    ("nearest", "the track is read at its NEAREST sample instead of being interpolated to the "
                "fix time: at 6 m/s a 12.5 ms difference is 7.5 cm.",
     "Interpolate x and y linearly in time (np.interp(gps_t, traj[:, 0], traj[:, 1]), and "
     "the same for y)."),
    ("previous", "the track is read at the last sample BEFORE each fix (a zero-order hold) "
                 "instead of being interpolated to the fix time.",
     "Interpolate x and y linearly in time (np.interp)."),
    ("clamped", "fixes before the first or after the last track sample are included: np.interp "
                "does not extrapolate, it repeats the end value, so those fixes are compared "
                "with a pose the car had at another time.",
     "Keep only the fixes with traj[0, 0] <= t <= traj[-1, 0]."),
    ("gps-interp", "the GPS is interpolated to the track's times. Across a GPS gap (up to a "
                   "minute in Victoria Park) the straight line between two fixes is not where "
                   "the car was.",
     "Compare only AT the fixes, interpolating the track (the 40 Hz estimate) to their "
     "times, and never the GPS."),
]


def _rmse_cases(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    table = {}

    def add(duration, note, **kw):
        traj, gt, gxy = _drive(rng, duration, **kw)
        ins = int(np.count_nonzero(_inside(traj, gt)))
        label = (f"#{len(table)}: {duration:.0f} s drive, {gt.size} GPS fixes ({gt.size - ins} "
                 f"outside the track's span){note}")
        table[label] = (traj, gt, gxy)

    add(40.0, ", a 9 s GPS gap in a turn", gaps=[(12.0, 21.0)])
    add(60.0, ", two gaps (5 s and 25 s)", gaps=[(8.0, 13.0), (30.0, 55.0)])
    add(30.0, ", every fix inside the track's span", before=-0.1, after=-0.1, gaps=[(10, 15)])
    add(50.0, ", a one-fix spike of 126 m", spike_at=33.0, gaps=[(40.0, 44.0)])
    for _ in range(max(n, 0)):
        d = float(rng.uniform(20.0, 80.0))
        a = float(rng.uniform(2.0, d - 15.0))
        add(d, "", gaps=[(a, a + rng.uniform(2.0, 12.0))])
    return table


def _real_run(name: str):
    """(track, GPS) of a real run, for a check that names it ('victoria_park'): the run's
    dead-reckoned laser track from its GPS-fitted start, and its GPS record. Computed by
    the check itself, so a grader needs nothing from the student's notebook."""
    from ..data import loaders as datasets
    from ..slam.dead_reckoning import dead_reckon, initial_pose_from_gps

    ds = datasets.load(name)
    fit = initial_pose_from_gps(ds.odometry, ds.gps, ds.vehicle)
    return dead_reckon(ds.odometry, fit.pose, ds.vehicle), ds.gps


@forbids(trajectory_errors)
def check_track_rmse(fn: Callable, *, seed: int = 0, n: int = 4, real=None) -> str:
    """Exercise 6.1 (notebook 06 section 3, the track against GPS): ``fn(traj, gps_t,
    gps_xy)`` must return the RMSE (m) of the track's position at the GPS fixes inside the
    track's time span, the track interpolated linearly to each fix time, as
    :func:`annslam_lib.evaluation.trajectory.trajectory_errors` ``.rmse``; and raise ValueError when no
    fix lies inside the span. Cases: 4 fixed synthetic drives (gaps, fixes outside the span,
    a spike) plus ``n`` seeded ones; ``real=(traj, gps)`` adds a real run, and
    ``real='victoria_park'`` that run's dead-reckoned track and GPS (:func:`_real_run`). Catches the
    mean, the MSE, a per-coordinate RMS, the median, the nearest or previous sample instead
    of interpolation, fixes outside the span (np.interp clamps), the GPS interpolated across
    its gaps."""
    name = "my_track_rmse"
    table = _rmse_cases(seed, n)
    if isinstance(real, str):
        real = _real_run(real)
    if real is not None:
        traj, gps = real
        if not isinstance(gps, Gps):
            raise TypeError(f"real must be (trajectory, records.Gps), got {type(gps).__name__}")
        traj = np.asarray(traj, dtype=float)
        table[f"#{len(table)}: the chapter's run, {traj.shape[0]} track samples against "
              f"{len(gps)} GPS fixes"] = (traj, gps.t, gps.xy)
    mistakes = [Mistake(msg, labelled(_rmse_wrong(k), table), ans)
                for k, msg, ans in _RMSE_MISTAKES]
    check_function(labelled(fn, table), labelled(_rmse_ref, table),
                   [(lab,) for lab in table], name=name, arg_names=["case"], atol=1e-9,
                   rtol=1e-9, mistakes=mistakes, quiet=True)
    traj, gt, gxy = next(iter(table.values()))
    late = gt + (traj[-1, 0] - gt[0]) + 1.0          # every fix after the track
    none = {"no GPS fix inside the track's time span (all of them after its last sample)":
            (traj, late, gxy)}
    for why in none:
        check_raises(labelled(_shown(fn), none), (why,), name=name, arg_names=["case"],
                     why="no fix lies inside the track's time span, so there is nothing to "
                         "compare (an RMSE of no errors is undefined; np.mean would return "
                         "nan with a warning)")
    ok = f"✓ {name} agrees with evaluation.trajectory.trajectory_errors on {len(table)} drives."
    print(ok)
    return Passed(ok)


def _shown(fn):
    """fn with its result rounded for a message (check_raises prints what came back)."""
    def shown(*args):
        out = fn(*args)
        try:
            return float(out)
        except (TypeError, ValueError):
            return f"a {type(out).__name__}"
    return shown


# ------------------------------------------------------------------------------ GPS outliers

def _outlier_cases(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    table = {}

    def drive(duration=30.0, gaps=()):
        _, gt, gxy = _drive(rng, duration, gaps=gaps, before=0.0, after=0.0)
        return gt, gxy

    t, xy = drive(40.0, gaps=[(20.0, 32.0)])
    xy = xy.copy()
    k = int(np.searchsorted(t, t[0] + 6.0))
    xy[k] += (90.0, 60.0)                               # a one-fix spike
    j = int(np.searchsorted(t, t[0] + 12.0))
    xy[j:] += (6.5, 0.0)                                # jumps 6.5 m and stays off
    table[f"#0: a one-fix spike (fix {k}), a 6.5 m jump that stays (fix {j}), a 12 s gap"] = \
        (t, xy)
    t, xy = drive(40.0, gaps=[(10.0, 30.0)])
    g = int(np.argmax(np.diff(t)))
    table[f"#1: a 20 s gap, after which the car is {np.hypot(*(xy[g + 1] - xy[g])):.0f} m "
          f"further on (a legitimate move)"] = (t, xy)
    t, xy = drive(20.0)
    xy = xy.copy()
    m = int(t.size // 2)
    xy[m] += (0.0, 2.6)
    table[f"#2: receiver jitter, fix {m} 2.6 m off its neighbours (within the tolerance)"] = \
        (t, xy)
    t, xy = drive(20.0)
    xy = xy.copy()
    xy[10:12] += (-80.0, 20.0)
    table["#3: a two-fix spike (fixes 10 and 11 together, 82 m away)"] = (t, xy)
    for _ in range(max(n, 0)):
        d = float(rng.uniform(20.0, 60.0))
        a = float(rng.uniform(2.0, d - 10.0))
        t, xy = drive(d, gaps=[(a, a + rng.uniform(1.0, 8.0))])
        xy = xy.copy()
        for s in rng.choice(np.arange(2, t.size), size=2, replace=False):
            xy[s] += rng.normal(0, 40.0, 2)
        table[f"#{len(table)}: {d:.0f} s, a gap, two random spikes"] = (t, xy)
    return table


def _outliers_ref(t, xy, max_speed=10.0, tolerance=3.0) -> np.ndarray:
    return gps_outliers(Gps(t=t, east=xy[:, 0], north=xy[:, 1]), max_speed, tolerance)


def _outliers_wrong(kind: str):
    def wrong(t, xy, max_speed=10.0, tolerance=3.0):
        step = np.hypot(*np.diff(xy, axis=0).T)
        dt = np.diff(t)
        flag = np.zeros(t.size, bool)
        if kind == "every-fast":
            flag[1:] = step > max_speed * dt + tolerance
        elif kind in ("fixed-dt", "no-tolerance"):
            fast = step > (max_speed * (0.2 if kind == "fixed-dt" else dt)
                           + (0.0 if kind == "no-tolerance" else tolerance))
            for i in range(1, t.size):
                flag[i] = fast[i - 1] and not flag[i - 1]
        elif kind == "one-early":
            fast = step > max_speed * dt + tolerance
            for i in range(t.size - 1):
                flag[i] = fast[i] and not (i > 0 and flag[i - 1])
        return flag
    return wrong


_OUTLIER_MISTAKES = [
    ("every-fast", "you flag every fast step, so the fix AFTER a one-fix spike is flagged too: "
                   "its step is the way back from the spike.",
     "Flag fix i only if its step is too fast AND fix i - 1 is not itself flagged (a loop "
     "over the fixes)."),
    ("fixed-dt", "the allowed step uses a fixed 0.2 s between fixes. After a GPS gap the car "
                 "may legitimately be 100 m further on.",
     "Allow max_speed * (t[i] - t[i-1]) + tolerance, with the actual time since the previous "
     "fix."),
    ("no-tolerance", "the tolerance is missing: a receiver jitters by a metre or two between "
                     "fixes 0.2 s apart, which at 10 m/s * 0.2 s = 2 m is already 'too fast'.",
     "Allow max_speed * dt + tolerance."),
    ("one-early", "every flag is one fix early: check to which fix each step belongs.",
     "np.diff(...)[i] is the step from fix i to fix i + 1, so it belongs to fix i + 1 (the "
     "fix that arrived too far away)."),
]


def _as_mask(name, out, size, where) -> np.ndarray:
    if out is None:
        raise GradingError(f"{name} returned None at case '{where}': did you forget `return`?")
    a = np.asarray(out)
    if a.shape != (size,):
        raise GradingError(f"{name} returned shape {a.shape} at case '{where}'; expected one "
                           f"flag per fix, shape ({size},)")
    if a.dtype != bool:
        if not (np.issubdtype(a.dtype, np.number) and np.all(np.isin(a, (0, 1)))):
            raise GradingError(f"{name} must return booleans (True = outlier), got {a.dtype} "
                               f"values {fmt(np.unique(a)[:5])} at case '{where}'")
        a = a.astype(bool)
    return a


def _fix_note(t, xy, i, max_speed, tolerance) -> str:
    if i == 0:
        return "fix 0 (the first fix has no previous one: never an outlier)"
    step = float(np.hypot(*(xy[i] - xy[i - 1])))
    dt = float(t[i] - t[i - 1])
    return (f"fix {i}: {step:.2f} m from fix {i - 1}, {dt:.2f} s earlier, allowed "
            f"{max_speed * dt + tolerance:.2f} m")


@forbids(gps_outliers)
def check_gps_outliers(fn: Callable, *, seed: int = 0, n: int = 3, gps: Gps | None = None,
                       max_speed: float = 10.0, tolerance: float = 3.0) -> str:
    """Exercise 6.2 (notebook 06 section 3, GPS outliers): ``fn(t, xy, max_speed,
    tolerance)`` must return the boolean mask of :func:`annslam_lib.evaluation.trajectory.
    gps_outliers`: fix i is an outlier if its step from fix i - 1 is longer than
    max_speed * (t[i] - t[i-1]) + tolerance, unless fix i - 1 is itself an outlier. Cases:
    4 synthetic GPS tracks (spikes, a jump that stays, a gap with a long legitimate move,
    jitter) plus ``n`` seeded ones; ``gps`` adds a real GPS record (a ``records.Gps``, or a
    run's name such as 'victoria_park'). Catches flagging the
    way back from a spike, a fixed dt, a missing tolerance, flags one fix early; otherwise
    names the first fix flagged or missed with its step and the allowed step."""
    name = "my_gps_outliers"
    table = _outlier_cases(seed, n)
    if isinstance(gps, str):
        gps = _real_run(gps)[1]
    if gps is not None:
        if not isinstance(gps, Gps):
            raise TypeError(f"gps must be a records.Gps, got {type(gps).__name__}")
        table[f"#{len(table)}: the real GPS record, {len(gps)} fixes"] = (gps.t, gps.xy)
    got, exp = {}, {}
    for label, (t, xy) in table.items():
        out = _call(fn, (t.copy(), xy.copy(), max_speed, tolerance), name, label)
        got[label] = _as_mask(name, out, t.size, label)
        exp[label] = _outliers_ref(t, xy, max_speed, tolerance)
    bad = [lab for lab in table if not np.array_equal(got[lab], exp[lab])]
    if bad:
        for kind, msg, ans in _OUTLIER_MISTAKES:
            w = _outliers_wrong(kind)
            wrong = {lab: w(*table[lab], max_speed, tolerance) for lab in table}
            if all(np.array_equal(got[lab], wrong[lab]) for lab in table):
                raise GradingError(Mistake(msg, w, ans).text)
        lab = bad[0]
        t, xy = table[lab]
        extra = np.flatnonzero(got[lab] & ~exp[lab])
        missed = np.flatnonzero(exp[lab] & ~got[lab])
        parts = [f"{name} disagrees with the reference on {len(bad)} of {len(table)} GPS "
                 f"records. First: case '{lab}' (max_speed {max_speed:g} m/s, tolerance "
                 f"{tolerance:g} m)"]
        if extra.size:
            parts.append(f"  flagged but not outliers: fixes {extra[:8].tolist()}; e.g. "
                         + _fix_note(t, xy, int(extra[0]), max_speed, tolerance)
                         + (" (the way back from the previous, flagged fix)"
                            if extra[0] > 0 and exp[lab][extra[0] - 1] else ""))
        if missed.size:
            parts.append(f"  outliers not flagged: fixes {missed[:8].tolist()}; e.g. "
                         + _fix_note(t, xy, int(missed[0]), max_speed, tolerance))
        raise GradingError("\n".join(parts))
    for label, (t, xy) in list(table.items())[:1]:        # the inputs must stay untouched
        t0, xy0 = t.copy(), xy.copy()
        _call(fn, (t, xy, max_speed, tolerance), name, label)
        if not (np.array_equal(t, t0) and np.array_equal(xy, xy0)):
            raise GradingError(f"{name} changed its input arrays t or xy in place: work on "
                               f"copies (the caller's GPS record must stay as it was).")
    ok = (f"✓ {name} agrees with evaluation.trajectory.gps_outliers on {len(table)} GPS records "
          f"({sum(int(e.sum()) for e in exp.values())} outliers).")
    print(ok)
    return Passed(ok)


def _call(fn, args, name, label):
    """call() with the case named by its label instead of its thousands of numbers."""
    def named(_label):
        return fn(*args)
    return call(named, (label,), name=name, arg_names=["case"])
