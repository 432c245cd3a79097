"""One companion module per notebook: its explorers (widgets) and chapter-only figures,
so a notebook cell stays one line (as the companion modules of Labbe's Kalman filter book).

Every chapter imports its module under one name and starts with its set-up line::

    from annslam_lib.chapters import ch03_observation as chapter
    chapter.setup()

Each explorer is built from a pure function (testable without a browser) and a drawing
callback; the widget keeps its latest result in ``widget.holder["summary"]`` so a headless
test can move a slider and check what a student would see.
"""

__all__ = ["ch00_course_map", "ch01_kinematics", "ch01a_kalman_filter", "ch02_laser_offset", "ch03_observation", "ch04_landmarks", "ch04a_localisation", "ch05_ekf_slam", "ch06_victoria_park", "ch07_ann_training", "ch08_verdict", "ch09_capstone", "ch10_beyond_ekf"]
