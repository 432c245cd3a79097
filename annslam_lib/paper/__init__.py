"""The paper: its equations as printed, the errata that prove the misprints, the study of
its claims and the report that reproduces its figures.

- ``equations``: the printed formulas, typos included (``*_printed``)
- ``errata``: :data:`ERRATA` and :data:`CONFIRMED` with their numerical proofs
- ``study``: the Car Park experiment, the simulator transfer, the verdict, the R-scale sweep
- ``fold_stats``: the verdict's statistics over folds (rule, corrected interval, TOST)
- ``figures``: the verdict's figures (pose uncertainty, transfer, R-scale sweep)
- ``report``: Figures 5-8 and the results table (``python -m annslam_lib reproduce``)

The printed forms and the errata are reachable from here (``paper.ERRATA``,
``paper.observation_printed``).
"""
from __future__ import annotations

from .._lazy import attach
from .equations import __all__ as _EQUATIONS

__getattr__, __dir__, __all__ = attach(
    __name__, ["equations", "errata", "study", "fold_stats", "figures", "report"],
    {**{n: "equations" for n in _EQUATIONS},
     **{n: "errata" for n in ("Erratum", "ERRATA", "CONFIRMED", "errata_table",
                              "errata_markdown", "check_reading_b")}})
