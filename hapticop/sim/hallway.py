"""The simulated dead-end hallway: walls as segments, a vectorised LIDAR ray-cast, footprint clearance.

Why: the hallway experiment (docs/hallway-experiment.md §2) needs one deterministic world that the simulated
TiM561, the force models and the metrics all agree on. Robot motion is not modelled here: callers pass the
pose that the ropod plant produced.

Frames. World: x along the hallway towards the end wall, y to the left, theta counter-clockwise from +x
(ROS REP 103). Robot: x forward, y left, origin at the footprint's centre; its footprint and LIDAR mount are
the robot's body (hapticop.devices.ropod.body). LIDAR: mounted at (x, y, yaw) in the robot frame; beam
angles are in its sensor frame (x forward, y left, counter-clockwise; docs/devices/sick-tim561.md §5),
so a TiM561 covers -135 deg ... +134.973 deg in 811 steps of 0.3333 deg and index 405 looks about straight ahead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.body import Body, Footprint, SensorMount

F64 = NDArray[np.float64]

SegmentKind = Literal["side", "end", "pillar", "other"]


@dataclass(frozen=True)
class Pillar:
    """A rectangular obstacle standing against a side wall (H4), centred at x_m along the hallway."""

    x_m: float
    along_m: float
    depth_m: float
    side: Literal["left", "right"] = "right"


@dataclass(frozen=True)
class LidarModel:
    """The TiM561 as §2 and docs/devices/sick-tim561.md §5 describe it: where it sits, its beams, range
    limits and noise."""

    mount: SensorMount = Body().lidar  # x, y [m], yaw [rad] in the robot frame
    beams: int = 811
    start_deg: float = -135.0  # SICK -45 deg minus 90 deg into the sensor frame
    step_deg: float = 0.3333  # transmitted as 3333/10000 deg, not 1/3 deg
    min_range_m: float = 0.05
    max_range_m: float = 10.0
    rate_hz: float = 15.0
    noise_sigma_m: float = 0.01
    dropout: float = 0.0  # probability a beam returns nothing
    spurious: float = 0.0  # probability a beam returns a phantom range
    spurious_range_m: tuple[float, float] = (0.3, 1.0)

    def angles(self) -> F64:
        """Beam angles in the sensor frame [rad], start + i * step as the scanner transmits them."""
        return np.radians(self.start_deg + self.step_deg * np.arange(self.beams))


def _deg(theta: float) -> float:
    return math.radians(theta)


@dataclass(frozen=True)
class HallwayGeometry:
    """One dead-end hallway of §2 and the task constants that go with it.

    The hallway runs along +x from its open entrance at `entrance_x_m` to the end wall at `length_m`; its side
    walls are at y = +-width/2 (left is +y). Task distances, all measured from the robot's footprint:
    dist1 = comfortable side clearance to keep from each side wall (side keeping, §5 #3);
    dist2 = front-of-footprint to end-wall distance at which the robot should stop (stop error, §5 #2);
    dist3 = virtual bumper: clearance below it counts as a collision (with hysteresis, §2 / §5 #1).
    """

    name: str = "H1"
    width_m: float = 2.0
    length_m: float = 10.0
    entrance_x_m: float = 0.0
    start: tuple[float, float, float] = (0.5, 0.0, 0.0)  # x, y [m], theta [rad]
    dist1_m: float = 0.40
    dist2_m: float = 0.50
    dist3_m: float = 0.10
    collision_hysteresis_m: float = 0.02
    pillars: tuple[Pillar, ...] = ()
    footprint: Footprint = field(default_factory=Footprint)
    lidar: LidarModel = field(default_factory=LidarModel)
    t_max_s: float = 90.0
    still_speed_mps: float = 0.02
    still_time_s: float = 1.0

    @classmethod
    def named(cls, name: str) -> HallwayGeometry:
        """H1 ... H6 of §2's table (H5 is H2 with the noisy sensor; H6 is optional in docs/hallway-experiment.md)."""
        wide = dict(width_m=2.0, length_m=10.0, dist1_m=0.40)
        table: dict[str, dict] = {
            "H1": dict(wide, start=(0.5, 0.0, 0.0)),
            "H2": dict(wide, start=(0.5, 0.30, _deg(8.0))),
            "H3": dict(width_m=1.5, length_m=8.0, dist1_m=0.30, start=(0.5, 0.0, _deg(-4.0))),
            "H4": dict(wide, start=(0.5, 0.0, 0.0), pillars=(Pillar(5.0, along_m=0.40, depth_m=0.25),)),
            "H5": dict(wide, start=(0.5, 0.30, _deg(8.0)),
                       lidar=LidarModel(noise_sigma_m=0.03, dropout=0.02, spurious=0.01)),
            "H6": dict(wide, length_m=20.0, start=(0.5, 0.0, 0.0)),
        }
        try:
            return cls(name=name, **table[name.upper()])
        except KeyError:
            raise ValueError(f"unknown hallway {name!r}; expected one of {', '.join(table)}") from None

    @property
    def stop_line_x_m(self) -> float:
        """Where the front of the footprint should be at the stop."""
        return self.length_m - self.dist2_m

    def segments(self) -> tuple[F64, tuple[SegmentKind, ...]]:
        """Wall segments (m, 2, 2) as [[x0, y0], [x1, y1]] and what each one is; nothing behind the entrance."""
        x0, x1, h = self.entrance_x_m, self.length_m, 0.5 * self.width_m
        segs: list[list[list[float]]] = [[[x0, h], [x1, h]], [[x0, -h], [x1, -h]], [[x1, -h], [x1, h]]]
        kinds: list[SegmentKind] = ["side", "side", "end"]
        for p in self.pillars:
            wall = h if p.side == "left" else -h
            face = wall - math.copysign(p.depth_m, wall)
            a, b = p.x_m - 0.5 * p.along_m, p.x_m + 0.5 * p.along_m
            segs += [[[a, wall], [a, face]], [[a, face], [b, face]], [[b, face], [b, wall]]]
            kinds += ["pillar"] * 3
        return np.array(segs, dtype=np.float64), tuple(kinds)


class _RayScratch:
    """Work arrays for one beam count, made once so a scan allocates nothing."""

    def __init__(self, n: int, m: int):
        self.phi = np.empty(n)
        self.dx = np.empty(n)
        self.dy = np.empty(n)
        self.denom = np.empty((n, m))
        self.snum = np.empty((n, m))
        self.t = np.empty((n, m))
        self.tmp = np.empty((n, m))
        self.valid = np.empty((n, m), dtype=bool)
        self.vtmp = np.empty((n, m), dtype=bool)
        self.r = np.empty(n)
        self.bad = np.empty(n, dtype=bool)
        self.btmp = np.empty(n, dtype=bool)


class World:
    """Walls as line segments; ray-casts a whole scan at once and measures footprint clearance.

    Walls are thin: a footprint that overlaps a wall has clearance 0. Segments carry a kind ("side", "end",
    "pillar") so that metrics can ask for the front (end wall) and side (everything else) clearances separately.
    """

    def __init__(self, segments: ArrayLike, kinds: Sequence[SegmentKind] | None = None):
        self.segments = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2))
        m = self.segments.shape[0]
        self.kinds: tuple[SegmentKind, ...] = tuple(kinds) if kinds is not None else ("other",) * m
        if len(self.kinds) != m:
            raise ValueError(f"{m} segments but {len(self.kinds)} kinds")
        self._ax = self.segments[:, 0, 0].copy()
        self._ay = self.segments[:, 0, 1].copy()
        self._ex = self.segments[:, 1, 0] - self._ax
        self._ey = self.segments[:, 1, 1] - self._ay
        self._walls = tuple(
            (float(ax), float(ay), float(bx), float(by), min(ax, bx), max(ax, bx), min(ay, by), max(ay, by))
            for (ax, ay), (bx, by) in self.segments.tolist()
        )
        self._wx = np.empty(m)
        self._wy = np.empty(m)
        self._tnum = np.empty((1, m))
        self._mtmp = np.empty(m)
        self._scratch: dict[int, _RayScratch] = {}

    @classmethod
    def from_geometry(cls, geometry: HallwayGeometry) -> World:
        segs, kinds = geometry.segments()
        return cls(segs, kinds)

    def scratch_for(self, n: int) -> _RayScratch:
        """Make the work arrays for n beams now (else the first scan of that size makes them)."""
        s = self._scratch.get(n)
        if s is None:
            s = self._scratch[n] = _RayScratch(n, self.segments.shape[0])
        return s

    def raycast(
        self,
        pose: ArrayLike,
        mount: Sequence[float],
        angles: NDArray[np.floating],
        out_ranges: NDArray[np.floating],
        max_range: float = 10.0,
        min_range: float = 0.05,
    ) -> NDArray[np.floating]:
        """Range along every beam to the nearest wall, NaN where nothing lies within [min_range, max_range].

        Solves origin + t*d = a + s*e for all beams and segments at once with 2-D cross products:
        t = (w x e) / (d x e), s = (w x d) / (d x e), w = a - origin; a hit needs t > 0 and 0 <= s <= 1.
        """
        n = angles.shape[0]
        s = self.scratch_for(n)
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])  # type: ignore[index]
        c, sn = math.cos(th), math.sin(th)
        mx, my, myaw = float(mount[0]), float(mount[1]), float(mount[2])
        ox, oy = x + c * mx - sn * my, y + sn * mx + c * my

        np.add(angles, th + myaw, out=s.phi)
        np.cos(s.phi, out=s.dx)
        np.sin(s.phi, out=s.dy)
        np.subtract(self._ax, ox, out=self._wx)
        np.subtract(self._ay, oy, out=self._wy)
        # w x e per segment
        np.multiply(self._wx, self._ey, out=self._tnum[0])
        np.multiply(self._wy, self._ex, out=self._mtmp)
        np.subtract(self._tnum[0], self._mtmp, out=self._tnum[0])
        # d x e and w x d per beam and segment
        np.multiply.outer(s.dx, self._ey, out=s.denom)
        np.multiply.outer(s.dy, self._ex, out=s.tmp)
        np.subtract(s.denom, s.tmp, out=s.denom)
        np.multiply.outer(s.dy, self._wx, out=s.snum)
        np.multiply.outer(s.dx, self._wy, out=s.tmp)
        np.subtract(s.snum, s.tmp, out=s.snum)
        # Hit tests without dividing: with D = d x e, t > 0 <=> tnum*D > 0 and 0 <= s <= 1 <=> 0 <= snum*D <= D^2.
        np.multiply(self._tnum, s.denom, out=s.tmp)
        np.greater(s.tmp, 0.0, out=s.valid)
        np.multiply(s.snum, s.denom, out=s.tmp)
        np.greater_equal(s.tmp, 0.0, out=s.vtmp)
        np.logical_and(s.valid, s.vtmp, out=s.valid)
        np.multiply(s.denom, s.denom, out=s.t)
        np.less_equal(s.tmp, s.t, out=s.vtmp)
        np.logical_and(s.valid, s.vtmp, out=s.valid)
        s.t.fill(np.inf)
        np.divide(self._tnum, s.denom, out=s.t, where=s.valid)
        np.min(s.t, axis=1, out=s.r)
        np.greater(s.r, max_range, out=s.bad)
        np.less(s.r, min_range, out=s.btmp)
        np.logical_or(s.bad, s.btmp, out=s.bad)
        np.copyto(s.r, np.nan, where=s.bad)
        np.copyto(out_ranges, s.r, casting="same_kind")
        return out_ranges

    def clearance(self, pose: ArrayLike, footprint: Footprint, margin: float = 0.0) -> tuple[float, bool]:
        """Smallest distance from the footprint to any wall, and whether it is <= margin (0: touching a wall).

        The judge asks every cycle, so this is scalar maths on the walls' precomputed end points; it agrees
        with `clearances` (the vectorised form for whole trajectories) to rounding.
        Counting virtual-bumper collisions (dist3, with hysteresis) is the metrics' job, not this one's.
        """
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])  # type: ignore[index]
        d = _footprint_clearance(x, y, math.cos(th), math.sin(th),
                                 0.5 * footprint.length_m, 0.5 * footprint.width_m, self._walls)
        return d, d <= margin

    def clearances(
        self,
        poses: ArrayLike,
        footprint: Footprint,
        kinds: Sequence[SegmentKind] | None = None,
        out: F64 | None = None,
        chunk: int = 4096,
    ) -> F64:
        """Footprint-to-wall distance for every pose (T, 3), optionally only to segments of the given kinds.

        The distance between the rectangle and a segment is 0 where an edge crosses it or an end point lies
        inside, else the smallest of the corner-to-segment and end-point-to-edge distances.
        """
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        segs = self.segments if kinds is None else self.segments[[k in kinds for k in self.kinds]]
        res = np.empty(p.shape[0]) if out is None else out
        if segs.shape[0] == 0:
            res.fill(np.inf)
            return res
        for i in range(0, p.shape[0], chunk):
            res[i : i + chunk] = _footprint_distance(p[i : i + chunk], footprint, segs)
        return res


def _footprint_distance(poses: F64, footprint: Footprint, segs: F64) -> F64:
    """Rectangle-to-segment distances (T,) in the robot frame, where the footprint is the box |x|<=hl, |y|<=hw.

    Two disjoint convex shapes are closest at a vertex of one of them, so the distance is the smallest of the
    segment end points' distances to the box and the box corners' distances to the segment, or 0 where they
    overlap (separating-axis test on x, y and the segment's normal).
    """
    hl, hw = 0.5 * footprint.length_m, 0.5 * footprint.width_m
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])  # (T, 1)
    rel = segs[None, :, :, :] - poses[:, None, None, :2]  # (T, m, 2 ends, 2)
    lx = c[:, :, None] * rel[..., 0] + s[:, :, None] * rel[..., 1]
    ly = -s[:, :, None] * rel[..., 0] + c[:, :, None] * rel[..., 1]  # (T, m, 2)
    ends = np.hypot(np.maximum(np.abs(lx) - hl, 0.0), np.maximum(np.abs(ly) - hw, 0.0)).min(axis=2)
    ax, ay = lx[..., 0:1], ly[..., 0:1]  # (T, m, 1)
    ex, ey = lx[..., 1:2] - ax, ly[..., 1:2] - ay
    kx, ky = np.array([hl, -hl, -hl, hl]), np.array([hw, hw, -hw, -hw])
    ll = ex * ex + ey * ey
    u = np.clip(((kx - ax) * ex + (ky - ay) * ey) / np.where(ll > 0, ll, 1.0), 0.0, 1.0)
    corners = np.hypot(kx - (ax + u * ex), ky - (ay + u * ey)).min(axis=2)
    overlap = (
        (lx.min(axis=2) <= hl) & (lx.max(axis=2) >= -hl) & (ly.min(axis=2) <= hw) & (ly.max(axis=2) >= -hw)
        & (np.abs(ex * ay - ey * ax)[..., 0] <= (hl * np.abs(ey) + hw * np.abs(ex))[..., 0])
    )
    return np.where(overlap, 0.0, np.minimum(ends, corners)).min(axis=1)


def _footprint_clearance(
    x: float, y: float, c: float, s: float, hl: float, hw: float,
    walls: tuple[tuple[float, float, float, float, float, float, float, float], ...],
) -> float:
    """`_footprint_distance` for one pose (centre x, y; heading cos c, sin s) in scalar maths.

    Each wall is (ax, ay, bx, by, x_min, x_max, y_min, y_max). A wall whose bounding box is farther from
    the centre than the footprint reaches cannot be the nearest one and is skipped; an overlap is 0 at once.
    Distances are compared squared, with one square root at the end.
    """
    reach = math.sqrt(hl * hl + hw * hw)  # the footprint lies inside this circle about its centre
    best = math.inf  # squared distance
    for ax, ay, bx, by, x0, x1, y0, y1 in walls:
        gx = x0 - x if x < x0 else (x - x1 if x > x1 else 0.0)
        gy = y0 - y if y < y0 else (y - y1 if y > y1 else 0.0)
        bound = math.sqrt(gx * gx + gy * gy) - reach - 1e-9  # a lower bound of this wall's distance
        if bound > 0.0 and bound * bound > best:
            continue
        rx, ry = ax - x, ay - y
        lx0, ly0 = c * rx + s * ry, -s * rx + c * ry
        rx, ry = bx - x, by - y
        lx1, ly1 = c * rx + s * ry, -s * rx + c * ry
        ex, ey = lx1 - lx0, ly1 - ly0
        if ((lx0 if lx0 < lx1 else lx1) <= hl and (lx0 if lx0 > lx1 else lx1) >= -hl
                and (ly0 if ly0 < ly1 else ly1) <= hw and (ly0 if ly0 > ly1 else ly1) >= -hw
                and abs(ex * ly0 - ey * lx0) <= hl * abs(ey) + hw * abs(ex)):
            return 0.0  # separating-axis test: they overlap
        # the segment's end points to the box
        dx, dy = abs(lx0) - hl, abs(ly0) - hw
        dx, dy = (dx if dx > 0.0 else 0.0), (dy if dy > 0.0 else 0.0)
        d = dx * dx + dy * dy
        dx, dy = abs(lx1) - hl, abs(ly1) - hw
        dx, dy = (dx if dx > 0.0 else 0.0), (dy if dy > 0.0 else 0.0)
        d1 = dx * dx + dy * dy
        if d1 < d:
            d = d1
        # the box's corners to the segment
        ll = ex * ex + ey * ey
        den = ll if ll > 0.0 else 1.0
        for kx, ky in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)):
            u = ((kx - lx0) * ex + (ky - ly0) * ey) / den
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
            dx, dy = kx - (lx0 + u * ex), ky - (ly0 + u * ey)
            d1 = dx * dx + dy * dy
            if d1 < d:
                d = d1
        if d < best:
            best = d
    return math.sqrt(best)


class RangeNoise:
    """Seeded LIDAR corruption applied in place: Gaussian noise, drop-outs and spurious close returns (§2, H5).

    Every call draws the same amount of randomness, so a run is reproducible from its seed. Work arrays are
    made once; `apply` allocates nothing.
    """

    def __init__(
        self,
        beams: int,
        rng: np.random.Generator,
        sigma_m: float = 0.01,
        dropout: float = 0.0,
        spurious: float = 0.0,
        spurious_range_m: tuple[float, float] = (0.3, 1.0),
        min_range_m: float = 0.05,
        max_range_m: float = 10.0,
    ):
        self.rng = rng
        self.sigma_m, self.dropout, self.spurious = sigma_m, dropout, spurious
        self.spurious_range_m = spurious_range_m
        self.min_range_m, self.max_range_m = min_range_m, max_range_m
        self._noise = np.empty(beams)
        self._u = np.empty(beams)
        self._mask = np.empty(beams, dtype=bool)
        self._mtmp = np.empty(beams, dtype=bool)

    @classmethod
    def from_model(cls, lidar: LidarModel, rng: np.random.Generator) -> RangeNoise:
        return cls(lidar.beams, rng, lidar.noise_sigma_m, lidar.dropout, lidar.spurious, lidar.spurious_range_m,
                   lidar.min_range_m, lidar.max_range_m)

    def apply(self, ranges: NDArray[np.floating]) -> NDArray[np.floating]:
        """Corrupt ranges (NaN = no return) in place; results outside the sensor's range become NaN."""
        if self.sigma_m > 0:
            self.rng.standard_normal(out=self._noise)
            np.multiply(self._noise, self.sigma_m, out=self._noise)
            np.add(ranges, self._noise, out=ranges, casting="same_kind")
        if self.dropout > 0:
            self.rng.random(out=self._u)
            np.less(self._u, self.dropout, out=self._mask)
            np.copyto(ranges, np.nan, where=self._mask)
        if self.spurious > 0:
            self.rng.random(out=self._u)
            np.less(self._u, self.spurious, out=self._mask)
            lo, hi = self.spurious_range_m
            self.rng.random(out=self._u)
            np.multiply(self._u, hi - lo, out=self._u)
            np.add(self._u, lo, out=self._u)
            np.copyto(ranges, self._u, where=self._mask, casting="same_kind")
        np.less(ranges, self.min_range_m, out=self._mask)
        np.greater(ranges, self.max_range_m, out=self._mtmp)
        np.logical_or(self._mask, self._mtmp, out=self._mask)
        np.copyto(ranges, np.nan, where=self._mask)
        return ranges
