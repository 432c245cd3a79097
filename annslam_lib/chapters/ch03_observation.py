"""Chapter 03 explorer: a landmark's predicted measurement and its uncertainty.

The laser sits at the origin of the world, heading East (phi = 0), so the world
frame is the laser frame: x forward, y left. The pose is uncertain (position
sigma, heading sigma), so is the landmark, and the laser adds its own noise R.
The EKF's prediction of the measurement is z = h(pose, landmark) with the
innovation covariance S = H P H^T + R (notebook 03, "the predicted measurement
and its uncertainty"); the plot sets it against a Monte-Carlo cloud of the true
nonlinear h, so a student can see where the linearisation stops being honest.
"""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import FloatSlider, interactive

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..plots.style import show_widget_figure, widget_figure
from ..models.uncertainty import coverage, draw_ellipse, expected_coverage, monte_carlo, propagate
from ..plots.style import notebook_setup as setup

#: The laser pose of the explorer: origin, heading East.
POSE = np.array([0.0, 0.0, 0.0])
#: Laser noise of the Car Park program (as simulate.SimConfig): 0.1 m, 1 degree.
SIGMA_RANGE = 0.1
SIGMA_BEARING = math.radians(1.0)
#: Size of the two panels of :func:`draw_prediction`.
PREDICTION_FIGSIZE = (11, 4.5)

__all__ = ["setup", "measurement_prediction", "draw_prediction", "measurement_explorer"]


def measurement_prediction(landmark_x: float, landmark_y: float, *, sigma_xy: float,
                           sigma_phi: float, sigma_landmark: float = 0.0,
                           sigma_range: float = SIGMA_RANGE,
                           sigma_bearing: float = SIGMA_BEARING, pose=POSE) -> dict:
    """Predicted measurement of the landmark (landmark_x, landmark_y) from ``pose``,
    and its linearised covariance S = H P H^T + R.

    P = diag(sigma_xy^2, sigma_xy^2, sigma_phi^2, sigma_landmark^2, sigma_landmark^2)
    is the covariance of (pose, landmark); R = diag(sigma_range^2, sigma_bearing^2);
    H = [H_pose, H_landmark] from ``observation.observe`` (angles in radians).
    Returns a dict with floats ``range``, ``bearing``, ``sigma_range``,
    ``sigma_bearing``, ``correlation`` and arrays ``z``, ``H``, ``P``, ``R``, ``S``,
    ``pose``, ``landmark``.
    Raises ValueError for a negative sigma or a landmark on the sensor.
    """
    s_xy = _checks.real("sigma_xy", sigma_xy, lo=0.0)
    s_phi = _checks.real("sigma_phi", sigma_phi, lo=0.0)
    s_lm = _checks.real("sigma_landmark", sigma_landmark, lo=0.0)
    s_r = _checks.real("sigma_range", sigma_range, lo=0.0)
    s_b = _checks.real("sigma_bearing", sigma_bearing, lo=0.0)
    pose = np.asarray(pose, dtype=float)
    landmark = np.array([landmark_x, landmark_y], dtype=float)
    z, H_pose, H_lm = observe(pose, landmark)
    H = np.concatenate([H_pose, H_lm], axis=1)
    P = np.diag([s_xy**2, s_xy**2, s_phi**2, s_lm**2, s_lm**2])
    R = np.diag([s_r**2, s_b**2])
    S = propagate(H, P, R)
    sd = np.sqrt(np.diag(S))
    corr = float(S[0, 1] / (sd[0] * sd[1])) if sd[0] > 0 and sd[1] > 0 else 0.0
    return {"range": float(z[0]), "bearing": float(z[1]), "sigma_range": float(sd[0]),
            "sigma_bearing": float(sd[1]), "correlation": corr,
            "z": z, "H": H, "P": P, "R": R, "S": S, "pose": pose, "landmark": landmark}


def _sample_measurements(summary: dict, n: int, seed: int):
    """Monte-Carlo measurements: sample (pose, landmark), apply the true h, add R noise."""
    mean = np.concatenate([summary["pose"], summary["landmark"]])

    def h(x):
        return observe(x[:, :3], x[:, 3:])[0]

    _, _, z = monte_carlo(h, mean, summary["P"], n, seed=seed, angle_outputs=[1])
    noise = np.random.default_rng(seed + 1).standard_normal((n, 2)) * np.sqrt(np.diag(summary["R"]))
    return z + noise


def draw_prediction(summary: dict, *, n_samples: int = 2000, seed: int = 3, axes=None):
    """Two panels: the scene (pose, its 2-sigma position ellipse and heading fan, the
    landmark and its ellipse) and measurement space (bearing in degrees, range) with
    a Monte-Carlo cloud of the true h and the linearised 2-sigma ellipse of S.
    Adds to ``summary``: ``mc_coverage``, the fraction of the cloud inside that ellipse,
    and ``mc_sd_ratio``, the cloud's (range, bearing) standard deviations divided by the
    linearised ones (1 where the linearisation is honest). ``axes``: the two axes to draw
    on (default: a new pyplot figure). Returns the Figure."""
    pose, lm = summary["pose"], summary["landmark"]
    z_mc = _sample_measurements(summary, n_samples, seed)
    summary["mc_coverage"] = coverage(z_mc, summary["z"], summary["S"], 2.0, angle_columns=[1])
    err = z_mc - summary["z"]
    err[:, 1] = wrap_angle(err[:, 1])
    lin_sd = np.sqrt(np.diag(summary["S"]))
    summary["mc_sd_ratio"] = np.std(err, axis=0, ddof=1) / np.where(lin_sd > 0, lin_sd, np.nan)
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=PREDICTION_FIGSIZE)
    a1, a2 = axes
    fig = a1.figure
    P = summary["P"]
    a1.plot(*pose[:2], "k^", ms=9, label="laser (mean pose)")
    if P[0, 0] > 0:
        draw_ellipse(a1, pose[:2], P[:2, :2], 2.0, color="tab:blue", label="2σ position")
    fan = 2.0 * math.sqrt(P[2, 2])
    reach = 1.1 * summary["range"]
    for d in (-fan, 0.0, fan):
        a1.plot([pose[0], pose[0] + reach * math.cos(pose[2] + d)],
                [pose[1], pose[1] + reach * math.sin(pose[2] + d)],
                "-" if d == 0 else ":", color="tab:blue", lw=1)
    a1.plot(*lm, "r*", ms=14, label="landmark")
    if P[3, 3] > 0:
        draw_ellipse(a1, lm, P[3:, 3:], 2.0, color="tab:red", label="2σ landmark")
    a1.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal",
           title="scene (dotted: heading ±2σ)")
    a1.grid(True, alpha=0.3)
    a1.legend(fontsize=8, loc="best")
    deg = np.diag([180.0 / math.pi, 1.0])
    a2.plot(np.degrees(z_mc[::2, 1]), z_mc[::2, 0], ".", ms=2, color="0.7",
            label="Monte Carlo (true h)")
    zb = np.array([math.degrees(summary["bearing"]), summary["range"]])
    S_deg = deg @ summary["S"][::-1, ::-1] @ deg
    draw_ellipse(a2, zb, S_deg, 2.0, color="tab:green", lw=2, label="2σ of S = HPHᵀ + R")
    a2.plot(*zb, "g+", ms=12)
    ratio = summary["mc_sd_ratio"]
    a2.set(xlabel="bearing [deg] (90 = straight ahead)", ylabel="range [m]",
           title=f"Monte-Carlo sd / linearised sd: range {ratio[0]:.2f}, bearing {ratio[1]:.2f}\n"
                 f"inside the 2σ ellipse: {100 * summary['mc_coverage']:.1f}% "
                 f"(a Gaussian: {100 * expected_coverage(2.0):.1f}%)")
    a2.grid(True, alpha=0.3)
    a2.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def measurement_explorer(*, landmark=(10.0, 3.0), sigma_xy: float = 0.3,
                         sigma_phi_deg: float = 5.0, sigma_landmark: float = 0.0,
                         n_samples: int = 2000):
    """Sliders for the landmark position, the pose's position and heading sigmas and the
    landmark's sigma; shows the predicted measurement, S and a Monte-Carlo cloud."""
    holder = {}

    def draw(landmark_x: float, landmark_y: float, sigma_xy: float, sigma_phi_deg: float,
             sigma_landmark: float) -> None:
        try:
            s = measurement_prediction(landmark_x, landmark_y, sigma_xy=sigma_xy,
                                       sigma_phi=math.radians(sigma_phi_deg),
                                       sigma_landmark=sigma_landmark)
        except ValueError as exc:      # e.g. the landmark dragged onto the sensor
            holder["summary"] = {"error": str(exc)}
            print(f"cannot predict: {exc}")
            return
        fig, axes = widget_figure(1, 2, figsize=PREDICTION_FIGSIZE)  # not pyplot: see widget_figure
        draw_prediction(s, n_samples=n_samples, axes=axes)
        holder["summary"] = s
        print(f"z = (range {s['range']:.2f} m, bearing {math.degrees(s['bearing']):.1f} deg); "
              f"sigma_range {s['sigma_range']:.3f} m, sigma_bearing "
              f"{math.degrees(s['sigma_bearing']):.2f} deg, correlation {s['correlation']:+.2f}; "
              f"Monte Carlo: sd ratios {s['mc_sd_ratio'][0]:.2f} (range), "
              f"{s['mc_sd_ratio'][1]:.2f} (bearing), {100 * s['mc_coverage']:.1f}% inside 2σ")
        show_widget_figure(fig)

    slider = dict(continuous_update=False, readout_format=".1f")
    widget = interactive(
        draw,
        landmark_x=FloatSlider(value=landmark[0], min=-5.0, max=40.0, step=0.5,
                               description="landmark x", **slider),
        landmark_y=FloatSlider(value=landmark[1], min=-20.0, max=20.0, step=0.5,
                               description="landmark y", **slider),
        sigma_xy=FloatSlider(value=sigma_xy, min=0.0, max=2.0, step=0.05,
                             description="σ position", **dict(slider, readout_format=".2f")),
        sigma_phi_deg=FloatSlider(value=sigma_phi_deg, min=0.0, max=30.0, step=0.5,
                                  description="σ heading°", **slider),
        sigma_landmark=FloatSlider(value=sigma_landmark, min=0.0, max=2.0, step=0.05,
                                   description="σ landmark", **dict(slider, readout_format=".2f")),
    )
    widget.holder = holder
    return widget
