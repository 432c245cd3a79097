"""The course as instructors run it: grading that a submission cannot game.

- ``grader``: scores from the instructor's notebook, decided outside the student's code
- ``sandbox``: the kernel that runs student code (bubblewrap, limits, time-outs, deadline)
- ``codec``: data, never code, between the grader and that kernel
- ``kernel_side``: the grader's small helper inside the kernel
"""
