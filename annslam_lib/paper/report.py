"""The paper reproduced without a browser (``python -m annslam_lib reproduce --out DIR``):
the study of :mod:`annslam_lib.paper.study` on the Car Park (with the verdict over folds of
the data, :func:`~annslam_lib.paper.study.fold_study`), or a short simulated run with
``--fast`` (no folds: its held-out rows are shown, not counted); the paper's Figures 5-8
as PNG and the results table as CSV and Markdown.
"""
from __future__ import annotations

import csv
import math
import numbers
import time
from pathlib import Path

from ..evaluation.summary import METRICS
from .study import FOLD_RULE, FoldStudy, Study, fast_dataset, fold_study, study, verdict

__all__ = ["table_markdown", "verdict_markdown", "write_table", "write_figures", "reproduce"]


def _fmt(v: float) -> str:
    return "" if isinstance(v, float) and math.isnan(v) else repr(float(v))



def table_markdown(st: Study, metrics=None) -> str:
    """The results as a Markdown table: one row per configuration, the ``metrics`` (keys of
    :data:`METRICS`, default all) rounded, mean ± sample sd where the seeds vary."""
    cols = list(METRICS) if metrics is None else list(metrics)
    bad = [c for c in cols if c not in METRICS]
    if bad:
        raise ValueError(f"unknown metric(s) {bad}; known: {list(METRICS)}")
    lines = ["| configuration | landmarks from | runs | " + " | ".join(METRICS[c] for c in cols) + " |",
             "|---" * (3 + len(cols)) + "|"]
    for r in st.table():
        cells = []
        for mt in cols:
            v, s = r[mt], r[mt + "_sd"]
            digits = 0 if mt in ("landmarks", "matched", "unmatched") else 4 if "trace" in mt else 3
            cells.append("—" if math.isnan(v) else f"{v:.{digits}f} ± {s:.{digits}f}" if s > 0
                         else f"{v:.{digits}f}")
        lines.append(f"| {r['configuration']} | {r['landmarks_from']} | {r['n_runs']} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)



def verdict_markdown(rows: list[dict]) -> str:
    """:func:`verdict`'s rows as a Markdown table: claim | what we measured | verdict | why."""
    word = {True: "**holds**", False: "**does not hold**", None: "not testable this way"}

    def said(r):            # a row tested but undecided carries its own word (not demonstrated)
        return f"**{r['verdict']}**" if r.get("verdict") else word[r["holds"]]

    lines = ["| the paper's claim | what we measured | verdict | why |", "|---|---|---|---|"]
    lines += [f"| {r['claim']} | {r['measured']} | {said(r)} | {r['why']} |" for r in rows]
    return "\n".join(lines)



def write_table(st: Study, out, folds: FoldStudy | None = None) -> tuple[Path, Path]:
    """results.csv (full precision, '' for not measurable) and results.md (rounded,
    mean ± sd where the seeds vary, and the claims: :func:`verdict` with ``folds``) in the
    folder ``out``."""
    out = Path(out)
    rows = st.table()
    cols = ["configuration", "landmarks_from", "n_runs"] + [c for m in METRICS for c in (m, m + "_sd")]
    p_csv = out / "results.csv"
    with open(p_csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([r[c] if c in ("configuration", "landmarks_from", "n_runs") else _fmt(r[c])
                        for c in cols])
    lines = [f"# Results: {st.dataset.name}, {len(st.seeds)} training seed(s)", "",
             table_markdown(st)]
    lines += ["", f"Held-out time: t >= {st.t_heldout:.1f} s (last 15 % of the scans); held-out "
              "beacons: leave-beacons-out fold (seed mod 5). ANN and control: mean ± sample sd "
              "over the training seeds. Natural features: point features from the ranges only "
              "(annslam_lib.perception.point_features); their landmarks that match no surveyed "
              "beacon are real objects that were never surveyed, counted as 'unmatched'.",
              "", "## The paper's claims", "",
              ("Held-out accuracy over folds of the data: " + FOLD_RULE) if folds is not None
              else "Held-out accuracy over the training seeds only: shown, not counted.",
              "", verdict_markdown(verdict(st, folds=folds))]
    p_md = out / "results.md"
    p_md.write_text("\n".join(lines) + "\n")
    return p_csv, p_md



def write_figures(st: Study, out) -> list[Path]:
    """The paper's Figures 5-8 as PNG in ``out``: fig5_map (true vs mapped, ANN seed
    ``st.seeds[0]``, 2-sigma ellipses x10), fig6_error_histogram, fig7_performance,
    fig8_regression (``ann_plots``; the chronological model of the first seed)."""
    import matplotlib.pyplot as plt

    from ..plots import ann as ann_plots
    from ..plots import slam as slam_plots

    out = Path(out)
    model, ts, sp = st.models["ann"][0], st.training_set, st.split
    paths = []

    def save(fig, name):
        p = out / name
        fig.savefig(p, dpi=80)
        plt.close(fig)
        paths.append(p)

    fig, ax = plt.subplots(figsize=(6, 8))
    car = st.dataset.name == "car_park"
    slam_plots.plot_true_vs_mapped(st.results["ann"][0], st.dataset, ax=ax, ellipse_scale=10.0,
                                   limits=slam_plots.CAR_PARK_LIMITS if car else None,
                                   label="mapped (ANN)",
                                   title="Figure 5: true and mapped (ANN-enhanced), 2σ ×10")
    save(fig, "fig5_map.png")
    save(ann_plots.plot_error_histogram(model, ts, sp), "fig6_error_histogram.png")
    save(ann_plots.plot_performance(model), "fig7_performance.png")
    save(ann_plots.plot_regression(model, ts, sp), "fig8_regression.png")
    return paths



def reproduce(out, *, fast: bool = False, seeds: int = 5, log=print) -> dict:
    """The whole pipeline (module docstring) into the folder ``out`` (created): the Car
    Park run, or with ``fast`` the short simulated one (:func:`fast_dataset`); ``seeds``
    training seeds. Writes fig5_map.png .. fig8_regression.png, results.csv, results.md.
    Figures are drawn with the Agg backend (the previous backend is restored after).
    Returns dict(study, files, seconds)."""
    import matplotlib

    if isinstance(seeds, bool) or not isinstance(seeds, numbers.Integral) or seeds < 1:
        raise ValueError(f"seeds must be a positive integer, got {seeds!r}")
    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if fast:
        ds = fast_dataset()
    else:
        from ..data.loaders import load_car_park
        ds = load_car_park()
    if log is not None:
        log(f"reproduce: {ds.name}, {seeds} training seed(s), output in {out}")
    st = study.uncached(ds, seeds=seeds, log=log)    # end to end: never from the study cache
    folds = None
    if not fast:                                     # the verdict over folds of the real run
        t = time.perf_counter()
        folds = fold_study.uncached(ds)
        if log is not None:
            log(f"[{time.perf_counter() - t0:6.1f} s] verdict over folds: "
                f"{time.perf_counter() - t:.2f} s")
    previous = matplotlib.get_backend()
    matplotlib.use("Agg")
    try:
        t = time.perf_counter()
        files = write_figures(st, out)
        files += list(write_table(st, out, folds))
    finally:
        if previous.lower() != "agg":
            matplotlib.use(previous)
    seconds = time.perf_counter() - t0
    if log is not None:
        log(f"[{seconds:6.1f} s] figures and table: {time.perf_counter() - t:.2f} s")
        log("\n".join(f"  wrote {p}" for p in files))
        log(f"reproduce: done in {seconds:.1f} s")
    return {"study": st, "files": files, "seconds": seconds}
