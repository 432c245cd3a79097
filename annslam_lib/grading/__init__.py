"""Automatic feedback for the course's graded exercises (nbgrader test cells call these).

``core`` holds the generic machinery (:func:`check_function`, :func:`check_jacobian`,
:class:`GradingError`); one module per chapter holds that chapter's checks, each comparing a
student's function with the library's reference on seeded inputs and edge cases, and naming
known mistakes (including the paper's misprinted equations).
"""
from .core import (NOT_WRITTEN, GradingError, Mistake, call, check_function, check_jacobian,
                   check_raises, describe, fail, fmt)

__all__ = ["NOT_WRITTEN", "GradingError", "Mistake", "call", "check_function", "check_jacobian",
           "check_raises", "describe", "fail", "fmt"]
