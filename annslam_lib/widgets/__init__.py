"""Interactive explorers for the notebooks (ipywidgets), one module per chapter.

Each explorer is built from a pure function (testable without a browser) plus a
drawing callback; the widget keeps the latest result in ``widget.holder["summary"]``
so a headless test can move the slider and check what a student would see.
"""
from .data import scan_scrubber, scan_summary

__all__ = ["scan_scrubber", "scan_summary"]
