"""Corridor tracks of any shape: a closed polyline centre line with a width.

The rectangular ring (`core.sim.track`) keeps its own fast path; a world file
(`core.sim.worldfile`) describes any other track as a `CorridorConfig`: the centre line's
vertices in lap order, a width per segment, the crossings the line is allowed to make (a
figure-8), the start, the signal and any number of obstacles with their placement rules.
`CorridorGeometry` derives what the sensing kernel, the physics and the pictures read: the
walls as segments (the centre line offset either side, mitred at corners, open where a
declared crossing is) and the legs' directions, lengths and arc lengths.

Segment (leg) ``k`` runs from ``centre[k]`` to ``centre[k + 1]`` (the last one back to
``centre[0]``); ``vertices[k]`` is its end, as in `TrackGeometry`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from core.sim.track import FloatArray, ObstacleConfig, SignalConfig

ObstacleRule = Literal["seeded", "fixed", "moving"]
Point = tuple[float, float]
Segment = tuple[Point, Point]

CROSSING_MARGIN_M = 0.3
"""How far a crossing stays from either crossing segment's ends, beyond the other's half width."""
MAX_TURN_DEG = 120.0
"""The sharpest corner a centre line may turn (a sharper one's mitre reaches far past it)."""
WALL_CLEARANCE_M = 0.05
"""The gap a fixed or moving obstacle leaves between itself and a wall, at least."""


@dataclass(frozen=True, slots=True)
class ObstaclePlacement:
    """One obstacle and where it goes.

    Attributes:
        rule: ``seeded`` (drawn each episode anywhere on the track, outside the keep-outs of
            `ObstacleConfig`), ``fixed`` (always at `segment`, `along_m`, `lateral_m`) or
            ``moving`` (back and forth along `segment` between the fractions `from_fraction`
            and `to_fraction` of its length at `speed_mps`, at `lateral_m`; where it is on
            its path at an episode's start is drawn from the episode's seed).
        segment: the segment it stands on (fixed, moving).
        along_m: its distance from the segment's start (fixed).
        lateral_m: its centre's offset left of the centre line (fixed, moving).
        from_fraction: one end of its path, a fraction of the segment's length (moving).
        to_fraction: the other end (moving).
        speed_mps: its speed along the path (moving).
    """

    rule: ObstacleRule = "seeded"
    segment: int = 0
    along_m: float = 0.0
    lateral_m: float = 0.0
    from_fraction: float = 0.0
    to_fraction: float = 1.0
    speed_mps: float = 0.0


@dataclass(frozen=True, slots=True)
class CorridorConfig:
    """A corridor track of any shape (see the module's docstring).

    Attributes:
        centre: the centre line's vertices in lap order, metres; the line closes by itself.
        widths_m: the corridor's width on each segment (one per vertex).
        crossings: pairs of segments whose centre lines cross (a figure-8); their walls open
            where the other corridor passes.
        start_segment: the segment the start pose is on, heading along it.
        start_along_m: the start pose's distance from that segment's start.
        signal: the traffic signal; `SignalConfig.leg` is its segment and
            `SignalConfig.stopline_fraction` where its stop line crosses the segment's
            straight part.
        obstacle: what every obstacle is (size, echo and sight ranges) and the keep-outs of
            seeded placements.
        obstacles: the obstacles and their placement rules.
    """

    centre: tuple[Point, ...]
    widths_m: tuple[float, ...]
    crossings: tuple[tuple[int, int], ...] = ()
    start_segment: int = 0
    start_along_m: float = 1.2
    signal: SignalConfig = field(default_factory=SignalConfig)
    obstacle: ObstacleConfig = field(default_factory=ObstacleConfig)
    obstacles: tuple[ObstaclePlacement, ...] = ()

    @property
    def corridor_width_m(self) -> float:
        """The widest segment's width (the ring's single width, for code that reads one)."""
        return max(self.widths_m)


@dataclass(frozen=True, slots=True)
class PlacedObstacle:
    """An obstacle placed for an episode: where it is at the episode's start and how it moves.

    Attributes:
        segment: the segment it is on.
        along_m: its distance from that segment's start at tick 0.
        lateral_m: its offset left of the centre line.
        low_m: the near end of its path (moving), metres from the segment's start.
        high_m: the far end of its path (moving).
        speed_mps: 0 for an obstacle that stands still.
        phase_m: how far along its back-and-forth cycle (2 x the path) it is at tick 0.
    """

    segment: int
    along_m: float
    lateral_m: float
    low_m: float = 0.0
    high_m: float = 0.0
    speed_mps: float = 0.0
    phase_m: float = 0.0

    def along_at(self, time_s: float) -> float:
        """Its distance along the segment `time_s` seconds into the episode."""
        if self.speed_mps <= 0.0:
            return self.along_m
        span = self.high_m - self.low_m
        s = (self.phase_m + self.speed_mps * time_s) % (2.0 * span)
        return self.low_m + (s if s <= span else 2.0 * span - s)


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def _line_meet(p: FloatArray, d: FloatArray, q: FloatArray, e: FloatArray) -> FloatArray | None:
    """Where the line p + t d meets the line q + s e (None: parallel)."""
    den = _cross(d[0], d[1], e[0], e[1])
    if abs(den) < 1e-9:
        return None
    t = _cross(q[0] - p[0], q[1] - p[1], e[0], e[1]) / den
    return p + t * d


def segments_meet(a: Segment, b: Segment) -> Point | None:
    """Where two segments cross (None: they do not, or they are parallel)."""
    (ax, ay), (bx, by) = a
    (cx, cy), (dx, dy) = b
    rx, ry, sx, sy = bx - ax, by - ay, dx - cx, dy - cy
    den = _cross(rx, ry, sx, sy)
    if abs(den) < 1e-12:
        return None
    t = _cross(cx - ax, cy - ay, sx, sy) / den
    u = _cross(cx - ax, cy - ay, rx, ry) / den
    if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
        return ax + t * rx, ay + t * ry
    return None


def segment_distance(a: Segment, b: Segment) -> float:
    """The shortest distance between two segments."""
    if segments_meet(a, b) is not None:
        return 0.0

    def point_to(p: Point, s: Segment) -> float:
        (x0, y0), (x1, y1) = s
        dx, dy = x1 - x0, y1 - y0
        n = dx * dx + dy * dy
        t = 0.0 if n == 0 else min(max(((p[0] - x0) * dx + (p[1] - y0) * dy) / n, 0.0), 1.0)
        return math.hypot(x0 + t * dx - p[0], y0 + t * dy - p[1])

    return min(point_to(a[0], b), point_to(a[1], b), point_to(b[0], a), point_to(b[1], a))


@dataclass(frozen=True, slots=True)
class CorridorGeometry:
    """Derived geometry of a `CorridorConfig`, with the attributes `TrackGeometry` has.

    `outer_box` is the walls' bounding box; `inner_box` is empty (a point at its centre):
    a corridor track has no single island box, its walls are `walls`.
    """

    config: CorridorConfig
    starts_xy: FloatArray
    vertices: FloatArray
    directions: FloatArray
    widths_m: FloatArray
    leg_lengths_m: FloatArray
    leg_start_m: FloatArray
    setbacks_m: FloatArray
    """Per segment, how far its straight part starts after and ends before its vertices."""
    left_corner: FloatArray
    """Per segment, 1 where it ends in a left turn of about 90 degrees (the ring's corner)."""
    walls: FloatArray
    """The wall segments, one row each: x0 y0 x1 y1."""
    lap_length_m: float
    outer_box: FloatArray
    inner_box: FloatArray
    start_pose: tuple[float, float, float]
    start_progress_m: float
    stopline_point: Point
    lamp_point: Point

    @classmethod
    def build(cls, config: CorridorConfig) -> CorridorGeometry:
        """Compute the arrays of a corridor track (its config assumed valid, see worldfile)."""
        starts = np.asarray(config.centre, dtype=np.float64)
        n = len(starts)
        ends = np.roll(starts, -1, axis=0)
        lengths = np.hypot(*(ends - starts).T)
        directions = (ends - starts) / lengths[:, None]
        widths = np.asarray(config.widths_m, dtype=np.float64)
        normals = np.stack([-directions[:, 1], directions[:, 0]], axis=1)
        turn = np.array(
            [turn_angle(directions[k], directions[(k + 1) % n]) for k in range(n)], dtype=float
        )
        # setback at the end of k (vertex k+1) and at the start of k (vertex k)
        end_back = np.array(
            [max(widths[k], widths[(k + 1) % n]) / 2 * math.tan(abs(turn[k]) / 2) for k in range(n)]
        )
        start_back = np.roll(end_back, 1)
        setbacks = np.stack([start_back, end_back], axis=1)
        left = np.array([1.0 if abs(t - math.pi / 2) < math.radians(5) else 0.0 for t in turn])
        walls = _walls(starts, directions, normals, widths, lengths, config.crossings)
        cum = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        s0 = config.start_segment
        start = starts[s0] + directions[s0] * config.start_along_m
        sig = config.signal
        k = sig.leg
        straight = lengths[k] - setbacks[k, 0] - setbacks[k, 1]
        stop = starts[k] + directions[k] * (setbacks[k, 0] + sig.stopline_fraction * straight)
        lamp = stop + directions[k] * sig.lamp_beyond_m - normals[k] * (widths[k] / 2 - 0.05)
        lo = walls[:, [0, 1]].min(axis=0), walls[:, [2, 3]].min(axis=0)
        hi = walls[:, [0, 1]].max(axis=0), walls[:, [2, 3]].max(axis=0)
        x0, y0 = (min(a, b) for a, b in zip(*lo, strict=True))
        x1, y1 = (max(a, b) for a, b in zip(*hi, strict=True))
        mid = ((x0 + x1) / 2, (y0 + y1) / 2)
        return cls(
            config=config,
            starts_xy=starts,
            vertices=ends,
            directions=directions,
            widths_m=widths,
            leg_lengths_m=lengths,
            leg_start_m=cum,
            setbacks_m=setbacks,
            left_corner=left,
            walls=walls,
            lap_length_m=float(lengths.sum()),
            outer_box=np.array([x0, y0, x1, y1]),
            inner_box=np.array([mid[0], mid[1], mid[0], mid[1]]),
            start_pose=(
                float(start[0]),
                float(start[1]),
                math.atan2(float(directions[s0][1]), float(directions[s0][0])),
            ),
            start_progress_m=float(cum[s0] + config.start_along_m),
            stopline_point=(float(stop[0]), float(stop[1])),
            lamp_point=(float(lamp[0]), float(lamp[1])),
        )

    def wall_segments(self) -> list[Segment]:
        """The wall segments as point pairs."""
        return [((float(a), float(b)), (float(c), float(d))) for a, b, c, d in self.walls]

    def centre_line(self) -> list[Point]:
        """The centre line's vertices in lap order (the line closes back to the first)."""
        return [(float(x), float(y)) for x, y in self.starts_xy]

    def point_on_leg(self, leg: int, along_m: float, lateral_m: float) -> Point:
        """The point `along_m` from segment `leg`'s start, `lateral_m` left of its centre line."""
        d = self.directions[leg]
        p = self.starts_xy[leg] + d * along_m + np.array([-d[1], d[0]]) * lateral_m
        return float(p[0]), float(p[1])

    def heading_of_leg(self, leg: int) -> float:
        """Direction of travel along a segment, radians."""
        d = self.directions[leg]
        return math.atan2(float(d[1]), float(d[0]))

    def straight_part(self, leg: int) -> tuple[float, float]:
        """Where segment `leg`'s straight part (clear of both corners) starts and ends."""
        return float(self.setbacks_m[leg, 0]), float(
            self.leg_lengths_m[leg] - self.setbacks_m[leg, 1]
        )

    def along_of(self, leg: int, point: Point) -> float:
        """A point's distance along segment `leg` from its start."""
        return float(np.dot(np.asarray(point) - self.starts_xy[leg], self.directions[leg]))

    def obstacle_at(self, placed: PlacedObstacle, time_s: float) -> Point:
        """Where an episode's obstacle is `time_s` seconds into the episode."""
        return self.point_on_leg(placed.segment, placed.along_at(time_s), placed.lateral_m)


def turn_angle(d0: FloatArray, d1: FloatArray) -> float:
    """The signed turn from direction `d0` to `d1`, radians, + = left."""
    return math.atan2(_cross(d0[0], d0[1], d1[0], d1[1]), float(np.dot(d0, d1)))


def _mitred_sides(
    starts: FloatArray,
    directions: FloatArray,
    normals: FloatArray,
    widths: FloatArray,
    lengths: FloatArray,
) -> list[tuple[list[FloatArray], list[FloatArray], list[tuple[int, FloatArray, FloatArray]]]]:
    """Each side's (left, then right) offset of the centre line, mitred with its neighbours.

    Per side: where each segment's wall begins and ends, and the steps (segment, a, b)
    joining two segments in line whose widths differ.
    """
    n = len(starts)
    sides = []
    for side in (1.0, -1.0):
        off = [starts[k] + side * normals[k] * widths[k] / 2 for k in range(n)]
        begin: list[FloatArray] = [off[k] for k in range(n)]
        end: list[FloatArray] = [off[k] + directions[k] * lengths[k] for k in range(n)]
        steps: list[tuple[int, FloatArray, FloatArray]] = []
        for k in range(n):
            j = (k + 1) % n
            meet = _line_meet(off[k], directions[k], off[j], directions[j])
            if meet is None:  # collinear segments: a step where the width changes
                if not np.allclose(end[k], begin[j]):
                    steps.append((k, end[k], begin[j]))
                continue
            end[k] = meet
            begin[j] = meet
        sides.append((begin, end, steps))
    return sides


def floor_quads(centre: Sequence[Point], widths: Sequence[float]) -> list[list[Point]]:
    """The corridor's floor, one quadrilateral per segment between its mitred walls.

    Each is [left begin, left end, right end, right begin]; together they cover the
    corridor (at a crossing two of them overlap in its square).
    """
    starts = np.asarray(centre, dtype=np.float64)
    ends = np.roll(starts, -1, axis=0)
    lengths = np.hypot(*(ends - starts).T)
    directions = (ends - starts) / lengths[:, None]
    normals = np.stack([-directions[:, 1], directions[:, 0]], axis=1)
    w = np.asarray(widths, dtype=np.float64)
    (lb, le, _), (rb, re, _) = _mitred_sides(starts, directions, normals, w, lengths)
    return [
        [(float(p[0]), float(p[1])) for p in (lb[k], le[k], re[k], rb[k])]
        for k in range(len(starts))
    ]


def _walls(
    starts: FloatArray,
    directions: FloatArray,
    normals: FloatArray,
    widths: FloatArray,
    lengths: FloatArray,
    crossings: tuple[tuple[int, int], ...],
) -> FloatArray:
    """The wall segments: each side's offset of the centre line, mitred, opened at crossings."""
    n = len(starts)
    pieces: list[tuple[int, FloatArray, FloatArray]] = []  # (segment, a, b)
    for begin, end, steps in _mitred_sides(starts, directions, normals, widths, lengths):
        pieces += [(k, begin[k], end[k]) for k in range(n)]
        pieces += steps
    out: list[FloatArray] = []
    for k, a, b in pieces:
        spans = [(0.0, 1.0)]
        for p, q in crossings:
            other = q if k == p else p if k == q else -1
            if other < 0:
                continue
            spans = [
                s for lo, hi in spans for s in _cut(a, b, lo, hi, starts, normals, widths, other)
            ]
        for lo, hi in spans:
            out.append(np.concatenate([a + (b - a) * lo, a + (b - a) * hi]))
    return np.array(out, dtype=np.float64)


def _cut(
    a: FloatArray,
    b: FloatArray,
    lo: float,
    hi: float,
    starts: FloatArray,
    normals: FloatArray,
    widths: FloatArray,
    other: int,
) -> list[tuple[float, float]]:
    """The parts of wall a-b (between fractions lo and hi) outside segment `other`'s corridor."""
    la = float(np.dot(a - starts[other], normals[other]))
    lb = float(np.dot(b - starts[other], normals[other]))
    half = widths[other] / 2
    if abs(lb - la) < 1e-12:  # parallel to the other corridor: inside it entirely or not at all
        return [] if abs(la) < half else [(lo, hi)]
    t0, t1 = sorted(((-half - la) / (lb - la), (half - la) / (lb - la)))
    keep = []
    if t0 > lo:
        keep.append((lo, min(t0, hi)))
    if t1 < hi:
        keep.append((max(t1, lo), hi))
    return [(x, y) for x, y in keep if y - x > 1e-9]


@dataclass(frozen=True, slots=True)
class SeededArea:
    """Where a seeded obstacle may go: straights less keep-outs (see `place_obstacles`).

    Attributes:
        straights: (segment, from, to) metres along it, where the straight parts are.
        keep_out: (segment, at, half span): no obstacle within half span of `at`.
        lateral_m: per segment, how far off the centre line an obstacle's centre may be.
    """

    straights: tuple[tuple[int, float, float], ...]
    keep_out: tuple[tuple[int, float, float], ...]
    lateral_m: tuple[float, ...]

    def spans(self) -> list[tuple[int, float, float]]:
        """The straights with the keep-outs cut out: (segment, from, to)."""
        out = []
        for k, lo, hi in self.straights:
            parts = [(lo, hi)]
            for seg, at, half in self.keep_out:
                if seg != k:
                    continue
                cut = []
                for a, b in parts:
                    if at - half > a:
                        cut.append((a, min(b, at - half)))
                    if at + half < b:
                        cut.append((max(a, at + half), b))
                parts = [(a, b) for a, b in cut if b > a]
            out += [(k, a, b) for a, b in parts]
        return out


def seeded_area(geometry: CorridorGeometry) -> SeededArea:
    """Where a seeded obstacle may go on a corridor track.

    Anywhere on the straight parts of the full-width segments (a narrow passage is left
    clear), at most `ObstacleConfig.max_lateral_m` off the centre line (less where the walls
    are nearer), outside the keep-outs: the corners, ahead of the start, either side of the
    stop line, the crossings, the ends of a narrow passage (as far as ahead of the start)
    and the places of fixed and moving obstacles.
    """
    config = geometry.config
    obs = config.obstacle
    full = float(geometry.widths_m.max())
    stop_leg = config.signal.leg
    n = len(geometry.leg_lengths_m)
    keep_out: list[tuple[int, float, float]] = []  # (segment, along, half span)
    keep_out.append(
        (
            config.start_segment,
            config.start_along_m + (obs.start_clearance_m - 0.3) / 2,
            (obs.start_clearance_m + 0.3) / 2,
        )
    )
    stop_along = geometry.along_of(stop_leg, geometry.stopline_point)
    keep_out.append((stop_leg, stop_along, obs.stopline_clearance_m))
    for a, b in config.crossings:
        for k, other in ((a, b), (b, a)):
            seg = (tuple(geometry.starts_xy[k]), tuple(geometry.vertices[k]))
            oth = (tuple(geometry.starts_xy[other]), tuple(geometry.vertices[other]))
            at = segments_meet(seg, oth)
            if at is not None:
                half = float(geometry.widths_m[other]) / 2 + obs.corner_margin_m
                keep_out.append((k, geometry.along_of(k, at), half))
    for k in range(n):  # either side of a narrow passage, as far as ahead of the start
        for side, nxt in ((0.0, (k - 1) % n), (1.0, (k + 1) % n)):
            if geometry.widths_m[k] == full and geometry.widths_m[nxt] < full:
                end = side * float(geometry.leg_lengths_m[k])
                keep_out.append((k, end, obs.start_clearance_m))
    for p in config.obstacles:  # clear of the obstacles that stand or move on their own
        if p.rule == "fixed":
            keep_out.append((p.segment, p.along_m, 2 * obs.size_m))
        elif p.rule == "moving":
            length = float(geometry.leg_lengths_m[p.segment])
            lo, hi = p.from_fraction * length, p.to_fraction * length
            keep_out.append((p.segment, (lo + hi) / 2, (hi - lo) / 2 + 2 * obs.size_m))
    straights = []
    for k in range(n):
        if geometry.widths_m[k] < full:
            continue
        lo, hi = geometry.straight_part(k)
        straights.append((k, lo + obs.corner_margin_m, hi - obs.corner_margin_m))
    lateral = tuple(
        max(min(obs.max_lateral_m, float(w) / 2 - obs.size_m / 2 - WALL_CLEARANCE_M), 0.0)
        for w in geometry.widths_m
    )
    return SeededArea(tuple(straights), tuple(keep_out), lateral)


def place_obstacles(geometry: CorridorGeometry, rng: np.random.Generator) -> list[PlacedObstacle]:
    """An episode's obstacles, in the order the track lists them, drawn from `rng`.

    A seeded obstacle is drawn uniformly over `seeded_area` (the draw is rejected and
    repeated where it falls in a keep-out); a moving one starts at a point of its cycle
    drawn here.
    """
    area = seeded_area(geometry)
    placed = []
    for p in geometry.config.obstacles:
        if p.rule == "fixed":
            placed.append(PlacedObstacle(p.segment, p.along_m, p.lateral_m))
        elif p.rule == "moving":
            length = float(geometry.leg_lengths_m[p.segment])
            low, high = p.from_fraction * length, p.to_fraction * length
            phase = float(rng.random()) * 2 * (high - low)
            path = PlacedObstacle(p.segment, low, p.lateral_m, low, high, p.speed_mps, phase)
            placed.append(dataclasses.replace(path, along_m=path.along_at(0.0)))
        else:
            placed.append(_seeded(area, rng))
    return placed


def _seeded(area: SeededArea, rng: np.random.Generator) -> PlacedObstacle:
    straights = area.straights
    total = sum(max(hi - lo, 0.0) for _, lo, hi in straights)
    for _ in range(1000):
        u = float(rng.random()) * total
        leg, along = straights[-1][0], straights[-1][2]
        for k, lo, hi in straights:
            span = max(hi - lo, 0.0)
            if u <= span:
                leg, along = k, lo + u
                break
            u -= span
        lateral = (float(rng.random()) * 2 - 1) * area.lateral_m[leg]
        if any(leg == k and abs(along - at) < half for k, at, half in area.keep_out):
            continue
        return PlacedObstacle(leg, along, lateral)
    raise ValueError("the keep-outs leave no place for a seeded obstacle")
