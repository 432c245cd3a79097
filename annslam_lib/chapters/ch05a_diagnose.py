"""Chapter 05a companion: diagnose the broken filter.

The lab hands each student several EKF-SLAM filters, each with one planted defect drawn for
that student (:func:`draw`, seeded by the student's name), and a control: the course's own
filter. The student runs them on the lab's simulated runs (:data:`LAB_RUNS`), reads the
evidence (:func:`evidence`: NEES against the truth, NIS, bearing innovations, the path and
the map) and names each defect and the evidence that shows it.

Every defect has one telltale (:data:`DEFECTS`), a sentence of :data:`EVIDENCE`; the
telltales are measured, not asserted: :func:`evidence` computes each one from a filter's
runs against the control's, and a defect is identifiable because its telltale is present
in its runs and absent in every other defect's and the control's.
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass

import numpy as np

from .._cache import memoize
from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..plots.style import BLUE, ORANGE, PALETTE, figure
from ..plots.style import notebook_setup as setup
from ..slam.base import InnovationError
from ..slam.dense import augment_landmark, joseph_update
from .ch09_capstone import reference_associate
from .harness import Predict, Track, dataset_of, midpoint_step, score_run, steps

__all__ = ["setup", "LAB_RUNS", "DEFECTS", "EVIDENCE", "Defect", "LabFilter", "student",
           "draw", "example_filter", "lab_filters", "DEMO", "run_filter", "evidence", "reference_diagnosis",
           "evidence_table", "evidence_figure"]

#: The lab's runs: one lap of the simulator and two laps of another loop (the heading
#: passes +-180 deg while landmarks are in view on both, so an unwrapped bearing shows).
LAB_RUNS = ("sim:5002:1", "sim:5003")

#: What a student may cite, as the notebook shows it.
EVIDENCE = {
    "nis-twice": "the NIS is about twice its expected value, while the path stays as good "
                 "as the control's",
    "nis-low": "the NIS is far below its expected value (under half of it)",
    "nees-high-nis-normal": "the pose NEES is several times the control's, while the NIS is "
                            "as expected",
    "bearing-jumps": "bearing innovations of about +-360 deg",
    "not-positive-definite": "the filter stops: an innovation covariance is not positive "
                             "definite",
    "runs-away": "the path runs away and the map fills with spurious landmarks, with no "
                 "bearing jump",
}


@dataclass(frozen=True)
class Defect:
    """A planted defect: what it is (``text``) and its telltale (a key of EVIDENCE)."""
    text: str
    telltale: str


#: The defects a student's filters are drawn from.
DEFECTS = {
    "R-halved": Defect("the filter's R is half the laser's true noise covariance", "nis-twice"),
    "R-too-large": Defect("the filter's R is four times the laser's true noise covariance",
                          "nis-low"),
    "Q-too-small": Defect("the filter's Q is a tenth of the odometry's true noise covariance",
                          "nees-high-nis-normal"),
    "no-bearing-wrap": Defect("the bearing innovation is not wrapped to (-180 deg, 180 deg]",
                              "bearing-jumps"),
    "no-cross-predict": Defect("the prediction moves P_vv but not the pose-map cross "
                               "covariances P_vm", "not-positive-definite"),
    "innovation-sign": Defect("the update uses z_hat - z instead of z - z_hat",
                              "runs-away"),
}

#: The worked example's defect, not among those drawn: Q ten times the odometry's noise.
DEMO = "Q-too-large"

#: How many defective filters each student diagnoses.
N_FILTERS = 4
LETTERS = "ABCDEF"

# ------------------------------------------------------------------ who, and their draw


def student() -> str:
    """The name a notebook's draw is made for: the hub's user name (``JUPYTERHUB_USER``);
    off a hub, the fixed name 'demo' (the draw of the course's own notebook)."""
    return os.environ.get("JUPYTERHUB_USER") or "demo"


def draw(name: str) -> dict[str, str]:
    """{letter: defect key} of the filters drawn for student ``name``: N_FILTERS of the
    DEFECTS, in an order and a choice fixed by the name (sha256 of it seeds the draw), so
    two students rarely share a draw (360 possible draws)."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"a student's name is a non-empty string, got {name!r}")
    seed = int.from_bytes(hashlib.sha256(f"annslam-05a:{name}".encode()).digest()[:8], "big")
    keys = sorted(DEFECTS)
    pick = np.random.default_rng(seed).permutation(len(keys))[:N_FILTERS]
    return {LETTERS[i]: keys[k] for i, k in enumerate(pick)}


# --------------------------------------------------------------------------- the filters

@dataclass(frozen=True)
class LabFilter:
    """One of the lab's filters: its name in the notebook ('control', 'A', ...) and,
    hidden from its display, the defect it carries (None for the control)."""
    name: str
    _defect: str | None

    def __repr__(self) -> str:
        return f"LabFilter({self.name!r})"


def example_filter() -> LabFilter:
    """The worked example's filter (its defect, :data:`DEMO`, is never drawn)."""
    return LabFilter("example", DEMO)


def lab_filters(name: str | None = None) -> list[LabFilter]:
    """The control and the filters drawn for ``name`` (default :func:`student`)."""
    d = draw(name or student())
    return [LabFilter("control", None)] + [LabFilter(k, v) for k, v in d.items()]


def _predict(x, P, control, dt, Q, vehicle, defect):
    x, P = x.copy(), P.copy()
    pose, F, G = midpoint_step(x[:3], control, dt, vehicle)
    if defect == "Q-too-small":
        Q = Q * 0.1
    elif defect == DEMO:
        Q = Q * 10
    x[:3] = pose
    if defect == "no-cross-predict":
        P[:3, :3] = F @ P[:3, :3] @ F.T
    else:
        P[:3, :] = F @ P[:3, :]
        P[:, :3] = P[:, :3] @ F.T
    P[:3, :3] += G @ Q @ G.T
    return x, 0.5 * (P + P.T)


def _update(x, P, z, idx, R, defect):
    """The EKF update of chapter 05 (Joseph form), with the defect planted; returns
    (x, P, nis, bearing innovations)."""
    if defect == "R-halved":
        R = R / 2
    elif defect == "R-too-large":
        R = R * 4
    n = len(x)
    zhat, Hp, Hm = observe(x[:3], x[3:].reshape(-1, 2)[idx])
    H = np.zeros((2 * idx.size, n))
    for i, j in enumerate(idx.tolist()):
        H[2 * i:2 * i + 2, :3] = Hp[i]
        H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hm[i]
    nu = z - zhat
    if defect != "no-bearing-wrap":
        nu[:, 1] = wrap_angle(nu[:, 1])
    if defect == "innovation-sign":
        nu = -nu
    Rm = np.kron(np.eye(idx.size), R)
    S = H @ P @ H.T + Rm
    nu = nu.ravel()
    nis = float(nu @ np.linalg.solve(S, nu))
    x, P = joseph_update(x, P, nu, H, Rm)
    return x, P, nis, nu[1::2]


@memoize
def run_filter(f: LabFilter, run: str) -> dict:
    """Run lab filter ``f`` on ``run``: the harness's track (t, pose, pose_cov, landmarks,
    landmark_cov), plus per scan with an update its time, NIS and dof
    (``nis_t``, ``nis``, ``nis_dof``) and every bearing innovation
    (``bearing_t``, ``bearing_innovation``), and ``stopped``: None, or why the filter
    stopped (an innovation covariance not positive definite) and when. Computed once per
    machine, then read back (the lab's Run All and its figures ask for the same runs)."""
    defect = f._defect
    track = Track()
    it = steps(run)
    st = next(it)
    x, P = st.x0.copy(), st.P0.copy()
    nis_t, nis, dof, bt, bi = [], [], [], [], []
    stopped = None
    for s in it:
        if isinstance(s, Predict):
            x, P = _predict(x, P, s.control, s.dt, s.Q, st.vehicle, defect)
            continue
        try:
            a = np.asarray(reference_associate(x, P, s.z, st.R, st.gate, st.new_landmark))
            old = np.flatnonzero(a >= 0)
            if old.size:
                x, P, q, b = _update(x, P, s.z[old].copy(), a[old], st.R, defect)
                nis_t.append(s.t)
                nis.append(q)
                dof.append(2 * old.size)
                bt += [s.t] * b.size
                bi += b.tolist()
        except (InnovationError, np.linalg.LinAlgError, ValueError) as e:
            stopped = f"stopped at t = {s.t:.1f} s: {e}"
            break
        for i in np.flatnonzero(a == -1):
            x, P = augment_landmark(x, P, s.z[i], st.R)
        track.record(s.t, x, P)
    out = track.result()
    out.update(nis_t=np.asarray(nis_t), nis=np.asarray(nis), nis_dof=np.asarray(dof, int),
               bearing_t=np.asarray(bt), bearing_innovation=np.asarray(bi), stopped=stopped,
               run=run, filter=f.name)
    return out


# ------------------------------------------------------------------------------ evidence

def _numbers(result: dict) -> dict:
    """The figures one run of one filter gives: pose NEES mean, NIS per dof, the largest
    bearing innovation (deg), the path's RMS error and spurious landmarks."""
    if len(result["t"]) == 0:
        return {"nees": math.nan, "nis_per_dof": math.nan, "max_bearing_deg": math.nan,
                "path_rmse": math.nan, "spurious": 0}
    s = score_run(result, result["run"])
    nis = float(np.sum(result["nis"]) / max(np.sum(result["nis_dof"]), 1))
    b = result["bearing_innovation"]
    return {"nees": s["nees_mean"], "nis_per_dof": nis,
            "max_bearing_deg": float(np.degrees(np.max(np.abs(b)))) if b.size else 0.0,
            "path_rmse": s["path_rmse"], "spurious": s["spurious"]}


def evidence(result: dict, control: dict) -> dict:
    """The telltales (keys of EVIDENCE) one run of a filter shows against the control's
    run on the same data, and the figures they are read from.

    Returns {'figures': {...}, 'control': {...}, 'shows': [keys]}. The rules (written
    before the lab's runs were looked at, margins chosen between the defects' effects):
    'not-positive-definite' if the filter stopped; 'bearing-jumps' if a bearing innovation
    exceeds 180 deg; 'runs-away' if the path's RMS error is over 5 times the control's
    and no bearing jumps; 'nis-twice' if NIS per dof is 1.5 to 3 times the control's and
    the path under 2 times the control's; 'nis-low' if NIS per dof is under half the
    control's; 'nees-high-nis-normal' if the pose NEES is over 2.5 times the control's and
    NIS per dof within 20 % of the control's."""
    if result["run"] != control["run"]:
        raise ValueError(f"a filter's run {result['run']!r} is compared with the control's "
                         f"on {control['run']!r}: compare runs of the same data")
    c = _numbers(control)
    if result["stopped"]:
        return {"figures": _numbers(result), "control": c, "shows": ["not-positive-definite"]}
    f = _numbers(result)
    shows = []
    jumps = f["max_bearing_deg"] > 180.0
    if jumps:
        shows.append("bearing-jumps")
    nis_ratio = f["nis_per_dof"] / c["nis_per_dof"]
    path_ratio = f["path_rmse"] / c["path_rmse"]
    if path_ratio > 5 and not jumps:
        shows.append("runs-away")
    if 1.5 <= nis_ratio <= 3.0 and path_ratio < 2:
        shows.append("nis-twice")
    if nis_ratio < 0.5:
        shows.append("nis-low")
    if f["nees"] / c["nees"] > 2.5 and abs(nis_ratio - 1) <= 0.2:
        shows.append("nees-high-nis-normal")
    return {"figures": f, "control": c, "shows": shows}


def reference_diagnosis(shows: list[str]) -> str | None:
    """The defect whose telltale is among ``shows`` (the evidence of a filter's runs),
    None when no telltale, or more than one defect's, is shown."""
    hits = [k for k, d in DEFECTS.items() if d.telltale in shows]
    return hits[0] if len(hits) == 1 else None


def _two(x: float) -> str:
    """Two significant digits: a filter that runs away is chaotic, its third digit is
    rounding (it changes with the machine's arithmetic); its first two are not."""
    return "nan" if not np.isfinite(x) else f"{float(f'{x:.2g}'):g}"


def evidence_table(results: dict[str, list[dict]]) -> str:
    """A text table, one row per filter and run, to two significant digits: NEES, NIS per
    dof, largest bearing innovation, path RMSE, spurious landmarks ('10+' for ten or more)
    (``results``: {filter name: its runs})."""
    rows = [f"{'filter':8s} {'run':12s} {'NEES':>8s} {'NIS/dof':>8s} {'max |bearing innov|':>20s} "
            f"{'path RMSE':>10s} {'spurious':>9s}  stopped"]
    for name, runs in results.items():
        for r in runs:
            f = _numbers(r)
            spurious = f"{f['spurious']:d}" if f["spurious"] < 10 else "10+"
            rows.append(f"{name:8s} {r['run']:12s} {_two(f['nees']):>8s} "
                        f"{_two(f['nis_per_dof']):>8s} {_two(f['max_bearing_deg']):>16s} deg "
                        f"{_two(f['path_rmse']):>8s} m {spurious:>9s}  "
                        f"{'yes' if r['stopped'] else 'no'}")
    return "\n".join(rows)


def evidence_figure(result: dict, control: dict):
    """Three panels for one filter against the control on the same run: pose NEES (log
    scale), NIS per dof per scan, and the bearing innovations (deg)."""
    fig, axes = figure(1, 3, height=3.4)
    c, f = control, result
    t_end = f["t"][-1] if len(f["t"]) else None
    for r, colour, label in ((c, BLUE, "control"), (f, ORANGE, f"filter {f['filter']}")):
        if len(r["t"]):
            nees = score_run(r, r["run"])["nees"]
            axes[0].semilogy(r["t"], np.maximum(nees, 1e-3), color=colour, lw=1, label=label)
        if r["nis"].size:
            axes[1].semilogy(r["nis_t"], np.maximum(r["nis"] / r["nis_dof"], 1e-3), ".",
                             color=colour, ms=2, label=label)
        if r["bearing_innovation"].size:
            axes[2].plot(r["bearing_t"], np.degrees(r["bearing_innovation"]), ".", color=colour,
                         ms=2, label=label)
    axes[0].axhline(3, color=PALETTE[-1], lw=1, ls="--", label="expected (3)")
    axes[1].axhline(1, color=PALETTE[-1], lw=1, ls="--", label="expected (1)")
    axes[0].set(xlabel="time [s]", ylabel="pose NEES", title="NEES against the truth")
    axes[1].set(xlabel="time [s]", ylabel="NIS / dof", title="NIS per scan")
    axes[2].set(xlabel="time [s]", ylabel="bearing innovation [deg]", title="bearing innovations")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left")
    if t_end is not None and f["stopped"]:
        axes[0].axvline(t_end, color="0.3", lw=1)
    return fig


def dataset(run: str):
    """The dataset of a lab run (for its truth and landmarks)."""
    return dataset_of(run)
