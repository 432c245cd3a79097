"""Vehicle constants of the ACFR utility car ("ute") used by both real runs.

The state every filter in the course estimates is the pose of the *laser*
(x, y, phi): position of the laser in the world frame and heading of the car.
The laser sits ``a`` metres ahead of the rear-axle centre and ``b`` metres to
its left; the speed encoder is on the back-left wheel, ``H`` metres left of
the rear-axle centre; ``L`` is the wheelbase (the course's data notes, data/README.md).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Vehicle:
    """Geometry of the car, in metres.

    Parameters
    ----------
    L : float, optional
        Wheelbase (rear axle to front axle), m, > 0.
    H : float, optional
        Lateral distance from the rear-axle centre to the encoder wheel (left), m.
    a : float, optional
        Longitudinal distance from the rear-axle centre to the laser (forward), m.
    b : float, optional
        Lateral distance from the rear-axle centre to the laser (left positive), m.

    Raises
    ------
    TypeError
        If a value is not a finite number.
    ValueError
        If the wheelbase ``L`` is not positive.
    """

    L: float = 2.83
    H: float = 0.76
    a: float = 3.78
    b: float = 0.50

    def __post_init__(self) -> None:
        for name in ("L", "H", "a", "b"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or value != value or abs(value) == float("inf"):
                raise TypeError(f"Vehicle.{name} must be a finite number, got {value!r}")
        if self.L <= 0:
            raise ValueError(f"Vehicle.L (wheelbase) must be positive, got {self.L}")


#: The ute of both ACFR runs (data/README.md: a = 3.78 m ahead of the rear axle,
#: b = 1.21 - 1.42/2 = 0.5 m to the side).
ACFR_UTE = Vehicle(L=2.83, H=0.76, a=3.78, b=0.50)
