"""The sensing kernel: sonars, camera and map odometry, computed analytically.

The ring's walls and the obstacle are axis-aligned boxes, so every sonar reading is a slab
test (`sense`); a corridor track's walls are segments, its obstacles any number of boxes
(`sense_corridor`). numba compiles both to machine code so sensing costs less than the
physics step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

from core.sim.sensing import (
    G_CAMERA_OFFSET,
    G_CAMERA_RANGE,
    G_CORNER_TRIGGER,
    G_CORRIDOR,
    G_FOV_HALF,
    G_HALF_LENGTH,
    G_INNER,
    G_LAMP_X,
    G_LAMP_Y,
    G_OBSTACLE_ECHO,
    G_OBSTACLE_SIGHT,
    G_OUTER,
    G_SIGNAL_LEG,
    G_SONAR_MOUNT,
    G_SONAR_RANGE,
    G_STOPLINE_X,
    G_STOPLINE_Y,
    G_TRACK_HOLD,
    INF,
    UNSEEN,
    empty_channels,
)

__all__ = [
    "empty_channels",
    "ray_entry",
    "ray_exit",
    "ray_segment",
    "residuals_at",
    "sense",
    "sense_corridor",
    "walls_hit",
]

_F = TypeVar("_F", bound=Callable[..., Any])


def _jit(f: _F) -> _F:
    """Compile with numba, caching the machine code beside the module."""
    return cast(_F, numba.njit(cache=True, nogil=True)(f))


@_jit
def ray_exit(px: float, py: float, dx: float, dy: float, box: Any) -> float:
    """Distance along a ray from inside a box to the box's boundary."""
    t = INF
    if dx > 1e-12:
        t = min(t, (box[2] - px) / dx)
    elif dx < -1e-12:
        t = min(t, (box[0] - px) / dx)
    if dy > 1e-12:
        t = min(t, (box[3] - py) / dy)
    elif dy < -1e-12:
        t = min(t, (box[1] - py) / dy)
    return max(t, 0.0)


@_jit
def ray_entry(px: float, py: float, dx: float, dy: float, box: Any) -> float:
    """Distance along a ray to where it enters a box (0 inside it, INF if it misses)."""
    tmin = -INF
    tmax = INF
    if abs(dx) < 1e-12:
        if px < box[0] or px > box[2]:
            return INF
    else:
        t1 = (box[0] - px) / dx
        t2 = (box[2] - px) / dx
        if t1 > t2:
            t1, t2 = t2, t1
        tmin = max(tmin, t1)
        tmax = min(tmax, t2)
    if abs(dy) < 1e-12:
        if py < box[1] or py > box[3]:
            return INF
    else:
        t1 = (box[1] - py) / dy
        t2 = (box[3] - py) / dy
        if t1 > t2:
            t1, t2 = t2, t1
        tmin = max(tmin, t1)
        tmax = min(tmax, t2)
    if tmax < max(tmin, 0.0):
        return INF
    return max(tmin, 0.0)


@_jit
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@_jit
def _sees(
    cx: float, cy: float, c: float, s: float, tx: float, ty: float, g: Any, reach: float
) -> tuple[bool, float, float, float]:
    """Whether the camera at (cx, cy) heading (c, s) sees the point (tx, ty) within `reach`."""
    rx = tx - cx
    ry = ty - cy
    fwd = rx * c + ry * s
    lat = -rx * s + ry * c
    dist = math.sqrt(rx * rx + ry * ry)
    if fwd <= 0.0 or dist > reach:
        return False, dist, fwd, lat
    if abs(math.atan2(lat, fwd)) > g[G_FOV_HALF]:
        return False, dist, fwd, lat
    # The inner island is the only thing that hides a target on this track.
    if ray_entry(cx, cy, rx, ry, g[G_INNER : G_INNER + 4]) < 1.0:
        return False, dist, fwd, lat
    return True, dist, fwd, lat


@_jit
def _walls_along(ox: float, oy: float, dx: float, dy: float, outer: Any, inner: Any) -> float:
    """Distance along a ray from (ox, oy) inside the corridor to the first static wall."""
    return min(ray_exit(ox, oy, dx, dy, outer), ray_entry(ox, oy, dx, dy, inner))


@_jit
def residuals_at(x: float, y: float, th: float, g: Any, sonar_angles: Any, out: Any) -> None:
    """Set each sonar's residual in `out` from the map's prediction at pose (x, y, th).

    The residual is the prediction minus the reading (`out`'s sonars). `sense` measures the
    residuals against the map from the true pose; a robot whose odometry drifts predicts
    from where it believes it is (`core.sim.perception`).
    """
    outer = g[G_OUTER : G_OUTER + 4]
    inner = g[G_INNER : G_INNER + 4]
    mount = g[G_SONAR_MOUNT]
    for i in range(8):
        a = th + sonar_angles[i]
        dx = math.cos(a)
        dy = math.sin(a)
        walls = _walls_along(x + mount * dx, y + mount * dy, dx, dy, outer, inner)
        out[8 + i] = min(walls, g[G_SONAR_RANGE]) - out[i]


@_jit
def sense(
    x: float,
    y: float,
    th: float,
    g: Any,
    sonar_angles: Any,
    noise: Any,
    obstacle: Any,
    has_obstacle: bool,
    lamp_color: float,
    bumper: float,
    track: Any,
    vertices: Any,
    directions: Any,
    lengths: Any,
    starts: Any,
    out: Any,
) -> None:
    """Fill `out` (see core.sim.channels.Channel) for a robot at pose (x, y, th)."""
    outer = g[G_OUTER : G_OUTER + 4]
    inner = g[G_INNER : G_INNER + 4]
    rng = g[G_SONAR_RANGE]
    mount = g[G_SONAR_MOUNT]
    for i in range(8):
        a = th + sonar_angles[i]
        dx = math.cos(a)
        dy = math.sin(a)
        ox = x + mount * dx
        oy = y + mount * dy
        walls = _walls_along(ox, oy, dx, dy, outer, inner)
        seen = walls
        if has_obstacle:
            hit = ray_entry(ox, oy, dx, dy, obstacle)
            # The obstacle's echo is heard only within its echo range; beyond it the
            # sonar reads what lies behind (see ObstacleConfig.echo_range_m).
            if hit <= g[G_OBSTACLE_ECHO]:
                seen = min(seen, hit)
        walls = min(walls, rng)
        reading = min(max(min(seen, rng) + noise[i], 0.0), rng)
        out[i] = reading
        out[8 + i] = walls - reading

    # Map odometry: the nearest leg of the centre line.
    best = 0
    best_d = INF
    for leg in range(4):
        ax = vertices[(leg + 3) % 4, 0]
        ay = vertices[(leg + 3) % 4, 1]
        along = (x - ax) * directions[leg, 0] + (y - ay) * directions[leg, 1]
        along = min(max(along, 0.0), lengths[leg])
        ex = ax + along * directions[leg, 0] - x
        ey = ay + along * directions[leg, 1] - y
        d = ex * ex + ey * ey
        if d < best_d:
            best_d = d
            best = leg
    ax = vertices[(best + 3) % 4, 0]
    ay = vertices[(best + 3) % 4, 1]
    dxl = directions[best, 0]
    dyl = directions[best, 1]
    along = (x - ax) * dxl + (y - ay) * dyl
    vertex_ahead = lengths[best] - along
    err_cur = _wrap(th - math.atan2(dyl, dxl))
    nxt = (best + 1) % 4
    err_next = _wrap(th - math.atan2(directions[nxt, 1], directions[nxt, 0]))
    ref = best
    err = err_cur
    if vertex_ahead < 0.5 * g[G_CORRIDOR] and abs(err_next) < abs(err_cur):
        ref = nxt
        err = err_next
    rax = vertices[(ref + 3) % 4, 0]
    ray_ = vertices[(ref + 3) % 4, 1]
    lateral = -(x - rax) * directions[ref, 1] + (y - ray_) * directions[ref, 0]
    out[16] = lateral
    out[17] = err
    out[18] = vertex_ahead
    out[19] = 1.0 if (ref == best and vertex_ahead < g[G_CORNER_TRIGGER]) else 0.0
    out[26] = best
    out[27] = starts[best] + min(max(along, 0.0), lengths[best])

    # Camera.
    c = math.cos(th)
    s = math.sin(th)
    cx = x + g[G_CAMERA_OFFSET] * c
    cy = y + g[G_CAMERA_OFFSET] * s
    out[20] = 0.0
    out[21] = UNSEEN
    out[22] = UNSEEN
    out[29] = UNSEEN
    out[31] = UNSEEN
    if has_obstacle:
        ocx = 0.5 * (obstacle[0] + obstacle[2])
        ocy = 0.5 * (obstacle[1] + obstacle[3])
        ok, _, fwd, lat = _sees(cx, cy, c, s, ocx, ocy, g, g[G_OBSTACLE_SIGHT])
        if ok:
            out[20] = 1.0
            out[31] = math.atan2(lat, fwd) / g[G_FOV_HALF]
            track[0] = 1.0
            track[1] = ocx
            track[2] = ocy
            track[3] = 0.0
        elif track[0] > 0.0:
            track[3] += 1.0
    # The obstacle's position on the map, from the camera's range and bearing and the
    # robot's own pose, is tracked for a while after it leaves the field of view, as long
    # as it is still ahead: where it lies across the corridor does not depend on where the
    # robot points.
    if track[0] > 0.0 and track[3] <= g[G_TRACK_HOLD]:
        tx = track[1] - x
        ty = track[2] - y
        ahead = tx * directions[ref, 0] + ty * directions[ref, 1]
        if ahead > -0.1:
            out[21] = math.sqrt(tx * tx + ty * ty)
            out[22] = -tx * directions[ref, 1] + ty * directions[ref, 0]
            out[29] = (
                -(track[1] - rax) * directions[ref, 1] + (track[2] - ray_) * directions[ref, 0]
            )
        else:
            track[0] = 0.0
    ok, _, _, _ = _sees(cx, cy, c, s, g[G_LAMP_X], g[G_LAMP_Y], g, g[G_CAMERA_RANGE])
    out[23] = lamp_color if ok else 0.0
    if best == int(g[G_SIGNAL_LEG]):
        ahead = (g[G_STOPLINE_X] - x) * dxl + (g[G_STOPLINE_Y] - y) * dyl
        out[24] = ahead if ahead > 0.0 else UNSEEN
        out[28] = ahead - g[G_HALF_LENGTH]
    else:
        out[24] = UNSEEN
        out[28] = UNSEEN
    out[25] = bumper
    out[30] = th


# Corridor tracks of any shape (`core.sim.corridor`): walls as segments, legs as rows.
LEG_X = 0
LEG_Y = 1
LEG_DX = 2
LEG_DY = 3
LEG_LENGTH = 4
LEG_START = 5  # arc length at the leg's start
LEG_CORNER = 6  # how far before its end the next leg's corner starts
LEG_LEFT90 = 7  # 1 where the leg ends in the ring's left turn of about 90 degrees
LEG_COLUMNS = 8


@_jit
def ray_segment(ox: float, oy: float, dx: float, dy: float, w: Any) -> float:
    """Distance along a ray from (ox, oy) to the wall segment w = (x0, y0, x1, y1), or INF."""
    ex = w[2] - w[0]
    ey = w[3] - w[1]
    den = dx * ey - dy * ex
    if abs(den) < 1e-12:
        return INF
    px = w[0] - ox
    py = w[1] - oy
    t = (px * ey - py * ex) / den
    u = (px * dy - py * dx) / den
    if t < 0.0 or u < 0.0 or u > 1.0:
        return INF
    return float(t)


@_jit
def walls_hit(ox: float, oy: float, dx: float, dy: float, walls: Any) -> float:
    """Distance along a ray to the first wall segment."""
    best = INF
    for k in range(walls.shape[0]):
        t = ray_segment(ox, oy, dx, dy, walls[k])
        if t < best:
            best = t
    return best


@_jit
def _sees_past_walls(
    cx: float, cy: float, c: float, s: float, tx: float, ty: float, g: Any, reach: float,
    walls: Any,
) -> tuple[bool, float, float, float]:  # fmt: skip
    """Whether the camera sees (tx, ty) within `reach`, no wall segment between."""
    rx = tx - cx
    ry = ty - cy
    fwd = rx * c + ry * s
    lat = -rx * s + ry * c
    dist = math.sqrt(rx * rx + ry * ry)
    if fwd <= 0.0 or dist > reach:
        return False, dist, fwd, lat
    if abs(math.atan2(lat, fwd)) > g[G_FOV_HALF]:
        return False, dist, fwd, lat
    if walls_hit(cx, cy, rx, ry, walls) < 1.0:
        return False, dist, fwd, lat
    return True, dist, fwd, lat


@_jit
def _nearest_leg(x: float, y: float, legs: Any, first: int, count: int) -> tuple[int, float]:
    """Of legs first, first + 1, ... (count of them, wrapping), the one nearest (x, y)."""
    n = legs.shape[0]
    best = first
    best_d = INF
    for i in range(count):
        leg = (first + i) % n
        along = (x - legs[leg, LEG_X]) * legs[leg, LEG_DX] + (y - legs[leg, LEG_Y]) * legs[
            leg, LEG_DY
        ]
        along = min(max(along, 0.0), legs[leg, LEG_LENGTH])
        ex = legs[leg, LEG_X] + along * legs[leg, LEG_DX] - x
        ey = legs[leg, LEG_Y] + along * legs[leg, LEG_DY] - y
        d = ex * ex + ey * ey
        if d < best_d:
            best_d = d
            best = leg
    return best, best_d


@_jit
def sense_corridor(
    x: float,
    y: float,
    th: float,
    g: Any,
    sonar_angles: Any,
    noise: Any,
    obstacles: Any,
    n_obstacles: int,
    lamp_color: float,
    bumper: float,
    track: Any,
    walls: Any,
    legs: Any,
    state: Any,
    out: Any,
) -> None:
    """`sense` on a corridor track: walls as segments, any number of obstacles.

    `obstacles` holds boxes (x0 y0 x1 y1), the first `n_obstacles` present. `state[0]` is
    the leg the robot was on at the last reading (-1: none yet): the robot's leg is the
    nearest of that one and its neighbours, so progress stays on the leg the robot is on
    where two legs cross.
    """
    rng = g[G_SONAR_RANGE]
    mount = g[G_SONAR_MOUNT]
    echo = g[G_OBSTACLE_ECHO]
    for i in range(8):
        a = th + sonar_angles[i]
        dx = math.cos(a)
        dy = math.sin(a)
        ox = x + mount * dx
        oy = y + mount * dy
        wall = walls_hit(ox, oy, dx, dy, walls)
        seen = wall
        for j in range(n_obstacles):
            hit = ray_entry(ox, oy, dx, dy, obstacles[j])
            if hit <= echo:
                seen = min(seen, hit)
        wall = min(wall, rng)
        reading = min(max(min(seen, rng) + noise[i], 0.0), rng)
        out[i] = reading
        out[8 + i] = wall - reading

    # Map odometry: the leg the robot is on.
    n = legs.shape[0]
    cur = int(state[0])
    if cur < 0:
        best, _ = _nearest_leg(x, y, legs, 0, n)
    else:
        best, _ = _nearest_leg(x, y, legs, (cur + n - 1) % n, 3)
    state[0] = best
    dxl = legs[best, LEG_DX]
    dyl = legs[best, LEG_DY]
    along = (x - legs[best, LEG_X]) * dxl + (y - legs[best, LEG_Y]) * dyl
    vertex_ahead = legs[best, LEG_LENGTH] - along
    err_cur = _wrap(th - math.atan2(dyl, dxl))
    nxt = (best + 1) % n
    err_next = _wrap(th - math.atan2(legs[nxt, LEG_DY], legs[nxt, LEG_DX]))
    ref = best
    err = err_cur
    left90 = legs[best, LEG_LEFT90] > 0.5
    if vertex_ahead < legs[best, LEG_CORNER] and (not left90 or abs(err_next) < abs(err_cur)):
        # The ring's left corner is turned by the Corner reflex; any other corner by the
        # heading hold, towards the next leg from where the corner starts.
        ref = nxt
        err = err_next
    rax = legs[ref, LEG_X]
    ray_ = legs[ref, LEG_Y]
    rdx = legs[ref, LEG_DX]
    rdy = legs[ref, LEG_DY]
    lateral = -(x - rax) * rdy + (y - ray_) * rdx
    out[16] = lateral
    out[17] = err
    out[18] = vertex_ahead
    out[19] = 1.0 if (left90 and ref == best and vertex_ahead < g[G_CORNER_TRIGGER]) else 0.0
    out[26] = best
    out[27] = legs[best, LEG_START] + min(max(along, 0.0), legs[best, LEG_LENGTH])

    # Camera: the nearest obstacle in view.
    c = math.cos(th)
    s = math.sin(th)
    cx = x + g[G_CAMERA_OFFSET] * c
    cy = y + g[G_CAMERA_OFFSET] * s
    out[20] = 0.0
    out[21] = UNSEEN
    out[22] = UNSEEN
    out[29] = UNSEEN
    out[31] = UNSEEN
    nearest = INF
    for j in range(n_obstacles):
        ocx = 0.5 * (obstacles[j, 0] + obstacles[j, 2])
        ocy = 0.5 * (obstacles[j, 1] + obstacles[j, 3])
        ok, dist, fwd, lat = _sees_past_walls(cx, cy, c, s, ocx, ocy, g, g[G_OBSTACLE_SIGHT], walls)
        if ok and dist < nearest:
            nearest = dist
            out[20] = 1.0
            out[31] = math.atan2(lat, fwd) / g[G_FOV_HALF]
            track[1] = ocx
            track[2] = ocy
    if nearest < INF:
        track[0] = 1.0
        track[3] = 0.0
    elif track[0] > 0.0:
        track[3] += 1.0
    if track[0] > 0.0 and track[3] <= g[G_TRACK_HOLD]:
        tx = track[1] - x
        ty = track[2] - y
        ahead = tx * rdx + ty * rdy
        if ahead > -0.1:
            out[21] = math.sqrt(tx * tx + ty * ty)
            out[22] = -tx * rdy + ty * rdx
            out[29] = -(track[1] - rax) * rdy + (track[2] - ray_) * rdx
        else:
            track[0] = 0.0
    ok, _, _, _ = _sees_past_walls(
        cx, cy, c, s, g[G_LAMP_X], g[G_LAMP_Y], g, g[G_CAMERA_RANGE], walls
    )
    out[23] = lamp_color if ok else 0.0
    if best == int(g[G_SIGNAL_LEG]):
        ahead = (g[G_STOPLINE_X] - x) * dxl + (g[G_STOPLINE_Y] - y) * dyl
        out[24] = ahead if ahead > 0.0 else UNSEEN
        out[28] = ahead - g[G_HALF_LENGTH]
    else:
        out[24] = UNSEEN
        out[28] = UNSEEN
    out[25] = bumper
    out[30] = th
