"""``python -m annslam_lib``: the course's command line (``annslam_lib.course.cli``)."""
import sys

from .course.cli import main

if __name__ == "__main__":
    sys.exit(main())
