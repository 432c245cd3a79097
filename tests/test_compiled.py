"""The compiled gating (annslam_lib.slam.compiled) against the numpy gating it copies
(EkfSlam.innovation_d2 and the Jacobians update reads), on random states, with and without
first-estimates Jacobians, on bad states, and on whole runs; when it is used and how to
switch it off."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from annslam_lib.data import simulate
from annslam_lib.data.records import Odometry
from annslam_lib.models import motion
from annslam_lib.models.observation import observe
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.slam import compiled, runner
from annslam_lib.slam.config import SlamConfig
from annslam_lib.slam.efficient import EkfSlam

SR, SB = 0.12, math.radians(1.5)


def _pair(seed: int, n_landmarks: int, fej: bool):
    """The same random, fully correlated state in a numpy-gating and a compiled-gating
    filter: landmarks all around, a prediction (the pose block held in floats, the cross
    covariance awaiting its flush), an update that moves the landmarks away from their
    first estimates."""
    rng = np.random.default_rng(seed)
    x0 = rng.uniform([-50, -50, -math.pi], [50, 50, math.pi])
    A = rng.normal(size=(3, 3))
    P0 = 0.01 * (A @ A.T) + np.diag([0.01, 0.01, 1e-3])
    z = np.column_stack([rng.uniform(2, 60, n_landmarks), rng.uniform(-math.pi, math.pi, n_landmarks)])
    odo = Odometry(t=np.array([0.0, 0.3]), speed=np.full(2, rng.uniform(0.5, 4)),
                   steering=np.full(2, rng.uniform(-0.4, 0.4)))
    u = motion.control_table(odo, ACFR_UTE, 0.7, math.radians(7))[0]
    noise = rng.normal(0, [0.3, 0.02], (4, 2))
    out = []
    for gating in ("numpy", "compiled"):
        f = EkfSlam(x0, P0, ACFR_UTE, fej=fej, gating=gating)
        f.augment(z, SR, SB)
        zt = observe(f.state()[0][:3], f.landmarks()[:4])[0] + noise
        f.update(zt, [0, 1, 2, 3], SR, SB)
        f.predict(u, 0.3)
        out.append(f)
    return out


def _detections(f, seed, n=12):
    """Detections near some landmarks and anywhere else, bearings across +-pi."""
    rng = np.random.default_rng(seed + 100)
    zhat = observe(f.state()[0][:3], f.landmarks())[0]
    near = zhat[rng.integers(0, len(zhat), n // 2)] + rng.normal(0, [0.2, 0.02], (n // 2, 2))
    far = np.column_stack([rng.uniform(1, 70, n - n // 2), rng.uniform(-math.pi, math.pi, n - n // 2)])
    z = np.vstack([near, far])
    z[:, 1] = (z[:, 1] + math.pi) % (2 * math.pi) - math.pi
    z[:, 0] = np.abs(z[:, 0]) + 0.1
    return z


@pytest.mark.parametrize("fej", [False, True], ids=["standard", "fej"])
@pytest.mark.parametrize("seed", range(6))
def test_compiled_gating_equals_the_numpy_gating(seed, fej):
    a, b = _pair(seed, 5 + 40 * seed, fej)
    z = _detections(a, seed)
    # the loop itself finds the state good (else innovation_d2 would hand it to numpy)
    b.flush()
    N = b.n_landmarks
    J, d2 = np.empty((5, N)), np.empty((len(z), N))
    assert compiled.gating_kernel()(b.x[3:].reshape(N, 2), b.P, b._px, b._py, b._pphi, *b._p,
                                    b._first, fej, z, SR**2, SB**2, J, d2) == compiled.OK
    d_np = a.innovation_d2(z, SR, SB)
    d_c = b.innovation_d2(z, SR, SB)
    assert d_c.shape == d_np.shape == (len(z), a.n_landmarks)
    np.testing.assert_allclose(d_c, d_np, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(b._om[4], a._om[4], rtol=1e-12, atol=1e-14)   # what update reads
    assert a._om[:4] == b._om[:4]
    # the update that follows reads those Jacobians: the same state after it
    lm = np.argmin(d_np, axis=1)[:4]
    a.update(z[:4], lm, SR, SB)
    b.update(z[:4], lm, SR, SB)
    (xa, Pa), (xb, Pb) = a.state(), b.state()
    np.testing.assert_allclose(xb, xa, rtol=0, atol=1e-10)
    np.testing.assert_allclose(Pb, Pa, rtol=0, atol=1e-12 * np.abs(Pa).max())


def test_the_loop_uncompiled_is_the_same_code():
    """gate_loop run as plain Python (what numba compiles) gives what the compiled one gives."""
    a, b = _pair(7, 30, True)
    z = _detections(a, 7)
    args = (a.x[3:].reshape(-1, 2), a.P, a._px, a._py, a._pphi, *a._p, a._first, True, z,
            SR**2, SB**2)
    J1, d1 = np.empty((5, a.n_landmarks)), np.empty((len(z), a.n_landmarks))
    J2, d2 = J1.copy(), d1.copy()
    assert compiled.gate_loop(*args, J1, d1) == compiled.OK
    assert compiled.gating_kernel()(*args, J2, d2) == compiled.OK
    np.testing.assert_allclose(d2, d1, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(J2, J1, rtol=1e-13, atol=1e-15)


def test_bearings_wrap_the_same_way_at_plus_minus_pi():
    """Landmarks straight behind the vehicle (bearing -pi) and detections on either side of
    the cut: the wrap of the loop is geometry.wrap_difference's."""
    f_np, f_c = (EkfSlam([0.0, 0.0, math.pi / 2], np.diag([0.01, 0.01, 1e-3]), ACFR_UTE, gating=g)
                 for g in ("numpy", "compiled"))
    z_new = np.array([[10.0, -math.pi], [12.0, math.pi - 1e-9], [8.0, -math.pi + 1e-9]])
    z = np.array([[10.0, math.pi - 1e-6], [10.0, -math.pi + 1e-6], [12.0, -math.pi], [8.0, 3.0]])
    for f in (f_np, f_c):
        f.augment(z_new, SR, SB)
    d_np, d_c = f_np.innovation_d2(z, SR, SB), f_c.innovation_d2(z, SR, SB)
    np.testing.assert_allclose(d_c, d_np, rtol=1e-9, atol=1e-9)
    assert d_np.max() < 1e4                                 # no 2 pi jump in either
    np.testing.assert_allclose(f_c._om[4][1], f_np._om[4][1], atol=1e-12)


BAD_STATES = {
    "NaN landmark": (lambda f: f.x.__setitem__(3, np.nan), "NaN"),
    "landmark on the sensor": (lambda f: f.x.__setitem__(slice(3, 5), f.x[:2]), "coincides"),
    "S not positive definite": (lambda f: f.P.__setitem__((3, 3), -50.0), "not positive definite"),
    "S negative definite": (lambda f: (f.P.__setitem__((3, 3), -50.0), f.P.__setitem__((4, 4), -50.0)),
                            "not positive definite"),
    "NaN covariance": (lambda f: f.P.__setitem__((4, 4), np.nan), "NaN"),
}


@pytest.mark.parametrize("what", list(BAD_STATES))
def test_a_bad_state_raises_the_numpy_gatings_error(what):
    spoil, match = BAD_STATES[what]
    errors = []
    for gating in ("numpy", "compiled"):
        f = EkfSlam([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 1e-3]), ACFR_UTE, gating=gating)
        f.augment([[5.0, 1.0], [7.0, 2.0]], SR, SB)
        f.flush()
        spoil(f)
        with pytest.raises(ValueError, match=match) as e:
            f.innovation_d2([[5.0, 1.0]], SR, SB)
        errors.append(str(e.value))
    assert errors[0] == errors[1]


def test_a_first_estimate_on_the_sensor_raises_the_same_error():
    errors = []
    for gating in ("numpy", "compiled"):
        f = EkfSlam([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 1e-3]), ACFR_UTE, fej=True, gating=gating)
        f.augment([[5.0, 1.0]], SR, SB)
        f._first[0] = f.x[:2]
        with pytest.raises(ValueError, match="first estimate coincides") as e:
            f.innovation_d2([[5.0, 1.0]], SR, SB)
        errors.append(str(e.value))
    assert errors[0] == errors[1]


def test_a_disagreement_between_the_two_codes_is_an_error_not_a_silent_fallback(monkeypatch):
    f = EkfSlam([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 1e-3]), ACFR_UTE, gating="compiled")
    f.augment([[5.0, 1.0]], SR, SB)
    monkeypatch.setattr(f, "_gate", lambda *a: compiled.BAD_S)      # a broken loop
    with pytest.raises(RuntimeError, match="compiled gating reported problem 3"):
        f.innovation_d2([[5.0, 1.0]], SR, SB)
    f._first = f._first[:0]                                          # arrays out of step
    with pytest.raises(RuntimeError, match="do not fit together"):
        f.innovation_d2([[5.0, 1.0]], SR, SB)


def test_switching_it_off_and_bad_choices(monkeypatch):
    with pytest.raises(ValueError, match="gating must be 'numpy' or 'compiled'"):
        EkfSlam([0.0, 0.0, 0.0], np.eye(3), ACFR_UTE, gating="fast")
    with pytest.raises(ValueError, match="gating must be 'auto', 'numpy' or 'compiled'"):
        runner.run("car_park", gating="numba")
    with pytest.raises(ValueError, match="efficient backend only"):
        runner.run(simulate.simulate(seed=3, raw_laser=False, laps=1), backend="dense",
                   gating="compiled")
    monkeypatch.setenv("ANNSLAM_KERNEL", "numpy")
    assert compiled.gating_kernel() is None and not compiled.use_compiled(10**6)
    with pytest.raises(RuntimeError, match="ANNSLAM_KERNEL=numpy"):
        EkfSlam([0.0, 0.0, 0.0], np.eye(3), ACFR_UTE, gating="compiled")
    monkeypatch.setenv("ANNSLAM_KERNEL", "off")                      # a typo is not 'on'
    with pytest.raises(ValueError, match="ANNSLAM_KERNEL must be 'numpy'"):
        compiled.use_compiled(10**6)
    monkeypatch.setenv("ANNSLAM_KERNEL", "auto")
    assert compiled.gating_kernel() is not None


def test_a_numba_that_cannot_load_leaves_the_numpy_gating(monkeypatch):
    """numba missing, or its LLVM library failing to load (an OSError, not an ImportError):
    long runs gate with numpy, and asking for the compiled loop names the reason."""
    import builtins
    real_import = builtins.__import__

    def broken(name, *args, **kwargs):
        if name == "numba" or name.startswith("numba."):
            raise OSError("libllvmlite.so: cannot open shared object file")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(compiled, "_kernel", None)
    monkeypatch.setattr(compiled, "_failed", None)
    monkeypatch.setattr(builtins, "__import__", broken)
    assert compiled.gating_kernel() is None and not compiled.use_compiled(10**6)
    with pytest.raises(RuntimeError, match="numba cannot be imported.*libllvmlite"):
        EkfSlam([0.0, 0.0, 0.0], np.eye(3), ACFR_UTE, gating="compiled")


def test_without_a_writable_cache_it_compiles_in_memory(monkeypatch):
    built = []

    def fake(numba, cache):
        built.append(cache)
        if cache:
            raise RuntimeError("cannot cache function 'gate_loop': no locator available")
        return "in memory"

    monkeypatch.setattr(compiled, "_kernel", None)
    monkeypatch.setattr(compiled, "_failed", None)
    monkeypatch.setattr(compiled, "_compiled", fake)
    with pytest.warns(RuntimeWarning, match="not cached on disk.*no locator"):
        assert compiled.gating_kernel() == "in memory"
    assert built == [True, False]


def test_a_fresh_process_compiles_caches_and_loads_it(tmp_path):
    """numba's cache in a folder of its own (NUMBA_CACHE_DIR): the first process compiles and
    writes it, the second loads it; both give the numpy gating's numbers."""
    code = ("import numpy as np, math\n"
            "from annslam_lib.slam.efficient import EkfSlam\n"
            "from annslam_lib.models.vehicle import ACFR_UTE\n"
            "fs = [EkfSlam([1.0, 2.0, 0.3], np.diag([0.02, 0.03, 1e-3]), ACFR_UTE, gating=g)\n"
            "      for g in ('numpy', 'compiled')]\n"
            "z = np.array([[5.0, 1.0], [9.0, 2.5], [20.0, -1.0]])\n"
            "for f in fs: f.augment(z, 0.1, 0.02)\n"
            "d = [f.innovation_d2(z + 0.01, 0.1, 0.02) for f in fs]\n"
            "print(float(np.max(np.abs(d[0] - d[1]) / np.abs(d[0]))))\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    env.pop("ANNSLAM_KERNEL", None)
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        assert float(out.stdout) <= 1e-12
        assert list(tmp_path.rglob("*gate_loop*.nbi")) and list(tmp_path.rglob("*gate_loop*.nbc"))


def test_runs_choose_by_length_and_decide_the_same(car_park):
    """'auto' gates the Car Park (586 scans) with numpy; forced to the compiled loop, the run
    makes every decision the same and ends within rounding."""
    auto = runner.run(car_park, progress=False)
    forced = runner.run(car_park, progress=False, gating="compiled")
    assert auto.gating == "numpy" and forced.gating == "compiled"
    assert auto.counts["scans"] < compiled.MIN_SCANS
    assert forced.counts == auto.counts
    np.testing.assert_allclose(forced.trajectory, auto.trajectory, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(forced.observations.landmark, auto.observations.landmark)


@pytest.mark.parametrize("fej", [False, True], ids=["standard", "fej"])
def test_victoria_park_gated_either_way_decides_the_same(victoria_park, fej):
    cfg = SlamConfig.for_dataset("victoria_park").replace(first_estimates=fej)
    auto = runner.run(victoria_park, cfg, progress=False)
    plain = runner.run(victoria_park, cfg, progress=False, gating="numpy")
    assert auto.counts["scans"] >= compiled.MIN_SCANS and auto.gating == "compiled"
    assert plain.gating == "numpy"
    assert auto.counts == plain.counts                     # every association decision
    np.testing.assert_array_equal(auto.observations.status, plain.observations.status)
    np.testing.assert_array_equal(auto.observations.landmark, plain.observations.landmark)
    np.testing.assert_allclose(auto.trajectory, plain.trajectory, rtol=0, atol=1e-8)
    np.testing.assert_allclose(auto.landmarks, plain.landmarks, rtol=0, atol=1e-8)


def test_a_study_gates_all_its_runs_by_their_scans_together_and_judges_the_same(monkeypatch):
    """A Monte-Carlo study pays for the compiled loop once for all its runs: a study whose
    runs hold MIN_SCANS scans together uses it, a single run does not; with the numpy gating
    forced, the study's every decision and its judgement are the same, its NEES within
    rounding."""
    from annslam_lib.evaluation import consistency

    asked = []
    real_run = runner.run

    def spy(*args, **kwargs):
        asked.append(kwargs.get("gating"))
        return real_run(*args, **kwargs)

    monkeypatch.setattr(runner, "run", spy)
    scans = len(simulate.simulate(seed=7300, raw_laser=False, laps=1).detections)
    n = -(-compiled.MIN_SCANS // scans)                       # just enough runs together
    seeds = range(7300, 7300 + n)
    study = consistency.monte_carlo.uncached(seeds, "midpoint", laps=1)
    assert asked == ["compiled"] * n
    asked.clear()
    consistency.monte_carlo.uncached(seeds[:1], "midpoint", laps=1)
    assert asked == ["numpy"]
    asked.clear()
    monkeypatch.setenv("ANNSLAM_KERNEL", "numpy")
    plain = consistency.monte_carlo.uncached(seeds, "midpoint", laps=1)
    assert asked == ["numpy"] * n
    assert plain.mapped == study.mapped
    np.testing.assert_array_equal(plain.rejected_runs, study.rejected_runs)
    np.testing.assert_allclose(plain.nees_runs, study.nees_runs, rtol=1e-9, atol=0)
    assert plain.nees.summary() == study.nees.summary()
    assert plain.map.summary() == study.map.summary()
