"""A seeded simulator of the ACFR ute driving closed routes through a field of beacons.

It produces the same :class:`~annslam_lib.data.records.Dataset` as the real loaders
(notebook "Simulated data"), plus the ground truth, so every filter of the
course can be checked against the truth before it meets the Car Park run:

- odometry at 40 Hz: the back-left *encoder* speed v_e = v_c (1 - tan(alpha) H / L)
  and the steering angle (``motion.axle_speed`` inverts the first relation);
- raw laser scans at ~4.7 Hz (dt 0.2135 s, 361 beams, 0..180 degrees from the
  vehicle's right) with beacon returns at intensity level 3;
- point detections of the beacons per scan (range, bearing, true landmark id):
  every beacon whose true range is within [min_range, max_range] and whose true
  *and* measured bearings are within the 0..pi field of view (no occlusion
  between poles: they are thin);
- GPS fixes of the laser point at 5 Hz.

Truth. The route is a curvature profile kappa(s) of the rear-axle centre
(straights and smooth turns). The controller is curvature feedforward:
alpha_k = atan(L kappa(s_k + v_k dt / 2)), held for dt (the midpoint rule makes
the driven heading exact to O(dt^3) per step, so whole laps close to mm).
The poses follow ``motion.predict_exact`` (exact arcs for constant
(v_c, alpha)); see :func:`_integrate` for how the 5000 steps are vectorised.

Odometry sample k is the control held over [t_k, t_k + dt); ``truth.poses[k]``
is the laser pose at t_k. The last sample has v = 0 (the car has stopped).

Randomness. ``SimConfig.seed`` seeds a ``numpy.random.SeedSequence`` whose
children feed one generator per noise source (:data:`STREAMS`), and every
source draws standard normals of a fixed shape, scaled afterwards. Hence the
same seed gives bitwise identical output, and changing one noise level (or
switching the raw laser off) changes no other source's draws.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.motion import axle_pose, laser_pose, predict_exact
from ..models.observation import observe
from .records import LASER_ANGLES, Dataset, Detections, Gps, Laser, Odometry, Truth
from ..models.vehicle import ACFR_UTE, Vehicle

__all__ = ["SimConfig", "Route", "simulate", "make_route", "place_beacons", "ROUTES",
           "STREAMS", "ODOMETRY_DT", "LASER_DT", "GPS_DT", "MAX_STEER", "NO_RETURN"]

#: Sample periods of the Car Park run (data/README.md): 40 Hz, ~4.7 Hz, 5 Hz.
ODOMETRY_DT = 0.025
LASER_DT = 0.2135
GPS_DT = 0.2
#: First laser scan / GPS fix after the first odometry sample (as in the Car Park run),
#: so the three streams do not tick together.
LASER_T_OFFSET = 0.079
GPS_T_OFFSET = 0.023
#: Largest steering angle a route may demand (the Car Park run reaches -0.62 .. 0.60 rad).
MAX_STEER = 0.6
#: Range the SICK reports for "no return" (records.Laser treats >= 81.0 as no return).
NO_RETURN = 81.91
#: Intensity level of a beacon (reflective tape) return.
BEACON_INTENSITY = 3
#: Available route shapes, see :func:`make_route`.
ROUTES = ("loop", "figure8", "hairpin")
#: EKF-SLAM defaults for simulated runs (``SlamConfig.for_dataset('simulated')``): the
#: simulator's own noise, the true initial pose, no GPS (a pure SLAM run whose consistency
#: can be checked against the truth); tentative landmarks (3 sightings within 2 s), so that
#: a rare 5-sigma bearing error, beyond the new-landmark threshold, leaves no duplicate.
FILTER_DEFAULTS = dict(sigma_speed=0.05, sigma_steer=math.radians(1.0), sigma_range=0.1,
                       sigma_bearing=math.radians(1.0), min_range=1.0, max_range=30.0,
                       landmark_min_observations=3, landmark_probation=2.0,
                       gps_mode="none", initial_pose="auto", initial_sigma_xy=0.0,
                       initial_sigma_phi=0.0)
#: Independent random streams, in SeedSequence.spawn order (append only: reordering
#: would change every simulated dataset).
STREAMS = ("beacons", "speed", "steering", "gps", "range", "bearing", "laser", "clutter")


@dataclass(frozen=True)
class SimConfig:
    """Parameters of :func:`simulate`; defaults mimic the Car Park run.

    Route and driving
        route: 'loop' (rounded rectangle ~42 x 22 m, 118 m lap, anticlockwise),
        'figure8' (two 270-degree loops, ~39 x 16 m, 108 m lap) or 'hairpin'
        (narrow stadium ~49 x 10 m with tight 180-degree turns, 109 m lap, clockwise).
        route_scale: multiplies all lengths (curvatures / route_scale); the route
        must keep |alpha| <= MAX_STEER. laps: whole laps driven. speed: cruise
        speed of the rear-axle centre (m/s); accel: start / stop ramps (m/s^2).
        The default run lasts ~122 s, like the Car Park run (125 s).
    Beacons
        n_beacons poles, seeded-randomly placed beacon_min_dist .. beacon_max_dist
        (m) from the path of both the rear axle and the laser, at least
        beacon_min_sep (m) apart. beacon_seed: seed of the layout alone (None:
        derived from ``seed``), so a route and a layout can be varied separately.
        pole_radius: radius of the poles for the raw laser, 0.1 m. The real poles
        are ~3 cm in radius, but mathematical rays 0.5 degrees apart (8.7 mm per
        metre of range) can pass either side of a 6 cm pole beyond ~7 m (half the
        time at 14 m), while the real tape is seen to 15.9 m because the real beam
        has a footprint. An effective 0.1 m radius is hit by at least one beam up
        to 23 m (and by chance up to max_range).
    Odometry noise (white, per 40 Hz sample) and systematic error
        sigma_speed (m/s, 0.05), sigma_steer (rad, 1 degree);
        speed_scale (-, 1: reported = speed_scale * v_e), steering_offset (rad, 0).
        (The original ACFR program's 0.7 m/s and 7 degrees are filter tuning
        values, not sensor noise.)
    Laser noise (Car Park program) and systematic error
        sigma_range 0.1 m, sigma_bearing 1 degree;
        range_meas = range_scale * r + range_bias + noise,
        bearing_meas = wrap(beta + bearing_offset + noise). The raw laser's beams see
        each pole at beta + bearing_offset too (a laser mounted turned by it), and
        range_scale and range_bias apply to its ranges.
        max_range (30 m, the Car Park extractor's limit) bounds detections and
        raw beacon returns; min_range (1 m) bounds detections.
    Clutter (detections only, not the raw laser)
        clutter_rate: spurious detections per scan on average (Poisson; 0, the default,
        has none), uniform in range over [min_range, max_range] and in bearing over the
        0..pi field of view, with landmark_id -1; each scan's detections are then ordered
        by bearing, as a laser's are (a test for data association:
        ``SlamConfig.association = 'truth'`` refuses them).
    GPS
        sigma_gps 0.05 m per axis; gps_dropouts: ((start, end), ...) seconds
        after t0 without fixes.
    Other
        seed: int; raw_laser: also produce raw scans (detections always);
        t0: time of the first odometry sample (s); vehicle: the car's geometry.
    """

    seed: int = 0
    route: str = "loop"
    route_scale: float = 1.0
    laps: int = 2
    speed: float = 2.0
    accel: float = 0.5
    n_beacons: int = 15
    beacon_seed: int | None = None
    beacon_min_dist: float = 3.0
    beacon_max_dist: float = 12.0
    beacon_min_sep: float = 3.0
    pole_radius: float = 0.1
    sigma_speed: float = 0.05
    sigma_steer: float = math.radians(1.0)
    speed_scale: float = 1.0
    steering_offset: float = 0.0
    sigma_range: float = 0.1
    sigma_bearing: float = math.radians(1.0)
    range_bias: float = 0.0
    bearing_offset: float = 0.0
    range_scale: float = 1.0
    max_range: float = 30.0
    min_range: float = 1.0
    clutter_rate: float = 0.0
    sigma_gps: float = 0.05
    gps_dropouts: tuple = ()
    raw_laser: bool = True
    t0: float = 0.0
    vehicle: Vehicle = ACFR_UTE

    def __post_init__(self) -> None:
        o = "SimConfig."
        _checks.integer(o + "seed", self.seed, lo=0)
        if self.beacon_seed is not None:
            _checks.integer(o + "beacon_seed", self.beacon_seed, lo=0)
        _checks.choice(o + "route", self.route, ROUTES)
        _checks.integer(o + "laps", self.laps, lo=1)
        _checks.integer(o + "n_beacons", self.n_beacons, lo=0)
        for name in ("route_scale", "speed", "accel", "pole_radius", "speed_scale",
                     "range_scale", "beacon_min_dist", "max_range"):
            _checks.real(o + name, getattr(self, name), lo=0.0, strict=True)
        for name in ("sigma_speed", "sigma_steer", "sigma_range", "sigma_bearing", "sigma_gps",
                     "beacon_min_sep", "min_range"):
            _checks.real(o + name, getattr(self, name), lo=0.0)
        _checks.real(o + "clutter_rate", self.clutter_rate, lo=0.0, hi=100.0)
        for name in ("steering_offset", "range_bias", "bearing_offset", "t0"):
            _checks.real(o + name, getattr(self, name))
        _checks.real(o + "beacon_max_dist", self.beacon_max_dist)
        if self.beacon_max_dist <= self.beacon_min_dist or not math.isfinite(self.beacon_max_dist):
            raise ValueError("SimConfig.beacon_max_dist must be finite and > beacon_min_dist, "
                             f"got {self.beacon_max_dist!r}")
        if self.max_range <= self.min_range:
            raise ValueError(f"SimConfig.max_range ({self.max_range}) must exceed min_range "
                             f"({self.min_range})")
        if self.max_range >= Laser.max_range:
            raise ValueError(f"SimConfig.max_range must be below the laser's no-return "
                             f"threshold {Laser.max_range} m, got {self.max_range}")
        if abs(self.steering_offset) >= 0.5:
            raise ValueError(f"SimConfig.steering_offset must be below 0.5 rad in magnitude, "
                             f"got {self.steering_offset}")
        _checks.flag(o + "raw_laser", self.raw_laser)
        _checks.instance(o + "vehicle", self.vehicle, Vehicle)
        try:
            gaps = tuple((float(a), float(b)) for a, b in self.gps_dropouts)
        except (TypeError, ValueError) as exc:
            raise ValueError("SimConfig.gps_dropouts must be ((start, end), ...) in seconds, "
                             f"got {self.gps_dropouts!r}") from exc
        for a, b in gaps:
            if not (math.isfinite(a) and math.isfinite(b) and a < b):
                raise ValueError(f"SimConfig.gps_dropouts interval ({a}, {b}) must be finite "
                                 "with start < end")
        object.__setattr__(self, "gps_dropouts", gaps)


# --------------------------------------------------------------------------- routes

@dataclass(frozen=True)
class Route:
    """A closed route of the rear-axle centre as a curvature profile kappa(s).

    Segment i has length ``lengths[i]``; straights have ``kappas[i] = 0``; a turn
    rises from 0 to its peak ``kappas[i]`` over ``ramps[i]`` metres (half cosine,
    so the steering moves smoothly), holds it, and falls back over ``ramps[i]``;
    it turns by kappas[i] * (lengths[i] - ramps[i]) radians.
    ``start`` is the rear-axle pose (x, y, phi) at s = 0.
    """

    name: str
    start: np.ndarray
    lengths: np.ndarray
    kappas: np.ndarray
    ramps: np.ndarray

    @property
    def length(self) -> float:
        """Length of one lap (m)."""
        return float(np.sum(self.lengths))

    @property
    def max_curvature(self) -> float:
        return float(np.max(np.abs(self.kappas)))

    def curvature(self, s) -> np.ndarray:
        """kappa(s) (1/m) at arc length(s) ``s``, taken modulo the lap length."""
        s = np.mod(np.asarray(s, dtype=float), self.length)
        starts = np.concatenate([[0.0], np.cumsum(self.lengths)[:-1]])
        i = np.clip(np.searchsorted(starts, s, side="right") - 1, 0, starts.size - 1)
        u, ell, r = s - starts[i], self.lengths[i], self.ramps[i]
        r_safe = np.where(r > 0, r, 1.0)
        w = np.ones_like(s)
        up, down = u < r, u > ell - r
        w = np.where(up, 0.5 * (1 - np.cos(np.pi * u / r_safe)), w)
        w = np.where(down, 0.5 * (1 - np.cos(np.pi * (ell - u) / r_safe)), w)
        return self.kappas[i] * w

    def path(self, step: float = 0.05) -> np.ndarray:
        """Rear-axle poses (P, 3) every ~``step`` metres over one lap, s = 0 .. length
        (midpoint rule: second order, for placing beacons and plotting)."""
        return _trace(self.start, self.curvature, self.length, step)

    def scaled(self, factor: float) -> Route:
        return Route(self.name, self.start * np.array([factor, factor, 1.0]),
                     self.lengths * factor, self.kappas / factor, self.ramps * factor)


def _trace(start, curvature, length: float, step: float) -> np.ndarray:
    n = max(int(math.ceil(length / step)), 1)
    h = length / n
    k = curvature((np.arange(n) + 0.5) * h)
    phi = start[2] + np.concatenate([[0.0], np.cumsum(k * h)])
    mid = phi[:-1] + 0.5 * k * h
    x = start[0] + np.concatenate([[0.0], np.cumsum(h * np.cos(mid))])
    y = start[1] + np.concatenate([[0.0], np.cumsum(h * np.sin(mid))])
    return np.column_stack([x, y, phi])


def _turn(angle: float, radius: float, ramp: float = 4.0) -> tuple[float, float, float]:
    """(length, peak curvature, ramp) of a smooth turn by ``angle`` (signed, rad)."""
    kappa = math.copysign(1.0 / radius, angle)
    return abs(angle) * radius + ramp, kappa, ramp


def _straight(length: float) -> tuple[float, float, float]:
    return length, 0.0, 0.0


def make_route(name: str, scale: float = 1.0) -> Route:
    """The route ``name`` (see :data:`ROUTES` and :class:`SimConfig`), centred on the
    origin, starting on a straight (heading East; the figure-8 at its crossing,
    heading South-East, with its loops to the East and West). Each closes by symmetry: the
    rectangle's four identical corners rotate by pi/2 each, the figure-8's loops
    are mirror images joined by straights through the crossing, the hairpin is
    symmetric under a half turn."""
    heading = 0.0
    if name == "loop":        # rounded rectangle, anticlockwise, start mid-way along a long side
        corner = _turn(math.pi / 2, 6.0)
        segs = [_straight(13.0), corner, _straight(6.0), corner, _straight(26.0), corner,
                _straight(6.0), corner, _straight(13.0)]
    elif name == "figure8":   # start at the crossing heading South-East; loops East and West
        heading = -math.pi / 4
        left, right = _turn(1.5 * math.pi, 8.0), _turn(-1.5 * math.pi, 8.0)
        # Straight arm length that makes the loops meet at the crossing. In the frame
        # of the crossing's bisector the left loop (entered at +45 degrees, left at
        # -45 degrees) moves the car by dx along the bisector, the mirrored right
        # loop too, and the straights by 2 sqrt(2) arm: closure needs dx + sqrt(2) arm = 0.
        one = Route("", np.array([0.0, 0.0, math.pi / 4]), *map(np.array, zip(left)))
        dx = one.path(0.002)[-1, 0]
        arm = -dx / math.sqrt(2.0)
        segs = [_straight(arm), left, _straight(2 * arm), right, _straight(arm)]
    elif name == "hairpin":   # narrow stadium, clockwise, tight ends
        end = _turn(-math.pi, 5.0)
        segs = [_straight(17.5), end, _straight(35.0), end, _straight(17.5)]
    else:
        raise ValueError(f"unknown route {name!r}; choose one of {ROUTES}")
    lengths, kappas, ramps = (np.array(v, dtype=float) for v in zip(*segs))
    route = Route(name, np.array([0.0, 0.0, heading]), lengths, kappas, ramps)
    xy = route.path()[:, :2]
    centre = 0.5 * (xy.min(0) + xy.max(0))
    route = Route(name, np.array([-centre[0], -centre[1], heading]), lengths, kappas, ramps)
    return route.scaled(scale) if scale != 1.0 else route


# --------------------------------------------------------------------------- beacons

def place_beacons(route: Route, n: int, rng: np.random.Generator, *, min_dist: float = 3.0,
                  max_dist: float = 12.0, min_sep: float = 3.0,
                  vehicle: Vehicle = ACFR_UTE) -> np.ndarray:
    """``n`` beacons (n, 2) at random spots min_dist .. max_dist metres beside the route.

    Candidates are drawn at a uniform arc length, side and offset along the
    normal of the rear-axle path; a candidate is kept if it is at least
    ``min_dist`` from the whole path of the rear axle *and* of the laser (which
    swings ~1 m wide in turns) and ``min_sep`` from the beacons kept so far.
    Raises ValueError if the route has no room for them.
    """
    axle = route.path(0.25)
    laser, _ = laser_pose(axle, vehicle)
    track = np.concatenate([axle[:, :2], laser[:, :2]])
    s_grid = np.linspace(0.0, route.length, axle.shape[0])
    kept = np.empty((n, 2))
    count, batch = 0, 64
    for _ in range(20 + 2 * n):                   # > 128 candidates per beacon, then give up
        if count == n:
            break
        s = rng.uniform(0.0, route.length, batch)
        side = np.where(rng.random(batch) < 0.5, -1.0, 1.0)
        d = rng.uniform(min_dist, max_dist, batch)
        x, y = np.interp(s, s_grid, axle[:, 0]), np.interp(s, s_grid, axle[:, 1])
        phi = np.interp(s, s_grid, axle[:, 2])
        cand = np.column_stack([x - side * d * np.sin(phi), y + side * d * np.cos(phi)])
        clear = np.min(np.linalg.norm(cand[:, None, :] - track[None], axis=-1), axis=1)
        for p in cand[clear >= min_dist]:
            if count == 0 or np.min(np.hypot(*(kept[:count] - p).T)) >= min_sep:
                kept[count] = p
                count += 1
                if count == n:
                    break
    if count < n:
        raise ValueError(f"could not place n_beacons = {n} beacons {min_dist}..{max_dist} m "
                         f"from route {route.name!r} at least {min_sep} m apart (placed "
                         f"{count}); lower n_beacons or beacon_min_sep")
    return kept


# --------------------------------------------------------------------------- truth

def _speed_profile(distance: float, speed: float, accel: float, dt: float) -> np.ndarray:
    """Rear-axle speeds of the motion steps: ramp up at ``accel``, cruise, brake at
    ``accel`` so that the speeds sum to exactly ``distance`` / dt."""
    out, s, v = [], 0.0, 0.0
    while True:
        rem = distance - s
        v = min(speed, v + accel * dt, math.sqrt(2.0 * accel * rem))
        if v * dt >= rem:
            out.append(rem / dt)
            return np.array(out)
        out.append(v)
        s += v * dt


def _integrate(start_axle: np.ndarray, controls: np.ndarray, dt: float,
               vehicle: Vehicle) -> np.ndarray:
    """Laser poses (N+1, 3) after each of the N ``controls`` held for ``dt``.

    Same result as N chained calls of ``motion.predict_exact`` (to rounding),
    but vectorised: the exact step is equivariant under rigid motions, so each
    step's displacement in the rear-axle frame is computed once by
    ``predict_exact`` from the axle at the origin, and the steps are then
    composed with cumulative sums (heading first, then the rotated displacements).
    """
    origin, _ = laser_pose(np.zeros(3), vehicle)
    moved = predict_exact(origin, controls, dt, vehicle)
    step, _ = axle_pose(moved, vehicle)                     # (dx, dy, dphi) in the axle frame
    phi = start_axle[2] + np.concatenate([[0.0], np.cumsum(step[:, 2])])
    c, s = np.cos(phi[:-1]), np.sin(phi[:-1])
    x = start_axle[0] + np.concatenate([[0.0], np.cumsum(c * step[:, 0] - s * step[:, 1])])
    y = start_axle[1] + np.concatenate([[0.0], np.cumsum(s * step[:, 0] + c * step[:, 1])])
    poses, _ = laser_pose(np.column_stack([x, y, phi]), vehicle)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses


def _poses_at(t: np.ndarray, odo_t: np.ndarray, poses: np.ndarray, controls: np.ndarray,
              vehicle: Vehicle) -> np.ndarray:
    """True laser poses at times ``t``: the exact arc from the last odometry sample."""
    k = np.clip(np.searchsorted(odo_t, t, side="right") - 1, 0, odo_t.size - 1)
    return predict_exact(poses[k], controls[k], t - odo_t[k], vehicle)


# --------------------------------------------------------------------------- sensors

def _detections(t, z, noise_r, noise_b, cfg: SimConfig) -> Detections:
    r, beta = z[..., 0], z[..., 1]
    r_meas = cfg.range_scale * r + cfg.range_bias + cfg.sigma_range * noise_r
    b_meas = beta + cfg.bearing_offset + cfg.sigma_bearing * noise_b
    # Wrap only what left (-pi, pi]: wrapping is not bitwise idempotent, and without
    # noise the detections must equal observe() exactly.
    out = (b_meas > np.pi) | (b_meas <= -np.pi)
    b_meas = np.where(out, wrap_angle(b_meas), b_meas)
    # In range and in the 0..pi field of view, both truly and as measured.
    seen = ((r >= cfg.min_range) & (r <= cfg.max_range) & (beta >= 0) & (beta <= np.pi)
            & (b_meas >= 0) & (b_meas <= np.pi) & (r_meas > 0))
    offsets = np.concatenate([[0], np.cumsum(seen.sum(axis=1))]).astype(np.int64)
    ids = np.broadcast_to(np.arange(z.shape[1]), seen.shape)[seen]
    return Detections(t=t, offsets=offsets, range=r_meas[seen], bearing=b_meas[seen],
                      diameter=np.full(int(offsets[-1]), np.nan), landmark_id=ids)


def _raw_laser(t, z, noise, cfg: SimConfig) -> Laser:
    """Ray-cast the 361 beams against the poles (circles of radius pole_radius).

    A pole at range r, bearing beta lies at angle d = beta - gamma off beam gamma:
    the beam meets it at r cos d - sqrt(rho^2 - r^2 sin^2 d) when r |sin d| <= rho.
    Only beams within asin(rho / r) (+1 beam for rounding) of a pole's bearing can
    meet it, so the (scan, beam, pole) triples are enumerated sparsely (a few
    per pole) and the nearest hit per beam kept with ``np.minimum.at``.
    """
    n_scans, n_beams = t.size, LASER_ANGLES.size
    step = LASER_ANGLES[1] - LASER_ANGLES[0]
    rho = cfg.pole_radius
    r, beta = z[..., 0].ravel(), z[..., 1].ravel() + cfg.bearing_offset   # a turned laser
    beta = np.where(beta < -np.pi / 2, beta + 2 * np.pi, beta)   # beams span 0..pi
    half = np.arcsin(np.minimum(rho / r, 1.0))
    lo = np.maximum(np.ceil((beta - half) / step) - 1, 0).astype(np.int64)
    hi = np.minimum(np.floor((beta + half) / step) + 1, n_beams - 1).astype(np.int64)
    count = np.where(r - rho <= cfg.max_range, np.maximum(hi - lo + 1, 0), 0)
    pair = np.repeat(np.arange(r.size), count)
    first = np.repeat(np.cumsum(count) - count, count)
    beam = lo[pair] + np.arange(pair.size) - first
    d = beta[pair] - LASER_ANGLES[beam]
    across, along = r[pair] * np.sin(d), r[pair] * np.cos(d)
    disc = rho * rho - across * across
    surface = along - np.sqrt(np.maximum(disc, 0.0))
    ok = (disc >= 0) & (surface > 0) & (surface <= cfg.max_range)
    scan = pair // max(z.shape[1], 1)
    nearest = np.full(n_scans * n_beams, np.inf)
    np.minimum.at(nearest, scan[ok] * n_beams + beam[ok], surface[ok])
    nearest = nearest.reshape(n_scans, n_beams)
    hit = np.isfinite(nearest)
    meas = cfg.range_scale * np.where(hit, nearest, 0.0) + cfg.range_bias + cfg.sigma_range * noise
    ranges = np.where(hit, np.maximum(meas, 0.0), NO_RETURN)
    intensity = np.where(hit, BEACON_INTENSITY, 0).astype(np.uint8)
    return Laser(t=t, ranges=ranges, intensity=intensity)


def _streams(seed: int) -> dict[str, np.random.Generator]:
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    return {name: np.random.default_rng(c) for name, c in zip(STREAMS, children)}


def _with_clutter(det: Detections, rng: np.random.Generator, cfg: SimConfig) -> Detections:
    """``det`` with Poisson(clutter_rate) spurious detections added to each scan, every scan
    then in bearing order, as a laser gives them, so that nothing tells clutter by its place
    (ties: the true detections first)."""
    n = det.t.size
    k = rng.poisson(cfg.clutter_rate, n)
    total = int(k.sum())
    r = rng.uniform(cfg.min_range, cfg.max_range, total)
    b = rng.uniform(0.0, np.pi, total)
    scan = np.concatenate([np.repeat(np.arange(n), np.diff(det.offsets)), np.repeat(np.arange(n), k)])
    bearing = np.concatenate([det.bearing, b])
    order = np.lexsort((bearing, scan))                # stable: scan, then bearing
    offsets = np.concatenate([[0], np.cumsum(np.bincount(scan, minlength=n))]).astype(np.int64)
    return Detections(t=det.t, offsets=offsets, range=np.concatenate([det.range, r])[order],
                      bearing=bearing[order],
                      diameter=np.concatenate([det.diameter, np.full(total, np.nan)])[order],
                      landmark_id=np.concatenate([det.landmark_id, np.full(total, -1)])[order])


# --------------------------------------------------------------------------- simulate

def simulate(config: SimConfig | None = None, *, beacons=None, **overrides) -> Dataset:
    """Simulate a run: ``Dataset`` named 'simulated' with odometry, GPS, detections,
    raw laser (unless ``raw_laser=False``), the true beacons and ``truth``.

    ``config`` defaults to ``SimConfig()``; keyword ``overrides`` replace its
    fields (``simulate(seed=3, route='figure8')``). ``beacons`` (M, 2) replaces
    the random layout. ``info`` holds the config, the route, its lap length and
    path, the true controls (v_c, alpha) per odometry sample, and the true laser
    poses at the scan times ('scan_poses') and GPS positions ('gps_truth').
    Deterministic: the same arguments give bitwise identical arrays.
    """
    cfg = SimConfig() if config is None else config
    if not isinstance(cfg, SimConfig):
        raise TypeError(f"config must be a SimConfig, got {type(cfg).__name__}")
    if overrides:
        unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(SimConfig)})
        if unknown:
            raise ValueError(f"unknown SimConfig field(s): {', '.join(unknown)}")
        cfg = dataclasses.replace(cfg, **overrides)
    veh, dt = cfg.vehicle, ODOMETRY_DT

    route = make_route(cfg.route, cfg.route_scale)
    max_alpha = math.atan(veh.L * route.max_curvature)
    if max_alpha > MAX_STEER:
        raise ValueError(f"route {cfg.route!r} at route_scale {cfg.route_scale} needs steering "
                         f"{max_alpha:.3f} rad > MAX_STEER = {MAX_STEER}; raise route_scale")

    streams = _streams(cfg.seed)
    if beacons is None:
        layout_rng = streams["beacons"] if cfg.beacon_seed is None else _streams(cfg.beacon_seed)["beacons"]
        beacons = place_beacons(route, cfg.n_beacons, layout_rng, min_dist=cfg.beacon_min_dist,
                                max_dist=cfg.beacon_max_dist, min_sep=cfg.beacon_min_sep,
                                vehicle=veh)
    else:
        beacons = np.array(beacons, dtype=float)
        if beacons.ndim != 2 or beacons.shape[1] != 2 or not np.all(np.isfinite(beacons)):
            raise ValueError(f"beacons must be a finite (M, 2) array, got shape {beacons.shape}")

    # Controls: curvature feedforward at the middle of each step, then a final stop sample.
    v = _speed_profile(cfg.laps * route.length, cfg.speed, cfg.accel, dt)
    s_start = np.concatenate([[0.0], np.cumsum(v * dt)[:-1]])
    alpha = np.arctan(veh.L * route.curvature(s_start + 0.5 * v * dt))
    controls = np.column_stack([np.append(v, 0.0), np.append(alpha, 0.0)])
    poses = _integrate(route.start, controls[:-1], dt, veh)
    n_odo = controls.shape[0]
    odo_t = cfg.t0 + np.arange(n_odo) * dt
    t_end = odo_t[-1]

    # Odometry: the encoder speed of the true motion, plus noise and systematic error.
    v_enc = controls[:, 0] * (1.0 - np.tan(controls[:, 1]) * veh.H / veh.L)
    odometry = Odometry(
        t=odo_t,
        speed=cfg.speed_scale * v_enc + cfg.sigma_speed * streams["speed"].standard_normal(n_odo),
        steering=controls[:, 1] + cfg.steering_offset
        + cfg.sigma_steer * streams["steering"].standard_normal(n_odo))

    # GPS of the laser point; dropouts remove fixes after the noise is drawn.
    gps_t = cfg.t0 + GPS_T_OFFSET + np.arange(int((t_end - cfg.t0 - GPS_T_OFFSET) // GPS_DT) + 1) * GPS_DT
    gps_truth = _poses_at(gps_t, odo_t, poses, controls, veh)[:, :2]
    gps_xy = gps_truth + cfg.sigma_gps * streams["gps"].standard_normal(gps_truth.shape)
    keep = np.ones(gps_t.size, dtype=bool)
    for a, b in cfg.gps_dropouts:
        keep &= ~((gps_t - cfg.t0 >= a) & (gps_t - cfg.t0 < b))
    gps = Gps(t=gps_t[keep], east=gps_xy[keep, 0], north=gps_xy[keep, 1])

    # Laser: true range/bearing of every beacon from every scan pose.
    scan_t = cfg.t0 + LASER_T_OFFSET + np.arange(int((t_end - cfg.t0 - LASER_T_OFFSET) // LASER_DT) + 1) * LASER_DT
    scan_poses = _poses_at(scan_t, odo_t, poses, controls, veh)
    n_scans, m = scan_t.size, beacons.shape[0]
    if m:
        z, _, _ = observe(scan_poses[:, None, :], beacons[None, :, :])
    else:
        z = np.zeros((n_scans, 0, 2))
    detections = _detections(scan_t, z, streams["range"].standard_normal((n_scans, m)),
                             streams["bearing"].standard_normal((n_scans, m)), cfg)
    if cfg.clutter_rate > 0:
        detections = _with_clutter(detections, streams["clutter"], cfg)
    laser = None
    if cfg.raw_laser:
        laser = _raw_laser(scan_t, z, streams["laser"].standard_normal((n_scans, LASER_ANGLES.size)), cfg)

    truth = Truth(poses=np.column_stack([odo_t, poses]), landmarks=beacons.copy())
    info = {"config": cfg, "route": route, "lap_length": route.length,
            "route_path": route.path()[:, :2], "controls": controls,
            "scan_poses": scan_poses, "gps_truth": gps_truth}
    return Dataset(name="simulated", odometry=odometry, gps=gps, vehicle=veh, laser=laser,
                   detections=detections, beacons=beacons.copy(), truth=truth,
                   landmark_kind="beacons", info=info)
