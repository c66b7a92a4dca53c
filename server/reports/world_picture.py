"""A top-down picture of a world (`srlab world show`).

Walls, centre line (segments numbered), start, stop line and lamp, and the obstacles with
where they go: a seeded one's area, a fixed one's place, a moving one's path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Polygon, Rectangle

from core.sim.corridor import CorridorGeometry, seeded_area
from core.sim.track import TrackGeometry
from core.sim.types import Geometry, WorldConfig, build_geometry
from core.sim.worlds import WorldPreset
from server.reports.plots import save, subplots

_WALL = "#202020"
_CENTRE = "#7a7a7a"
_SEEDED = "#e8b27a"
_OBSTACLE = "#96602a"
_PATH = "#c0392b"


def seeded_spans(geo: Geometry) -> list[tuple[int, float, float, float]]:
    """Where a seeded obstacle may go: (leg, from, to, lateral limit), metres."""
    if isinstance(geo, CorridorGeometry):
        if not any(p.rule == "seeded" for p in geo.config.obstacles):
            return []  # nothing is placed by the seed: no area to shade
        area = seeded_area(geo)
        return [(k, lo, hi, area.lateral_m[k]) for k, lo, hi in area.spans()]
    track = geo.config
    obs = track.obstacle
    if not obs.enabled:
        return []
    half = track.corridor_width_m / 2
    out = []
    stop_along = float(
        np.dot(np.asarray(geo.stopline_point) - geo.vertices[(track.signal.leg - 1) % 4],
               geo.directions[track.signal.leg])
    )  # fmt: skip
    for leg in range(4):
        lo = half + obs.corner_margin_m
        hi = float(geo.leg_lengths_m[leg]) - half - obs.corner_margin_m
        cuts = []
        if leg == 0:
            cuts.append((track.start_along_m - 0.3, track.start_along_m + obs.start_clearance_m))
        if leg == track.signal.leg:
            cuts.append(
                (stop_along - obs.stopline_clearance_m, stop_along + obs.stopline_clearance_m)
            )
        parts = [(lo, hi)]
        for a, b in cuts:
            parts = [p for x, y in parts for p in ((x, min(y, a)), (max(x, b), y)) if p[1] > p[0]]
        out += [(leg, x, y, obs.max_lateral_m) for x, y in parts]
    return out


def draw_world(preset: WorldPreset, out: Path) -> None:
    """Write the picture of a world to `out` (PNG)."""
    config: WorldConfig = preset.config
    geo = build_geometry(config.track)
    x0, y0, x1, y1 = (float(v) for v in geo.outer_box)
    scale = 1.1
    fig, axes = subplots(1, figsize=(scale * (x1 - x0) + 1.5, scale * (y1 - y0) + 1.2))
    ax: Axes = axes[0][0]
    ax.set_aspect("equal")
    ax.set_facecolor("#b8b8b8")
    _floor(ax, geo)
    for (ax_, ay), (bx, by) in geo.wall_segments():
        ax.plot([ax_, bx], [ay, by], color=_WALL, lw=2.5, solid_capstyle="round")
    centre = _centre_line(geo)
    xs, ys = zip(*[*centre, centre[0]], strict=True)
    ax.plot(xs, ys, color=_CENTRE, lw=1, ls="--")
    for k, (sx, sy) in enumerate(centre):
        ex, ey = centre[(k + 1) % len(centre)]
        ax.annotate(
            str(k), ((sx + ex) / 2, (sy + ey) / 2), color=_CENTRE, fontsize=8,
            ha="center", va="bottom", xytext=(0, 2), textcoords="offset points",
        )  # fmt: skip
    size = config.track.obstacle.size_m
    for leg, lo, hi, lateral in seeded_spans(geo):
        a, b = geo.point_on_leg(leg, lo, 0.0), geo.point_on_leg(leg, hi, 0.0)
        width = 2 * lateral + size
        d = geo.directions[leg]
        n = np.array([-d[1], d[0]]) * width / 2
        corners = [np.add(a, n), np.add(b, n), np.subtract(b, n), np.subtract(a, n)]
        ax.add_patch(Polygon(corners, color=_SEEDED, alpha=0.6, lw=0))
    if isinstance(geo, CorridorGeometry):
        for p in geo.config.obstacles:
            if p.rule == "fixed":
                _box(ax, geo.point_on_leg(p.segment, p.along_m, p.lateral_m), size)
            elif p.rule == "moving":
                length = float(geo.leg_lengths_m[p.segment])
                a = geo.point_on_leg(p.segment, p.from_fraction * length, p.lateral_m)
                b = geo.point_on_leg(p.segment, p.to_fraction * length, p.lateral_m)
                ax.annotate("", b, a, arrowprops={"arrowstyle": "<|-|>", "color": _PATH, "lw": 1.5})
                ax.annotate(f"{p.speed_mps:g} m/s", b, color=_PATH, fontsize=8)
                _box(ax, a, size, alpha=0.5)
                _box(ax, b, size, alpha=0.5)
    sx, sy, th = geo.start_pose
    ax.annotate(
        "start", (sx + 0.5 * math.cos(th), sy + 0.5 * math.sin(th)), (sx, sy),
        arrowprops={"arrowstyle": "-|>", "color": "#1f5fbf", "lw": 2},
        color="#1f5fbf", fontsize=8, ha="right",
    )  # fmt: skip
    leg = config.track.signal.leg
    half = config.track.corridor_width_m / 2
    if isinstance(geo, CorridorGeometry):
        half = float(geo.widths_m[leg]) / 2
    d = geo.directions[leg]
    nx, ny = -d[1] * half, d[0] * half
    stx, sty = geo.stopline_point
    ax.plot([stx - nx, stx + nx], [sty - ny, sty + ny], color="white", lw=2.5)
    lx, ly = geo.lamp_point
    ax.plot([lx], [ly], "o", color="#e01414", ms=8, mec="black")
    ax.annotate("signal", (lx, ly), color="#e01414", fontsize=8, xytext=(4, 4),
                textcoords="offset points")  # fmt: skip
    ax.set_xlim(x0 - 0.3, x1 + 0.3)
    ax.set_ylim(y0 - 0.3, y1 + 0.3)
    ax.set_xlabel("x, m")
    ax.set_ylabel("y, m")
    ax.set_title(f"{preset.name}: {preset.description}" if preset.description else preset.name,
                 fontsize=9)  # fmt: skip
    save(fig, out)


def _centre_line(geo: Geometry) -> list[tuple[float, float]]:
    if isinstance(geo, CorridorGeometry):
        return geo.centre_line()
    return [(float(x), float(y)) for x, y in np.roll(geo.vertices, 1, axis=0)]


def _floor(ax: Axes, geo: Geometry) -> None:
    if isinstance(geo, TrackGeometry):
        bx0, by0, bx1, by1 = (float(v) for v in geo.outer_box)
        ax.add_patch(Rectangle((bx0, by0), bx1 - bx0, by1 - by0, color="#d6d6d0", lw=0))
        ix0, iy0, ix1, iy1 = (float(v) for v in geo.inner_box)
        ax.add_patch(Rectangle((ix0, iy0), ix1 - ix0, iy1 - iy0, color="#5a605a", lw=0))
        return
    for k in range(len(geo.leg_lengths_m)):
        back, ahead = geo.setbacks_m[k]
        length = float(geo.leg_lengths_m[k])
        half = float(geo.widths_m[k]) / 2
        corners = [
            geo.point_on_leg(k, -back, half),
            geo.point_on_leg(k, length + ahead, half),
            geo.point_on_leg(k, length + ahead, -half),
            geo.point_on_leg(k, -back, -half),
        ]
        ax.add_patch(Polygon(corners, color="#d6d6d0", lw=0))


def _box(ax: Axes, at: tuple[float, float], size: float, alpha: float = 1.0) -> None:
    ax.add_patch(
        Rectangle((at[0] - size / 2, at[1] - size / 2), size, size, color=_OBSTACLE, alpha=alpha)
    )
