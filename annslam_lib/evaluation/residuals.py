"""How a residual that should be zero is shown: as what it means, not as its last digits.

Two computations of the same quantity that agree to rounding (a closed form against SymPy,
the efficient filter against the dense one) differ by a few units in the last place, and
which few depends on the CPU, the BLAS kernel and the summation order: 3.3e-16 on one
machine is 2.2e-16 on the next. Central differences agree with an analytic Jacobian to
their own truncation and rounding error, about 1e-9 here, again with machine-dependent
digits. A stored notebook output that printed those digits would fail on the next machine,
and the digits teach nothing: what matters is that the residual is below the resolution of
the comparison. :func:`residual` says so, with a bound that no CPU crosses.
"""
from __future__ import annotations

import math

__all__ = ["ROUNDING", "DIFFERENCES", "residual", "residuals", "bound_text"]

ROUNDING = 1e-12
"""Bound for two closed forms of one quantity at the course's scales (coordinates up to a
few hundred metres, covariances up to about 100): rounding leaves about 1e-14, a
hundredfold margin."""

DIFFERENCES = 1e-7
"""Bound for central differences (``geometry.numerical_jacobian``) against an analytic
Jacobian: their error is about 1e-9 to 1e-8 here, a tenfold margin."""


def bound_text(bound: float) -> str:
    """A bound as the course writes it: 1e-12, 5e-8 (no padded exponent)."""
    mantissa, exponent = f"{float(bound):.0e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def residual(x: float, bound: float = ROUNDING, unit: str = "") -> str:
    """'below 1e-12' (then ``unit``) when ``|x|`` is below ``bound``; otherwise the value to
    two significant digits, marked, so that a broken comparison shows in the output instead
    of hiding behind the phrase. NaN says so.

    Parameters
    ----------
    x : float
        The residual.
    bound : float, optional
        The resolution of the comparison (:data:`ROUNDING`, :data:`DIFFERENCES`).
    unit : str, optional
        Unit written after the phrase.

    Returns
    -------
    str
        'below <bound>', or the value marked '(NOT below <bound>)', or 'NaN (not
        computed)'.
    """
    x = float(x)
    u = f" {unit}" if unit else ""
    if math.isnan(x):
        return "NaN (not computed)"
    if abs(x) < bound:
        return f"below {bound_text(bound)}{u}"
    return f"{x:.2g}{u} (NOT below {bound_text(bound)})"


def residuals(values, bound: float = ROUNDING, unit: str = "") -> str:
    """One phrase for several residuals: '(all) below 1e-12' when every one is, else each
    value by :func:`residual`, comma-separated.

    Parameters
    ----------
    values : iterable of float
        The residuals.
    bound : float, optional
        The resolution of the comparison.
    unit : str, optional
        Unit written after the phrase.

    Returns
    -------
    str
        One phrase.
    """
    vals = [float(v) for v in values]
    if vals and all(abs(v) < bound for v in vals):
        return (f"{'all ' if len(vals) > 1 else ''}below {bound_text(bound)}"
                + (f" {unit}" if unit else ""))
    return ", ".join(residual(v, bound, unit) for v in vals)
