"""The odometry between events compounded once for a run (slam.stretches) against the
step-by-step prediction the run loop did before it: EkfSlam.predict_many over the samples
before each event and a partial step to the event's time."""
from __future__ import annotations

import math

import numpy as np
import pytest

from annslam_lib.data.records import Odometry
from annslam_lib.models.motion import control_table
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.slam import stretches
from annslam_lib.slam.dense import DenseEkfSlam
from annslam_lib.slam.efficient import EkfSlam
from annslam_lib.slam.runner import event_schedule


def _schedule(seed: int):
    """Irregular odometry (with turns past +-pi), and GPS fixes and scans that fall before
    the first sample, on sample times, several inside one interval, and after the last."""
    rng = np.random.default_rng(seed)
    K = 120
    t = 10.0 + np.cumsum(rng.uniform(0.01, 0.06, K))
    odo = Odometry(t=t, speed=rng.uniform(2.0, 6.0, K), steering=rng.uniform(-0.2, 0.55, K))
    scans = np.sort(np.concatenate([rng.uniform(t[0] - 0.2, t[-1] + 0.2, 40), t[[0, 7, 30]],
                                    [t[0] - 0.5]]))
    gps = np.sort(np.concatenate([rng.uniform(t[0], t[-1], 12), t[[7, 50]], [t[0] - 0.1]]))
    return odo, gps, scans


def _filter(cls, fej=False, motion_model="euler"):
    rng = np.random.default_rng(3)
    kw = {"fej": True} if fej else {}
    f = cls(np.array([1.0, -2.0, 3.0]), np.diag([0.04, 0.02, 0.01]), ACFR_UTE, motion_model, **kw)
    f.augment(np.column_stack([rng.uniform(3, 30, 6), rng.uniform(-1.5, 1.5, 6)]), 0.1, 0.02)
    return f


def _event_action(f, code, k):
    """What happens at a processed event: a GPS update (it moves the pose, and with FEJ
    leaves a position correction for the next prediction), or nothing."""
    if code == 0 and k % 2 == 0:
        x, y, _ = f.pose_tuple()
        f.gps_update([x + 0.3, y - 0.2], 0.5)


def _both_loops(odo, gps_t, scan_t, motion_model, fej, check_each=True):
    """The run loop as it was (predict_many over the samples before each event, then a
    partial step to its time) and the stretches, side by side on two filters, with the
    same event action; returns what each did."""
    rows = control_table(odo, ACFR_UTE, 0.7, math.radians(7), 0.1)
    ev_t, ev_code, _, ev_k = event_schedule(odo.t, gps_t, scan_t)
    legs = stretches.compound(odo.t, np.array(rows), ev_t, ev_k, ACFR_UTE,
                              motion_model == "midpoint")
    ref, new = _filter(EkfSlam, fej, motion_model), _filter(EkfSlam, fej, motion_model)
    odo_t = odo.t.tolist()
    t0, cur_t, u, k_done, steps, recorded = odo_t[0], odo_t[0], None, 0, 0, []
    starts = np.full((len(ev_t) + 1, 3), np.nan)
    skipped = []
    for e, (t, code, k_end) in enumerate(zip(ev_t, ev_code, ev_k)):
        if k_end > k_done:
            u, cur_t, n, poses = ref.predict_many(u, cur_t, odo_t[k_done:k_end], rows[k_done:k_end])
            steps += n
            recorded += poses
            k_done = k_end
        if t < t0 or u is None:
            skipped.append(e)
            continue
        if t > cur_t:
            ref.predict(u, t - cur_t)
            steps += 1
            cur_t = t
        starts[e] = new.pose_tuple()
        steps -= new.predict_stretch(legs.rows[e])
        for f in (ref, new):
            _event_action(f, code, e)
        if check_each:
            np.testing.assert_allclose(new.pose, ref.pose, rtol=0, atol=1e-12)
            np.testing.assert_allclose(new.state()[1], ref.state()[1], rtol=0, atol=1e-12)
    u, cur_t, n, poses = ref.predict_many(u, cur_t, odo_t[k_done:], rows[k_done:])
    steps += n
    recorded += poses
    starts[-1] = new.pose_tuple()
    steps -= new.predict_stretch(legs.rows[-1])
    return dict(ref=ref, new=new, steps=steps, skipped=skipped, legs=legs,
                recorded=np.array(recorded).reshape(-1, 4), rebuilt=legs.sample_poses(starts))


def _assert_same(out, n_samples):
    ref, new, legs = out["ref"], out["new"], out["legs"]
    assert out["steps"] == 0                            # the same number of steps taken
    assert out["skipped"] == np.flatnonzero(~legs.processed).tolist()
    d = new.state()[0] - ref.state()[0]
    d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    np.testing.assert_allclose(new.state()[1], ref.state()[1], rtol=0, atol=1e-12)
    rebuilt, rec = out["rebuilt"], out["recorded"]
    assert rebuilt.shape == rec.shape == (n_samples, 4)
    np.testing.assert_array_equal(rebuilt[:, 0], rec[:, 0])
    np.testing.assert_allclose(rebuilt[:, 1:3], rec[:, 1:3], rtol=0, atol=1e-12)
    dphi = (rebuilt[:, 3] - rec[:, 3] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(dphi, 0.0, atol=1e-12)
    assert np.all((rebuilt[:, 3] > -np.pi) & (rebuilt[:, 3] <= np.pi))


@pytest.mark.parametrize("fej", [False, True])
@pytest.mark.parametrize("motion_model", ["euler", "midpoint"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compounded_stretches_equal_the_step_by_step_loop(seed, motion_model, fej):
    odo, gps_t, scan_t = _schedule(seed)
    out = _both_loops(odo, gps_t, scan_t, motion_model, fej)
    _assert_same(out, len(odo.t))
    assert len(out["skipped"]) >= 2
    # the heading (from 3.0 rad) turned over a radian and crossed +-pi
    rec = out["recorded"]
    assert np.ptp(np.unwrap(rec[:, 3])) > 1.0 and np.ptp(rec[:, 3]) > np.pi


def _edge_schedule(rng, case: str):
    """Short runs with the run loop's corner cases: one sample, repeated sample times, no
    event, events only after the last sample or only before the first, a fix and a scan
    at a sample time and at one time together."""
    K = 1 if case == "one sample" else int(rng.integers(2, 12))
    gaps = rng.uniform(0.01, 0.1, K)
    if case == "repeated times":
        gaps[1:][rng.random(K - 1) < 0.4] = 0.0
    t = 5.0 + np.cumsum(gaps)
    odo = Odometry(t=t, speed=rng.uniform(-1.0, 6.0, K), steering=rng.uniform(-0.5, 0.5, K))
    if case == "no events":
        return odo, np.empty(0), np.empty(0)
    if case == "only after":
        return odo, np.empty(0), t[-1] + np.sort(rng.uniform(0.0, 1.0, 3))
    if case == "only before":
        return odo, t[0] - np.sort(rng.uniform(0.0, 1.0, 2)), np.empty(0)
    at = rng.choice(t, 2)
    gps = np.sort(np.concatenate([rng.uniform(t[0] - 0.2, t[-1] + 0.2, 3), at, [t[0]]]))
    scans = np.sort(np.concatenate([rng.uniform(t[0] - 0.2, t[-1] + 0.2, 5), at, [t[0], t[-1]]]))
    return odo, gps, scans


@pytest.mark.parametrize("case", ["one sample", "repeated times", "no events", "only after",
                                  "only before", "mixed"])
def test_the_run_loops_corner_cases(case):
    for seed in range(12):
        rng = np.random.default_rng(seed)
        odo, gps_t, scan_t = _edge_schedule(rng, case)
        for motion_model in ("euler", "midpoint"):
            for fej in (False, True):
                _assert_same(_both_loops(odo, gps_t, scan_t, motion_model, fej, False), len(odo.t))


def test_replayed_steps_are_the_loops_steps():
    """A step-by-step backend replays steps_of(s): the dense reference ends where its own
    predict_many loop ends."""
    odo, gps_t, scan_t = _schedule(4)
    controls = control_table(odo, ACFR_UTE, 0.7, math.radians(7))
    ev_t, _, _, ev_k = event_schedule(odo.t, gps_t, scan_t)
    legs = stretches.compound(odo.t, np.array(controls), ev_t, ev_k, ACFR_UTE, False)
    a, b = _filter(DenseEkfSlam), _filter(DenseEkfSlam)
    for s in range(len(ev_t) + 1):
        for h, dt in legs.steps_of(s):
            a.predict(controls[h], dt)
    odo_t = odo.t.tolist()
    u, cur_t, k_done = None, odo_t[0], 0
    for t, k_end in zip(ev_t, ev_k):
        if k_end > k_done:
            u, cur_t, _, _ = b.predict_many(u, cur_t, odo_t[k_done:k_end], controls[k_done:k_end])
            k_done = k_end
        if u is not None and t > cur_t:
            b.predict(u, t - cur_t)
            cur_t = t
    b.predict_many(u, cur_t, odo_t[k_done:], controls[k_done:])
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    assert legs.step_start[-1] == legs.step_row.size == sum(r[-1] for r in legs.rows)


def test_a_stretch_without_steps_changes_nothing():
    f = _filter(EkfSlam)
    x, P = (a.copy() for a in f.state())
    assert f.predict_stretch((1.0, 2.0, 0.5, 1, 0, 0, 1, 0, 1, 0)) == 0
    np.testing.assert_array_equal(f.state()[0], x)
    np.testing.assert_array_equal(f.state()[1], P)


def test_malformed_schedules_are_refused():
    odo, gps_t, scan_t = _schedule(0)
    controls = np.array(control_table(odo, ACFR_UTE, 0.7, 0.1))
    ev_t, _, _, ev_k = event_schedule(odo.t, gps_t, scan_t)
    ev_t, ev_k, t = np.asarray(ev_t), np.asarray(ev_k), odo.t
    cases = [
        ((t, controls[:-1], ev_t, ev_k), "equal lengths"),
        ((t, controls, ev_t, ev_k[:-1]), "equal lengths"),
        ((t, controls, ev_t, ev_k[::-1]), "nondecreasing sample counts"),
        ((t, controls, ev_t, ev_k + len(t)), "nondecreasing sample counts"),
        ((t[::-1], controls, ev_t, ev_k), "times must be nondecreasing"),
        ((t, controls, ev_t[::-1], ev_k), "times must be nondecreasing"),
        ((np.where(np.arange(t.size) == 5, np.nan, t), controls, ev_t, ev_k), "finite"),
        ((t, np.where(controls == controls[3, 0], np.inf, controls), ev_t, ev_k), "finite"),
        ((t, controls, ev_t - 1.0, ev_k), "count the odometry samples"),   # events moved earlier
        ((t, controls, ev_t + 1.0, ev_k), "count the odometry samples"),   # and later
    ]
    for args, match in cases:
        with pytest.raises(ValueError, match=match):
            stretches.compound(*args, ACFR_UTE, False)
