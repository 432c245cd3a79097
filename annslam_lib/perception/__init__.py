"""Perception layer: from raw sensor data to landmark detections, and which landmark each is.

- ``beacons``: reflective-tape beacons from raw laser scans, point features from ranges
- ``trees``: Victoria Park's tree detections and their filter
- ``sources``: which detections a run's filter uses, with their noise
- ``association``: chi-square gating and nearest neighbour (and the filter's fast copies)
- ``jcbb``: joint compatibility branch and bound, the whole scan's association at once
"""

__all__ = ["beacons", "trees", "sources", "association", "jcbb"]
