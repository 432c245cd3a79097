"""Figures: one style module and the chapters' shared plots.

- ``style``: ``notebook_setup()`` (every chapter's first line), the axes helper, widget figures
- ``data``: the runs (maps, scans, the car)
- ``slam``: Figure 5, landmark zooms, correlations, consistency bands
- ``ann``: the network's figures (the paper's Figures 6-8)
- ``blit``: a widget figure whose steps redraw only what moves
- ``alt``: every figure's alt text (what it shows, for a screen reader)
- ``frames``: a widget's pictures at several values of a control, for the website's animations
"""

__all__ = ["style", "data", "slam", "ann", "blit", "alt", "frames"]
