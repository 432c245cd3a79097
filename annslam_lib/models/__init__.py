"""Models layer: the car, its motion and its sensor, each value with its Jacobians.

- ``geometry``: angle wrapping, rotations, frames (Solà's toFrame / fromFrame), pose
  interpolation, finite-difference Jacobians
- ``vehicle``: the car's geometry (wheelbase, encoder and laser offsets)
- ``motion``: encoder to axle speed, laser offset, the process model with F and G, the exact
  arc (chapters 01-02)
- ``observation``: range and bearing with their Jacobians, the inverse model, the
  two-point landmark frame (chapter 03)
- ``uncertainty``: covariance propagation, ellipses, Monte Carlo, chi-square quantiles

Changing the sensor model: ``observation`` (its fast copies are listed in its docstring).
"""

__all__ = ["geometry", "vehicle", "motion", "observation", "uncertainty"]
