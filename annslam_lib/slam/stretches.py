"""The odometry between two events, compounded once for a whole run (notebook 06 "Victoria
Park at scale"; the run loop, ``slam.runner``, and the factor graph, ``smoothing.problem``).

Between two events (a scan or a GPS fix) the filter only predicts: one Euler (or midpoint)
step per odometry sample and a partial step to the event's time. None of those steps
depends on the state except through the heading phi0 and the position p0 at the start of
the stretch, and they enter as a rigid motion. The body-frame velocity of the laser is
(v - w b, w a), so a step moves it by dt R(phi) (v - w b, w a), where phi = phi0 + theta_k
and theta_k depends on the controls only: the heading turned since the start (Euler), or
that plus half the step's own turn (midpoint). Hence, in the frame of the stretch's start
(phi0 = 0), computed once for every stretch of the run at once (arrays, no per-sample
Python):

    D = sum_k dt_k R(theta_k) (v_k - w_k b, w_k a)      the laser's displacement
    Theta = sum_k dt_k w_k                              the heading turned
    Q = sum_k G_k N_k G_k^T                             the process noise at the end

with N_k the step's noise (``EkfSlam.predict_many``: dt_k Delta_k B Q_c B^T, B rotated
like the velocity) and G_k = [[1, 0, s0], [0, 1, s1], [0, 0, 1]] the Jacobian of the steps
after k, whose shear is the perpendicular of the displacement still to come, (s0, s1) =
(-(D_y - D_{k,y}), D_x - D_{k,x}), D_k the displacement up to and including step k. The
filter then applies a stretch with a dozen scalar operations (``EkfSlam.predict_stretch``):
p += R(phi0) D, phi += Theta, and

    P_vv <- F P_vv F^T + R0 Q R0^T,    F = [[1, 0, -D'_y], [0, 1, D'_x], [0, 0, 1]],

D' = R(phi0) D and R0 = diag(R(phi0), 1); the cross covariance gets the same F. This is
the step-by-step prediction, rearranged; ``tests/test_stretches.py`` holds the two equal
(to 1e-12) over events that split the odometry intervals, with both motion models, first
estimates, zero steps, repeated sample times and samples before the first event.

The steps follow the run loop's rules: from the first odometry sample on, each sample's
control is held until the next sample or event time; a step of zero length is no step; an
event that no odometry sample precedes (before the first sample, or a GPS fix at its very
time: fixes count the samples strictly before them) is skipped, the filter having no
control yet, and gets an empty stretch. Stretch e ends at event e; stretch E (one past the
last event) holds the samples after the last event.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.geometry import wrap_angle
from ..models.vehicle import Vehicle

__all__ = ["Stretches", "compound"]


@dataclass(frozen=True)
class Stretches:
    """The run's predictions between events (module docstring). For stretch s (one per
    event, and one for the samples after the last event):

    rows[s]: (dx, dy, dtheta, q00, q01, q02, q11, q12, q22, steps): D and Theta in the
        frame of the stretch's start, the six entries of Q, the number of steps taken;
        what ``EkfSlam.predict_stretch`` takes.
    processed (E,) bool: whether event e is processed (an odometry sample precedes it).
    step_row, step_dt, step_start: every step taken, in order: the control row held
        (``models.motion.control_table``) and its length; stretch s holds steps
        step_start[s]:step_start[s + 1] (a step-by-step backend replays them).
    sample_t, sample_stretch, sample_rel (K,), (K,), (K, 3): every odometry sample's time,
        its stretch, and the pose reached at it relative to that stretch's start
        (displacement in the start frame, heading turned).
    """

    rows: list
    processed: np.ndarray
    step_row: np.ndarray
    step_dt: np.ndarray
    step_start: np.ndarray
    sample_t: np.ndarray
    sample_stretch: np.ndarray
    sample_rel: np.ndarray

    def steps_of(self, s: int) -> list[tuple[int, float]]:
        """The steps of stretch ``s`` as (control row, dt) pairs."""
        a, b = int(self.step_start[s]), int(self.step_start[s + 1])
        return list(zip(self.step_row[a:b].tolist(), self.step_dt[a:b].tolist()))

    def sample_poses(self, starts) -> np.ndarray:
        """The pose at every odometry sample, (K, 4) rows (t, x, y, phi), from ``starts``
        (S, 3): the pose at the start of each stretch, as the filter held it (after the
        previous event's update). phi is wrapped to (-pi, pi]."""
        starts = np.asarray(starts, dtype=float)
        p0 = starts[self.sample_stretch]
        c, s = np.cos(p0[:, 2]), np.sin(p0[:, 2])
        dx, dy, dth = self.sample_rel.T
        return np.column_stack([self.sample_t, p0[:, 0] + c * dx - s * dy,
                                p0[:, 1] + s * dx + c * dy, wrap_angle(p0[:, 2] + dth)])


def _segment_cumsum(x: np.ndarray, first: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Inclusive cumulative sums of ``x`` restarted at every segment (points sorted by
    segment; ``first[s]`` the index of segment s's first point)."""
    cs = np.cumsum(x)
    before = np.concatenate([[0.0], cs])[first]          # the sum of everything earlier
    return cs - before[seg]


def compound(odo_t, controls, ev_t, ev_k, vehicle: Vehicle, midpoint: bool) -> Stretches:
    """The stretches of a run (module docstring): odometry times ``odo_t`` (K,), nondecreasing;
    ``controls`` (K, 9), the rows of ``models.motion.control_table``; the events' times
    ``ev_t`` (E,) in processing order and ``ev_k`` (E,), nondecreasing, the number of
    samples before each (``runner.event_schedule``); ``midpoint`` for the midpoint model.
    Raises ValueError for inputs that do not fit together (lengths, order, non-finite
    values, an ``ev_k`` that does not count the samples before its event)."""
    odo_t = np.asarray(odo_t, dtype=float).ravel()
    ctrl = np.asarray(controls, dtype=float).reshape(-1, 9)
    ev_t = np.asarray(ev_t, dtype=float).ravel()
    ev_k = np.asarray(ev_k, dtype=np.int64).ravel()
    K, E = odo_t.size, ev_t.size
    if ctrl.shape[0] != K or ev_k.size != E:
        raise ValueError("compound: odo_t and controls, ev_t and ev_k must have equal lengths")
    if not (np.all(np.isfinite(odo_t)) and np.all(np.isfinite(ev_t))
            and np.all(np.isfinite(ctrl))):
        raise ValueError("compound: times and controls must be finite")
    if np.any(np.diff(odo_t) < 0) or np.any(np.diff(ev_t) < 0):
        raise ValueError("compound: odometry and event times must be nondecreasing")
    if E and (np.any(np.diff(ev_k) < 0) or ev_k[0] < 0 or ev_k[-1] > K):
        raise ValueError("compound: ev_k must be nondecreasing sample counts within 0..K")
    before, after = ev_k >= 1, ev_k < K                  # each event between its samples
    if np.any(odo_t[ev_k[before] - 1] > ev_t[before]) or np.any(odo_t[ev_k[after]] < ev_t[after]):
        raise ValueError("compound: ev_k must count the odometry samples before each event "
                         "(runner.event_schedule)")
    processed = before                                   # a sample precedes it: a control
    pe = np.flatnonzero(processed)
    # The points, in processing order: sample k (key 2k) and processed event e right after
    # its last preceding sample (key 2 ev_k[e] - 1); a stable sort keeps the events' order.
    key = np.concatenate([2 * np.arange(K), 2 * ev_k[pe] - 1])
    order = np.argsort(key, kind="stable")
    is_sample = order < K
    t = np.concatenate([odo_t, ev_t[pe]])[order]
    # the control held over the step ending at a point: the previous sample's
    held = np.concatenate([np.arange(K) - 1, ev_k[pe] - 1])[order]
    # stretch of a point: a sample's is the first event after it, an event's its own
    seg = np.concatenate([np.searchsorted(ev_k, np.arange(K), side="right"), pe])[order]
    dt = np.diff(t, prepend=t[:1])
    step = (dt > 0.0) & (held >= 0)
    dt = np.where(step, dt, 0.0)
    v, _, ta, w, dw, q00, q01, q11, span = ctrl[np.maximum(held, 0)].T
    S = E + 1
    first = np.searchsorted(seg, np.arange(S))
    dth = dt * w
    theta_after = _segment_cumsum(dth, first, seg)
    theta = theta_after - dth                              # the heading at the step's start
    if midpoint:
        theta = theta + 0.5 * dth
    c, s = np.cos(theta), np.sin(theta)
    a, b, L = vehicle.a, vehicle.b, vehicle.L
    lx, ly = a * s + b * c, a * c - b * s
    ddx = dt * (v * c - w * lx)
    ddy = dt * (v * s + w * ly)
    Dx, Dy = _segment_cumsum(ddx, first, seg), _segment_cumsum(ddy, first, seg)
    # the step's noise k B Q_c B^T (as EkfSlam.predict_many), then carried to the stretch end
    tl = ta / L
    b00, b01, b10, b11 = c - tl * lx, -dw * lx, s + tl * ly, dw * ly
    k = dt * span
    g00, g01 = b00 * q00 + b01 * q01, b00 * q01 + b01 * q11
    g10, g11 = b10 * q00 + b11 * q01, b10 * q01 + b11 * q11
    g20, g21 = tl * q00 + dw * q01, tl * q01 + dw * q11
    n00, n01 = k * (g00 * b00 + g01 * b01), k * (g00 * b10 + g01 * b11)
    n02, n11 = k * (g00 * tl + g01 * dw), k * (g10 * b10 + g11 * b11)
    n12, n22 = k * (g10 * tl + g11 * dw), k * (g20 * tl + g21 * dw)
    end_x = np.bincount(seg, ddx, minlength=S)
    end_y = np.bincount(seg, ddy, minlength=S)
    s0, s1 = -(end_y[seg] - Dy), end_x[seg] - Dx
    q = [n00 + 2.0 * s0 * n02 + s0 * s0 * n22,
         n01 + s0 * n12 + s1 * n02 + s0 * s1 * n22,
         n02 + s0 * n22,
         n11 + 2.0 * s1 * n12 + s1 * s1 * n22,
         n12 + s1 * n22,
         n22]
    cols = [end_x, end_y, np.bincount(seg, dth, minlength=S)]
    cols += [np.bincount(seg, x, minlength=S) for x in q]
    cols.append(np.bincount(seg, step, minlength=S))
    rows = [(*r[:9], int(r[9])) for r in np.column_stack(cols).tolist()]
    taken = np.flatnonzero(step)
    return Stretches(
        rows=rows, processed=processed, step_row=held[taken], step_dt=dt[taken],
        step_start=np.searchsorted(seg[taken], np.arange(S + 1)),
        sample_t=odo_t, sample_stretch=seg[is_sample],
        sample_rel=np.column_stack([Dx, Dy, theta_after])[is_sample])
