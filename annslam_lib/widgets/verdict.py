"""Chapter 08 explorer: the verdict's control experiment on a slider.

The paper credits the ANN for a smaller position uncertainty. In a Kalman filter the
covariance depends on the measurement noise R the filter is TOLD, not on the
measurements: the plain beacons-only filter told a smaller R becomes just as certain.
:func:`r_scale_summary` runs the beacons-only EKF-SLAM (``ekf_slam.run``, about 0.2 s on the
Car Park) with R scaled by a factor k (both standard deviations times sqrt(k)) and measures
what the verdict measures (``reproduce.run_metrics``): the mean P_xx + P_yy, the map RMSE
against the surveyed beacons (absolute and after the best rigid alignment), the path RMSE
against GPS, and the normalised NIS. :func:`r_scale_sweep` does it for a range of k once;
the explorer :func:`r_scale_explorer` only looks the sweep up (notebook 08, section 3):
the covariance falls steadily with k and reaches the ANN run's, while the map error does not
improve.
"""
from __future__ import annotations

import html
import io
import math
import numbers

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import HTML, Image, SelectionSlider, VBox
from matplotlib.figure import Figure

from .. import ekf_slam, reproduce
from ..ekf_slam import SlamConfig
from ..records import Dataset

__all__ = ["SCALES", "r_scale_summary", "r_scale_sweep", "equivalent_scale",
           "reference_from_study", "plot_r_scale", "r_scale_explorer"]

#: Factors k applied to R by the sweep and the explorer's slider (1 = the sensor's R).
SCALES = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 2.0, 3.0)


def _scale(k) -> float:
    if isinstance(k, bool) or not isinstance(k, numbers.Real) or not (0 < k < math.inf):
        raise ValueError(f"the R scale must be a positive finite number, got {k!r}")
    return float(k)


def r_scale_summary(dataset: Dataset, scale: float = 1.0, config: SlamConfig | None = None, *,
                    t_heldout: float | None = None) -> dict:
    """The beacons-only filter (``config``, default ``SlamConfig.for_dataset``) with its
    measurement noise R = diag(sigma_range^2, sigma_bearing^2) multiplied by ``scale``.

    Returns a dict: scale, sigma_range (m), sigma_bearing (rad), t (K,) and trace (K,) the
    laser position variance P_xx + P_yy after each scan (``reproduce.pose_trace``), and
    ``reproduce.run_metrics``' pose_trace (its mean, m^2), map_rmse, map_rmse_aligned,
    traj_rmse (m), landmarks, matched, plus pose_trace_heldout and traj_rmse_heldout
    if ``t_heldout`` is given (NaN otherwise); nis_per_dof (laser NIS / degrees of
    freedom over the run; 1 for a consistent filter); result (the SlamResult)."""
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    if dataset.beacons is None:
        raise ValueError(f"dataset {dataset.name!r} has no surveyed beacons: no map error")
    k = _scale(scale)
    base = SlamConfig.for_dataset(dataset.name) if config is None else config
    if not isinstance(base, SlamConfig):
        raise ValueError(f"config must be a SlamConfig, got {type(base).__name__}")
    cfg = base.replace(sigma_range=base.sigma_range * math.sqrt(k),
                       sigma_bearing=base.sigma_bearing * math.sqrt(k))
    r = ekf_slam.run(dataset, cfg, progress=False)
    out = reproduce.run_metrics(r, dataset, t_heldout=t_heldout)
    t, tr = reproduce.pose_trace(r)
    laser = r.nis["kind"] == 0
    dof = float(np.sum(r.nis["dof"][laser]))
    out.update(scale=k, sigma_range=cfg.sigma_range, sigma_bearing=cfg.sigma_bearing, t=t,
               trace=tr, result=r,
               nis_per_dof=float(np.sum(r.nis["nis"][laser]) / dof) if dof else math.nan)
    return out


def r_scale_sweep(dataset: Dataset, scales=SCALES, config: SlamConfig | None = None, *,
                  t_heldout: float | None = None) -> dict:
    """:func:`r_scale_summary` for every factor in ``scales`` (distinct, positive), as
    {scale: summary} in increasing order."""
    ks = sorted(_scale(k) for k in scales)
    if not ks or len(set(ks)) != len(ks):
        raise ValueError(f"scales must be distinct positive numbers, got {scales!r}")
    return {k: r_scale_summary(dataset, k, config, t_heldout=t_heldout) for k in ks}


def equivalent_scale(sweep: dict, pose_trace: float) -> float:
    """The factor k at which the sweep's mean P_xx + P_yy equals ``pose_trace`` (m^2),
    interpolated linearly in log k and log trace; NaN outside the sweep's range."""
    ks = np.array(sorted(sweep))
    tr = np.array([sweep[k]["pose_trace"] for k in ks])
    if not np.all(np.diff(tr) > 0):
        raise ValueError("the sweep's mean pose variance does not increase with k: "
                         "cannot interpolate")
    if not (tr[0] <= pose_trace <= tr[-1]):
        return math.nan
    return float(np.exp(np.interp(math.log(pose_trace), np.log(tr), np.log(ks))))


def reference_from_study(st, index: int = 0) -> dict:
    """The ANN-enhanced run number ``index`` of a ``reproduce.study`` as the explorer's
    reference: label, t, trace, and its pose_trace, map_rmse, map_rmse_aligned, traj_rmse
    and the network's sigma_range, sigma_bearing."""
    r = st.results["ann"][index]
    t, tr = reproduce.pose_trace(r)
    m = st.runs["ann"][index]
    model = st.models["ann"][index]
    return {"label": f"ANN-enhanced (seed {st.seeds[index]})", "t": t, "trace": tr,
            "pose_trace": m["pose_trace"], "map_rmse": m["map_rmse"],
            "map_rmse_aligned": m["map_rmse_aligned"], "traj_rmse": m["traj_rmse"],
            "sigma_range": model.sigma_range, "sigma_bearing": model.sigma_bearing}


def plot_r_scale(sweep: dict, scale: float, reference: dict | None = None, fig=None):
    """Three panels for the factor ``scale`` of ``sweep``: P_xx + P_yy over time (k = 1,
    the chosen k, the reference run); the mean against k; the map RMSE (absolute and
    aligned) against k. The reference's values are dashed lines. Returns the Figure."""
    if scale not in sweep:
        raise ValueError(f"scale {scale!r} is not in the sweep {tuple(sweep)}")
    if fig is None:
        fig = plt.figure(figsize=(13, 4))
    a0, a1, a2 = fig.subplots(1, 3)
    ks = np.array(sorted(sweep))
    s = sweep[scale]
    if 1.0 in sweep and scale != 1.0:
        a0.plot(sweep[1.0]["t"], sweep[1.0]["trace"], color="tab:blue", lw=1,
                label="beacons-only, R × 1", gid="trace_1")
    a0.plot(s["t"], s["trace"], color="k", lw=1.2, label=f"beacons-only, R × {scale:g}",
            gid="trace_k")
    if reference is not None:
        a0.plot(reference["t"], reference["trace"], color="tab:red", lw=1, ls="--",
                label=reference["label"], gid="trace_ref")
    a0.set(xlabel="t (s)", ylabel="P_xx + P_yy (m²)", yscale="log",
           title="position variance after each scan")
    a0.legend(fontsize=7)
    trace = np.array([sweep[k]["pose_trace"] for k in ks])
    a1.plot(ks, trace, "o-", color="tab:blue", gid="mean_trace")
    a1.plot([scale], [s["pose_trace"]], "s", ms=11, mfc="none", mec="k", mew=1.5, gid="current")
    rmse = np.array([sweep[k]["map_rmse"] for k in ks])
    aligned = np.array([sweep[k]["map_rmse_aligned"] for k in ks])
    a2.plot(ks, rmse, "o-", color="tab:purple", label="map RMSE, absolute", gid="map_rmse")
    a2.plot(ks, aligned, "o-", color="tab:green", label="map RMSE, aligned",
            gid="map_rmse_aligned")
    a2.plot([scale, scale], [s["map_rmse"], s["map_rmse_aligned"]], "s", ms=11, mfc="none",
            mec="k", mew=1.5)
    if reference is not None:
        a1.axhline(reference["pose_trace"], color="tab:red", ls="--", label=reference["label"],
                   gid="ref_trace")
        a2.axhline(reference["map_rmse"], color="tab:red", ls="--",
                   label=f"{reference['label']}, absolute", gid="ref_map_rmse")
        a2.axhline(reference["map_rmse_aligned"], color="tab:red", ls=":",
                   label=f"{reference['label']}, aligned", gid="ref_map_rmse_aligned")
        a1.legend(fontsize=7)
    a1.set(xscale="log", yscale="log", xlabel="R scale k", ylabel="mean P_xx + P_yy (m²)",
           title="uncertainty: falls with the R it is told")
    a2.set(xscale="log", xlabel="R scale k", ylabel="m", ylim=(0, 1.3 * max(rmse.max(), 0.01)),
           title="map error: does not improve")
    a2.legend(fontsize=7)
    for ax in (a1, a2):
        ax.set_xticks(ks, [f"{k:g}" for k in ks], fontsize=7)
        ax.minorticks_off()
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _line(s: dict, reference: dict | None) -> str:
    text = (f"R × {s['scale']:g}: sigma_range {s['sigma_range']:.3f} m, sigma_bearing "
            f"{math.degrees(s['sigma_bearing']):.2f}°; mean P_xx+P_yy {s['pose_trace']:.4f} m², "
            f"map RMSE {s['map_rmse']:.3f} m ({s['map_rmse_aligned']:.3f} m aligned), path RMSE "
            f"vs GPS {s['traj_rmse']:.3f} m, NIS/dof {s['nis_per_dof']:.2f}")
    if reference is not None:
        text += (f"\n{reference['label']}: mean P_xx+P_yy {reference['pose_trace']:.4f} m², map "
                 f"RMSE {reference['map_rmse']:.3f} m ({reference['map_rmse_aligned']:.3f} m "
                 f"aligned), path RMSE {reference['traj_rmse']:.3f} m")
    return text


def _render(sweep: dict, scale: float, reference: dict | None) -> bytes:
    """The three panels as PNG bytes (a matplotlib Figure, not pyplot: nothing is shown as a
    side effect)."""
    fig = Figure(figsize=(13, 4), dpi=80)
    plot_r_scale(sweep, scale, reference, fig=fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def r_scale_explorer(dataset: Dataset | None = None, *, sweep: dict | None = None,
                     reference: dict | None = None, scale: float = 1.0,
                     config: SlamConfig | None = None, t_heldout: float | None = None):
    """A slider over the factor k of R: the beacons-only filter's position variance and map
    error for that k (:func:`plot_r_scale`) next to the ``reference`` run (e.g.
    :func:`reference_from_study`). ``sweep``: a precomputed :func:`r_scale_sweep`; without it
    one is computed from ``dataset`` over :data:`SCALES` (2 s on the Car Park).

    Returns a VBox (slider, image, text); the latest summary is in
    ``widget.holder["summary"]``, the sweep in ``holder["sweep"]``, the text in
    ``holder["text"]``. Plain Image and HTML widgets (no Output widget), like
    ``widgets.slam.slam_explorer``, for headless executors."""
    if sweep is None:
        if dataset is None:
            raise ValueError("r_scale_explorer needs a dataset or a precomputed sweep")
        sweep = r_scale_sweep(dataset, SCALES, config, t_heldout=t_heldout)
    if not isinstance(sweep, dict) or not sweep:
        raise ValueError("sweep must be the dict returned by r_scale_sweep")
    ks = sorted(sweep)
    if scale not in sweep:
        raise ValueError(f"scale {scale!r} is not in the sweep {tuple(ks)}")
    holder: dict = {"sweep": sweep}
    slider = SelectionSlider(options=[(f"{k:g}", k) for k in ks], value=scale,
                             description="R × k", continuous_update=False)
    image = Image(format="png")
    text = HTML()

    def update(_change=None) -> None:
        k = slider.value
        holder["summary"] = sweep[k]
        holder["text"] = _line(sweep[k], reference)
        image.value = _render(sweep, k, reference)
        text.value = f"<pre>{html.escape(holder['text'])}</pre>"

    slider.observe(update, names="value")
    update()
    widget = VBox([slider, image, text])
    widget.holder = holder
    return widget
