"""Chapter 08 explorer: the verdict's control experiment on a slider.

The paper credits the ANN for a smaller position uncertainty. In a Kalman filter the
covariance depends on the measurement noise R the filter is TOLD, not on the
measurements: the plain beacons-only filter told a smaller R becomes just as certain.
:func:`r_scale_summary` runs the beacons-only EKF-SLAM (``slam.runner.run``, about 0.2 s on the
Car Park) with R scaled by a factor k (both standard deviations times sqrt(k)) and measures
what the verdict measures (``evaluation.summary.run_metrics``): the mean P_xx + P_yy, the map RMSE
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

from ipywidgets import HTML, Image, SelectionSlider, VBox
from matplotlib.figure import Figure

from ..data.records import Dataset
from ..paper.study import SCALES, r_scale_sweep
from ..plots.paper import plot_r_scale
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig

__all__ = ["setup", "r_scale_explorer"]

#: Factors k applied to R by the sweep and the explorer's slider (1 = the sensor's R).


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
