"""One companion module per notebook: its explorers (widgets) and chapter-only figures,
so a notebook cell stays one line (as the companion modules of Labbe's Kalman filter book).

Every chapter imports its module under one name and starts with its set-up line::

    from annslam_lib.chapters import ch03_observation as chapter
    chapter.setup()

Each explorer is built from a pure function (testable without a browser) and a drawing
callback; the widget keeps its latest result in ``widget.holder["summary"]`` so a headless
test can move a slider and check what a student would see.

- ``ch00_course_map``: the tour's figures and the scan scrubber
- ``ch01_kinematics``: the exact turning arc against Euler steps, dead reckoning against GPS
- ``ch01a_kalman_filter``: the Kalman filter's experiments, figures and explorer
- ``ch02_laser_offset``: where the laser offset puts the laser's path, against GPS
- ``ch03_observation``: a landmark's predicted measurement and its uncertainty
- ``ch04_landmarks``: beacons extracted scan by scan, and gating
- ``ch04a_localisation``: EKF localisation on the surveyed Car Park map
- ``ch05_ekf_slam``: the EKF-SLAM run on the Car Park, scrubbed in time and re-tuned
- ``ch05a_diagnose``: the lab's broken filters, each with a planted defect, and their evidence
- ``ch06_victoria_park``: one EKF-SLAM run over Victoria Park, scrubbed in time
- ``ch07_ann_training``: how big the landmark network should be
- ``ch08_verdict``: the verdict's control experiment on a slider
- ``ch09_capstone``: the capstone, in which a student's own EKF-SLAM runs
- ``ch10_beyond_ekf``: why the filter claims too much, first-estimates Jacobians, JCBB, the
  runs as factor graphs
- ``ch11_graph_slam``: graph-SLAM from scratch on the Car Park, against GTSAM; the
  information matrix's sparsity, the gauge, wrong associations and a robust loss
- ``harness``: the harness a student's own filter runs in (chapters 04a and 09): a run as
  steps, the loop's track, its score against the truth
"""

__all__ = ["ch00_course_map", "ch01_kinematics", "ch01a_kalman_filter", "ch02_laser_offset",
           "ch03_observation", "ch04_landmarks", "ch04a_localisation", "ch05_ekf_slam",
           "ch05a_diagnose", "ch06_victoria_park", "ch07_ann_training", "ch08_verdict",
           "ch09_capstone", "ch10_beyond_ekf", "ch11_graph_slam", "harness"]
