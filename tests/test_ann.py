"""Tests of annslam_lib.ann: the landmark network of section 4.2 and its two evaluation protocols."""
import dataclasses
import functools
import math
import pickle

import numpy as np
import pytest
import torch

from annslam_lib import ann
from annslam_lib.ann import network
from annslam_lib.models.observation import inverse_observe, observe
from annslam_lib.data import simulate
from annslam_lib.slam import config as slam_config
from annslam_lib.slam import results as slam_results
from annslam_lib.slam import runner


@functools.lru_cache(maxsize=None)
def _sim(bias: float):
    ds = simulate.simulate(range_bias=bias)
    res = runner.run(ds, slam_config.SlamConfig.for_dataset("simulated"))
    return ds, res, ann.training_set(res, ds)


@pytest.fixture(scope="module")
def sim():
    return _sim(0.0)


@pytest.fixture(scope="module")
def sim_bias():
    return _sim(0.3)


@pytest.fixture(scope="module")
def car_park_run(car_park):
    res = runner.run(car_park, slam_config.SlamConfig.for_dataset("car_park"))
    return car_park, res, ann.training_set(res, car_park)


@pytest.fixture(scope="module")
def quick_model(sim):
    _, _, ts = sim
    return ann.train(ts, ann.chronological_split(ts), ann.TrainConfig(seed=3))


# --------------------------------------------------------------------------- training set

def test_training_set_simulator(sim):
    ds, res, ts = sim
    log = res.observations
    used = np.isin(log.status, [slam_results.STATUS["associated"], slam_results.STATUS["new"]]) \
        & (log.landmark >= 0)
    n = int(used.sum())
    assert n > 1000 and len(ts) == n
    assert ts.X.shape == (n, len(ann.FEATURE_NAMES)) and ts.Y.shape == (n, 2)
    # Targets are the true beacons of the detections' true ids.
    np.testing.assert_array_equal(ts.beacon, log.true_id[used])
    np.testing.assert_array_equal(ts.target, ds.beacons[log.true_id[used]])
    # Inputs are built from the PRIOR pose; the base is observation.inverse_observe.
    z = np.column_stack([log.range[used], log.bearing[used]])
    np.testing.assert_array_equal(ts.pose, log.pose_prior[used])
    assert np.max(np.abs(ts.pose - log.pose[used])) > 1e-3       # the posterior differs
    np.testing.assert_array_equal(ts.base, inverse_observe(log.pose_prior[used], z)[0])
    np.testing.assert_array_equal(ts.Y, ts.target - ts.base)
    col = {c: i for i, c in enumerate(ann.FEATURE_NAMES)}
    np.testing.assert_array_equal(ts.X[:, [col["lm_x"], col["lm_y"]]], ts.base)
    np.testing.assert_allclose(ts.X[:, col["sin_phi"]] ** 2 + ts.X[:, col["cos_phi"]] ** 2, 1.0)
    # The ray direction points from the pose to the inverse-observed landmark.
    d = ts.base - ts.pose[:, :2]
    np.testing.assert_allclose(ts.X[:, [col["cos_ray"], col["sin_ray"]]] * ts.z[:, :1], d, atol=1e-9)
    # The simulator's detections have no width: encoded as 0, not NaN.
    assert np.all(ts.X[:, col["width"]] == 0.0)


def test_training_set_car_park(car_park_run):
    ds, res, ts = car_park_run
    assert len(ts) > 800
    assert np.unique(ts.beacon).size == ds.beacons.shape[0] == 15
    np.testing.assert_array_equal(ts.target, ds.beacons[ts.beacon])
    # Each sample's beacon is the surveyed beacon nearest to the filter's final landmark.
    log = res.observations
    used = np.isin(log.status, ann.USED_STATUS) & (log.landmark >= 0)
    lm = res.landmarks[log.landmark[used]]
    nearest = np.argmin(np.hypot(lm[:, None, 0] - ds.beacons[None, :, 0],
                                 lm[:, None, 1] - ds.beacons[None, :, 1]), axis=1)
    np.testing.assert_array_equal(ts.beacon, nearest)
    # Intensity levels 1..4 and cluster widths are real inputs here.
    col = {c: i for i, c in enumerate(ann.FEATURE_NAMES)}
    assert set(np.unique(ts.X[:, col["intensity"]])) <= {1.0, 2.0, 3.0, 4.0}
    assert np.all((ts.X[:, col["width"]] > 0.01) & (ts.X[:, col["width"]] < 0.5))
    # The inverse model is already good: its error is a few decimetres at most.
    err = np.hypot(*(ts.base - ts.target).T)
    assert 0.05 < np.sqrt(np.mean(err**2)) < 0.3


def test_training_set_bad_input(sim):
    ds, res, _ = sim
    with pytest.raises(ValueError, match="no surveyed beacons"):
        ann.training_set(res, dataclasses.replace(ds, beacons=None))
    with pytest.raises(ValueError, match="pose must be"):
        ann.encode(np.zeros((2, 3)), np.ones((3, 2)))
    with pytest.raises(ValueError, match="finite"):
        ann.encode(np.zeros(3), [[np.nan, 1.0]])
    with pytest.raises(ValueError, match="range must be > 0"):
        ann.encode(np.zeros(3), [[0.0, 1.0]])


# --------------------------------------------------------------------------- splits

def test_chronological_split_has_no_time_overlap(sim):
    _, _, ts = sim
    sp = ann.chronological_split(ts)
    assert ts.t[sp.train].max() < ts.t[sp.val].min()
    assert ts.t[sp.val].max() < ts.t[sp.test].min()
    assert np.array_equal(np.sort(np.concatenate([sp.train, sp.val, sp.test])), np.arange(len(ts)))
    scans = [np.unique(ts.t[sp.part(p)]).size for p in ann.SPLITS]
    frac = np.array(scans) / sum(scans)
    np.testing.assert_allclose(frac, [0.7, 0.15, 0.15], atol=0.01)
    with pytest.raises(ValueError, match="fractions"):
        ann.chronological_split(ts, (0.5, 0.5, 0.5))


def test_leave_beacons_out_folds_never_share_beacons(sim):
    _, _, ts = sim
    folds = ann.beacon_folds(ts, n_folds=5, seed=0)
    assert len(folds) == 5
    tested = np.concatenate([f.test for f in folds])
    assert np.array_equal(np.sort(tested), np.arange(len(ts)))        # each sample once
    for f in folds:
        b = {p: set(ts.beacon[f.part(p)].tolist()) for p in ann.SPLITS}
        assert len(b["test"]) == 3 and len(b["val"]) == 3 and len(b["train"]) == 9
        assert not (b["train"] & b["test"]) and not (b["val"] & b["test"])
        assert not (b["train"] & b["val"])
    with pytest.raises(ValueError, match="n_folds"):
        ann.beacon_folds(ts, n_folds=2)


# --------------------------------------------------------------------------- network

@pytest.mark.filterwarnings("ignore:`torch.jit.script` is deprecated:DeprecationWarning")
@pytest.mark.parametrize("hidden", [(10,), (5, 4)])
def test_backprop_jacobian_matches_autodiff(hidden):
    X = torch.from_numpy(np.random.default_rng(0).normal(size=(50, 7)))
    shapes = network._shapes(7, hidden)
    theta = network._init(shapes, 1)
    J_auto = torch.func.jacfwd(lambda th: network._forward(th, X, shapes).reshape(-1))(theta)
    J = network._jacobian(theta, X, shapes)
    assert J.shape == (100, theta.numel())
    torch.testing.assert_close(J, J_auto, rtol=0, atol=1e-13)


def test_training_is_deterministic(sim):
    ts = sim[2].subset(np.arange(800))
    sp = ann.chronological_split(ts)
    threads, det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    a = ann.train(ts, sp, ann.TrainConfig(seed=7))
    b = ann.train(ts, sp, ann.TrainConfig(seed=7))
    assert torch.equal(a.theta, b.theta)
    assert a.best_epoch == b.best_epoch and a.epochs == b.epochs
    for k in a.history:
        np.testing.assert_array_equal(a.history[k], b.history[k])
    np.testing.assert_array_equal(a.predict(ts.X), b.predict(ts.X))
    c = ann.train(ts, sp, ann.TrainConfig(seed=8))
    assert not torch.equal(a.theta, c.theta)
    adam = [ann.train(ts, sp, ann.TrainConfig(algorithm="adam", seed=7, max_epochs=30))
            for _ in range(2)]
    assert torch.equal(adam[0].theta, adam[1].theta)
    # The global torch settings are restored.
    assert torch.get_num_threads() == threads
    assert torch.are_deterministic_algorithms_enabled() == det


@pytest.mark.parametrize("max_fail", [6, 2])
def test_early_stopping_keeps_the_best_epoch(sim, max_fail):
    _, _, ts = sim
    sp = ann.chronological_split(ts)
    cfg = ann.TrainConfig(max_fail=max_fail, seed=0)
    m = ann.train(ts, sp, cfg)
    val = m.history["val"]
    assert m.stop_reason == "max_fail"
    assert m.epochs == m.best_epoch + max_fail == val.size - 1       # exactly max_fail failures
    assert np.all(val[m.best_epoch] < val[:m.best_epoch])              # a new best there
    assert np.all(val[m.best_epoch + 1:] >= val[m.best_epoch])         # no better one after
    # The returned weights are the best epoch's: the same training stopped there agrees.
    again = ann.train(ts, sp, dataclasses.replace(cfg, max_epochs=m.best_epoch))
    assert again.epochs == m.best_epoch and again.stop_reason == "max_epochs"
    np.testing.assert_array_equal(m.predict(ts.X), again.predict(ts.X))
    # ... and its recorded validation MSE is what the returned model gives.
    err = m.predict(ts.X[sp.val]) - ts.target[sp.val]
    assert math.isclose(np.mean(err**2), val[m.best_epoch], rel_tol=1e-9)


def test_train_config_validation():
    for bad in (dict(hidden=()), dict(hidden=(0,)), dict(features=("nope",)), dict(algorithm="sgd"),
                dict(lr=0.0), dict(max_fail=0), dict(max_epochs=-1), dict(mu_dec=2.0), dict(seed=1.5)):
        with pytest.raises(ValueError):
            ann.TrainConfig(**bad)


# --------------------------------------------------------------------------- save / load

def test_save_load_round_trip(quick_model, sim, tmp_path):
    _, _, ts = sim
    path = ann.save(quick_model, tmp_path / "model.pt")
    back = ann.load(path)
    np.testing.assert_array_equal(back.predict(ts.X), quick_model.predict(ts.X))
    assert back.config == quick_model.config and back.best_epoch == quick_model.best_epoch
    assert back.sigmas == quick_model.sigmas
    for k in quick_model.history:
        np.testing.assert_array_equal(back.history[k], quick_model.history[k])


def _resaved(quick_model, tmp_path, name, **change):
    path = ann.save(quick_model, tmp_path / f"{name}.pt")
    d = torch.load(path, weights_only=True)
    d.update(change)
    torch.save(d, path)
    return path


def test_load_names_damaged_and_implausible_model_files(quick_model, tmp_path):
    """Faults that torch.load accepts silently: each is refused, saying what is wrong."""
    good = ann.save(quick_model, tmp_path / "good.pt")
    raw = bytearray(good.read_bytes())
    at = bytes(raw).find(quick_model.theta.numpy().tobytes()[:16])
    assert at > 0                                     # the weights are stored uncompressed
    raw[at + 5] ^= 0x10                               # one bit of one weight
    flipped = tmp_path / "flipped.pt"
    flipped.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="fails its CRC check"):
        ann.load(flipped)
    n = quick_model.theta.numel()
    cases = {
        "NaN weights": (dict(theta=torch.full((n,), float("nan"), dtype=torch.float64)), "NaN or infinite"),
        "huge weights": (dict(theta=torch.full((n,), 1e308, dtype=torch.float64)), "not a trained network"),
        "sigma_range NaN": (dict(sigma_range=float("nan")), "sigma_range = nan"),
        "sigma_bearing -1": (dict(sigma_bearing=-1.0), "sigma_bearing = -1.0"),
    }
    for name, (change, message) in cases.items():
        with pytest.raises(ValueError, match=message):
            ann.load(_resaved(quick_model, tmp_path, name.replace(" ", "_"), **change))
    text = tmp_path / "notes.pt"
    text.write_text("these are my notes, not a model\n")
    with pytest.raises(ValueError, match="not a model file") as err:
        ann.load(text)
    assert not isinstance(err.value, ann.UnsafeModelFile)        # not "holds objects"
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match="damaged model file"):
        ann.load(truncated)
    assert ann.load(good).sigmas == quick_model.sigmas           # the intact file still loads


class _Payload:
    """Unpickling this writes a file: proof that code from the model file ran."""

    def __init__(self, flag):
        self.flag = str(flag)

    def __reduce__(self):
        return (exec, (f"open({self.flag!r}, 'w').write('ran')",))


@pytest.mark.filterwarnings("ignore:Detected pickle protocol:UserWarning")
def test_load_refuses_pickled_objects(quick_model, tmp_path):
    flag = tmp_path / "flag.txt"
    bad = tmp_path / "evil.pt"
    torch.save({"format": "annslam-ann-v1", "theta": _Payload(flag)}, bad)
    with pytest.raises(ann.UnsafeModelFile, match="refused"):
        ann.load(bad)
    assert not flag.exists()
    plain = tmp_path / "plain.pkl"
    with open(plain, "wb") as f:
        pickle.dump({"format": "annslam-ann-v1", "obj": _Payload(flag)}, f)
    with pytest.raises(ValueError):
        ann.load(plain)
    assert not flag.exists()
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"\x00not a model" * 10)
    with pytest.raises(ValueError):
        ann.load(junk)
    other = tmp_path / "other.pt"
    torch.save({"format": "something else"}, other)
    with pytest.raises(ValueError, match="not an annslam ANN model"):
        ann.load(other)


# --------------------------------------------------------------------------- evaluation

def test_range_bias_is_learned_on_unseen_beacons(sim_bias):
    """A 0.3 m range bias is a correction along the ray that does not depend on which
    beacon is seen: the network must learn it from 9 beacons and apply it to 3 others."""
    _, _, ts = sim_bias
    ev = ann.evaluate_leave_beacons_out(ts)
    assert ev.index.size == len(ts)
    print("\n" + ev.summary())
    assert ev.rmse_ann < 0.9 * ev.rmse_base
    assert all(f["rmse_ann"] < f["rmse_base"] for f in ev.folds)
    # The learned correction points back along the ray by what the data say: the filter
    # absorbs part of the 0.3 m into the poses, so the mean along-ray target is smaller.
    col = {c: i for i, c in enumerate(ann.FEATURE_NAMES)}
    i = ev.index
    ray = ts.X[i][:, [col["cos_ray"], col["sin_ray"]]]
    c = np.concatenate([m.correction(ts.X[s.test]) for m, s in zip(ev.models, ev.splits)])
    along, along_true = np.mean(np.sum(c * ray, 1)), np.mean(np.sum(ts.Y[i] * ray, 1))
    assert -0.3 < along_true < -0.1
    # at least 80 % of it (the networks stop early, at epochs 3-6, with nntool's patience)
    assert 0.8 < along / along_true < 1.2, (along, along_true)


def test_no_systematic_error_little_to_learn(sim):
    _, _, ts = sim
    ev = ann.evaluate_leave_beacons_out(ts)
    print("\n" + ev.summary())
    assert abs(ev.improvement) < 0.05


def test_memorisation_is_measurable(sim):
    """A network that sees only the inverse-model position snaps it to the nearest
    beacon it was trained on: excellent on the chronological test, useless on unseen beacons.
    It takes patience: the validation error sits on a plateau after epoch 1, where nntool's
    max_fail = 6 stops (best epoch 1 of 7, no gain); with 20 it trains for all 300 epochs."""
    _, _, ts = sim
    cfg = ann.TrainConfig(features=("lm_x", "lm_y"), hidden=(30,), max_epochs=300, max_fail=20)
    chrono = ann.evaluate_chronological(ts, cfg)
    unseen = ann.evaluate_leave_beacons_out(ts, cfg)
    print(f"\n{chrono.summary()}\n{unseen.summary()}")
    assert chrono.rmse_ann < 0.3 * chrono.rmse_base
    assert unseen.rmse_ann > 0.95 * unseen.rmse_base


def test_car_park_training_is_fast_and_reported(car_park_run):
    _, _, ts = car_park_run
    ev = ann.evaluate_chronological(ts)
    m = ev.models[0]
    assert m.seconds < 30.0
    parts = ev.folds[0]["parts"]
    assert parts["train"]["n"] + parts["val"]["n"] + parts["test"]["n"] == len(ts)
    # The residual noise of the pseudo-measurement is of the sensor's order.
    assert 0.01 < m.sigma_range < 0.2 and math.radians(0.2) < m.sigma_bearing < math.radians(3)
    print("\n" + ev.summary() + f"; best epoch {m.best_epoch} of {m.epochs}, {m.seconds:.2f} s")


def test_figure_data(quick_model, sim):
    _, _, ts = sim
    sp = ann.chronological_split(ts)
    h = ann.error_histogram(quick_model, ts, sp, bins=20)
    assert h["edges"].shape == (21,) and all(h["counts"][p].shape == (20,) for p in ann.SPLITS)
    for p in ann.SPLITS:
        assert h["counts"][p].sum() == 2 * sp.part(p).size     # both coordinates, none lost
        err = ts.target[sp.part(p)] - quick_model.predict(ts.X[sp.part(p)])
        np.testing.assert_allclose(np.sort(h["errors"][p]), np.sort(err.ravel()))
    reg = ann.regression(quick_model, ts, sp, kind="position")
    # Positions spanning tens of metres give R ~ 1 and slope ~ 1 for ANY sensible estimate.
    assert reg["all"]["r"] > 0.999 and abs(reg["all"]["slope"] - 1) < 0.01
    inv = ann.InverseModel(0.1, 0.01)
    reg_inv = ann.regression(inv, ts, sp, kind="position")
    assert reg_inv["all"]["r"] > 0.999                        # the baseline too
    corr = ann.regression(inv, ts, sp, kind="correction")
    assert corr["all"]["slope"] == 0.0                        # no correction at all
    with pytest.raises(ValueError, match="kind"):
        ann.regression(inv, ts, sp, kind="nope")
    perf = quick_model.history
    assert perf["train"].size == perf["val"].size == perf["test"].size == quick_model.epochs + 1
    assert perf["val"][quick_model.best_epoch] == perf["val"].min()


def test_pseudo_measurement_round_trip(quick_model, sim):
    _, _, ts = sim
    pose, z = ts.pose[0], ts.z[:5]
    zp = quick_model.pseudo_measurement(pose, z)
    X, _ = ann.encode(pose, z)
    np.testing.assert_allclose(inverse_observe(pose, zp)[0], quick_model.predict(X), atol=1e-12)
    np.testing.assert_allclose(observe(pose, quick_model.predict(X))[0], zp, atol=1e-12)
    inv = ann.InverseModel(0.1, 0.02)
    np.testing.assert_array_equal(inv.pseudo_measurement(pose, z), z)
    with pytest.raises(ValueError):
        ann.InverseModel(0.0, 0.02)


def test_numpy_inference_equals_torch_forward(quick_model, sim):
    """The run-time forward pass (numpy) against the training one (torch), on every sample
    and on one-row batches: equal to 1e-12 of the output's scale (float64 both)."""
    from annslam_lib.ann import network

    _, _, ts = sim
    xn = (ts.X[:, quick_model._cols] - quick_model.x_mean) / quick_model.x_std
    with torch.no_grad():
        ref = network._forward(quick_model.theta, torch.from_numpy(xn), quick_model._shapes).numpy()
    got = network._forward_numpy(quick_model.theta.numpy(), xn, quick_model._shapes)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    one = np.vstack([network._forward_numpy(quick_model.theta.numpy(), xn[i:i + 1], quick_model._shapes)
                     for i in range(20)])
    np.testing.assert_allclose(one, ref[:20], rtol=0, atol=1e-12 * np.abs(ref).max())
    with pytest.raises(ValueError, match="one laser pose"):
        quick_model.pseudo_measurement(ts.pose[:2], ts.z[:2])


# --------------------------------------------------------------------------- ANN-enhanced EKF-SLAM

def _zero_model(sigma_range, sigma_bearing):
    """A network whose correction is exactly zero: its landmark is the inverse observation."""
    n_par = sum(o * n + o for o, n in network._shapes(len(ann.FEATURE_NAMES), (10,)))
    return ann.TrainedModel(config=ann.TrainConfig(), theta=torch.zeros(n_par, dtype=torch.float64),
                            x_mean=np.zeros(12), x_std=np.ones(12), y_mean=np.zeros(2),
                            y_std=np.ones(2), sigma_range=sigma_range, sigma_bearing=sigma_bearing)


@pytest.mark.parametrize("which", ["sim", "car_park"])
def test_zero_correction_reproduces_the_plain_filter(which, request):
    """Zero correction with R' = R: z' = h(g(z)) equals z up to rounding (a few ulp of
    atan2 / hypot / sin / cos), the filter is stable, so the runs agree to ~1e-14 m; the
    tolerance 1e-9 m leaves a wide margin yet is far below any physical effect. Every
    association decision must be the same (flipping one would need a d2 within ~1e-12 of
    a gate)."""
    if which == "sim":
        ds, plain, _ = request.getfixturevalue("sim")
    else:
        ds, plain, _ = request.getfixturevalue("car_park_run")
    cfg = plain.config
    ann_cfg = cfg.replace(landmark_model="ann")
    r = runner.run(ds, ann_cfg, landmark_model=_zero_model(cfg.sigma_range, cfg.sigma_bearing))
    np.testing.assert_array_equal(r.observations.status, plain.observations.status)
    np.testing.assert_array_equal(r.observations.landmark, plain.observations.landmark)
    np.testing.assert_allclose(r.landmarks, plain.landmarks, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.trajectory, plain.trajectory, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.covariance, plain.covariance, rtol=0, atol=1e-12)
    # The identity model passes z itself: bitwise the plain run.
    same = runner.run(ds, ann_cfg, landmark_model=ann.InverseModel(cfg.sigma_range,
                                                                     cfg.sigma_bearing))
    np.testing.assert_array_equal(same.landmarks, plain.landmarks)
    np.testing.assert_array_equal(same.covariance, plain.covariance)


def test_ann_filter_corrects_a_range_bias_on_a_new_layout(sim_bias):
    """Train on one simulated run with a 0.3 m range bias (fold 0: 9 training beacons),
    then map ANOTHER run (other seed: other beacons, other noise) with the same bias."""
    _, _, ts = sim_bias
    model = ann.train(ts, ann.beacon_folds(ts)[0])
    ds = simulate.simulate(seed=1, range_bias=0.3)
    cfg = slam_config.SlamConfig.for_dataset("simulated")
    from annslam_lib.evaluation.map import map_errors
    plain = map_errors(runner.run(ds, cfg).landmarks, ds.beacons)
    with_ann = map_errors(runner.run(ds, cfg.replace(landmark_model="ann"),
                                       landmark_model=model).landmarks, ds.beacons)
    # Control: the plain filter with the model's (larger) noise: the noise is not the cure.
    control = map_errors(runner.run(ds, cfg.replace(sigma_range=model.sigma_range,
                                                      sigma_bearing=model.sigma_bearing)).landmarks,
                         ds.beacons)
    print(f"\nplain {plain.summary()}\nANN   {with_ann.summary()}\nctrl  {control.summary()}")
    assert with_ann.rmse < 0.6 * plain.rmse      # 0.41 here; 0.45..0.8 on other seeds
    assert control.rmse > 0.9 * plain.rmse
    assert with_ann.missed == 0 and with_ann.spurious <= plain.spurious


def test_landmark_model_switch_is_checked(sim):
    ds, plain, _ = sim
    cfg = plain.config
    inv = ann.InverseModel(0.1, 0.02)
    with pytest.raises(ValueError, match="landmark_model"):
        slam_config.SlamConfig(landmark_model="nn")
    with pytest.raises(ValueError, match="needs the trained model"):
        runner.run(ds, cfg.replace(landmark_model="ann"))
    with pytest.raises(ValueError, match="'inverse'"):
        runner.run(ds, cfg, landmark_model=inv)
    with pytest.raises(ValueError, match="pseudo_measurement"):
        runner.run(ds, cfg.replace(landmark_model="ann"), landmark_model=object())

    class Broken(ann.InverseModel):
        def pseudo_measurement(self, pose, z, intensity=None, width=None):
            return np.full((len(z), 2), np.nan)
    with pytest.raises(ValueError, match="invalid pseudo-measurements"):
        runner.run(ds, cfg.replace(landmark_model="ann"), landmark_model=Broken(0.1, 0.02))


def test_without_systematic_error_the_ann_filter_does_not_help(sim):
    """No bias to learn: the network's correction is a few centimetres of fitted noise,
    smooth in the geometry, so the filter cannot average it away (measured: the map RMSE
    grows from 0.065 m to about 0.12 m on this layout)."""
    _, _, ts = sim
    model = ann.train(ts, ann.beacon_folds(ts)[0])
    ds = simulate.simulate(seed=1)
    cfg = slam_config.SlamConfig.for_dataset("simulated")
    from annslam_lib.evaluation.map import map_errors
    plain = map_errors(runner.run(ds, cfg).landmarks, ds.beacons)
    with_ann = map_errors(runner.run(ds, cfg.replace(landmark_model="ann"),
                                       landmark_model=model).landmarks, ds.beacons)
    print(f"\nno bias: map RMSE plain {plain.rmse:.3f} m, ANN {with_ann.rmse:.3f} m")
    assert with_ann.rmse > 0.9 * plain.rmse


def test_zero_output_starts_from_the_inverse_model(sim):
    _, _, ts = sim
    sp = ann.chronological_split(ts)
    m = ann.train(ts, sp, ann.TrainConfig(zero_output=True, max_epochs=0))
    assert m.epochs == 0 and m.best_epoch == 0
    np.testing.assert_allclose(m.correction(ts.X), np.broadcast_to(ts.Y[sp.train].mean(0), ts.Y.shape),
                               rtol=0, atol=1e-15)


def test_first_deterministic_training_does_not_load_dynamo(sim):
    # torch.use_deterministic_algorithms imports torch._inductor (and _dynamo, 1.2 s on its
    # first call here); the course sets the eager flag alone. In a fresh interpreter: the
    # flag is on inside training, dynamo never loads, and the weights equal this process's.
    import subprocess
    import sys
    _, _, ts = sim
    code = (
        "import sys, numpy as np, torch\n"
        "from annslam_lib import ann\n"
        "from annslam_lib.ann import network\n"
        "from annslam_lib.data import simulate\n"
        "from annslam_lib.slam import config, runner\n"
        "seen = []\n"
        "orig = network._forward\n"
        "def spy(*a):\n"
        "    seen.append(torch.are_deterministic_algorithms_enabled())\n"
        "    return orig(*a)\n"
        "network._forward = spy\n"
        "ds = simulate.simulate(range_bias=0.0)\n"
        "res = runner.run(ds, config.SlamConfig.for_dataset('simulated'))\n"
        "ts = ann.training_set(res, ds)\n"
        "m = ann.train(ts, ann.chronological_split(ts), ann.TrainConfig(seed=3))\n"
        "np.save(sys.argv[1], m.theta)\n"
        "print(all(seen), len(seen) > 0, torch.are_deterministic_algorithms_enabled(),\n"
        "      'torch._dynamo' in sys.modules)\n")
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-c", code, f"{tmp}/theta.npy"],
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        assert out.stdout.split() == ["True", "True", "False", "False"]
        theta = np.load(f"{tmp}/theta.npy")
    mine = ann.train(ts, ann.chronological_split(ts), ann.TrainConfig(seed=3))
    np.testing.assert_array_equal(theta, mine.theta)
