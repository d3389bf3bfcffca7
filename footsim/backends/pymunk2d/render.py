"""Top-down drawing of an episode like thesis Fig. 5.1 (PIL, no display needed).

Left footsteps green, right red (the commanded put-downs of the current double step filled
pale in the same colours), navigation poses as black arrows, rays olive, obstacles blue, the
ball orange, the goal cyan; a disc in the bottom-right corner is green once the goal is
reached, red before; the black bar beside it is 1 m long.
"""

from __future__ import annotations

import math

import numpy as np
from PIL import Image, ImageDraw

from footsim.geometry import Pose2D
from footsim.walk.footsteps import Side

SIZE = 600
MARGIN_M = 0.5


def _arrow(draw, to_px, pose: Pose2D, length: float, colour, width: int = 2) -> None:
    x0, y0 = to_px(pose.x, pose.y)
    x1, y1 = to_px(pose.x + length * math.cos(pose.theta), pose.y + length * math.sin(pose.theta))
    draw.line([(x0, y0), (x1, y1)], fill=colour, width=width)
    head = 0.35 * length
    for side in (2.6, -2.6):
        hx, hy = to_px(
            pose.x + length * math.cos(pose.theta) + head * math.cos(pose.theta + side),
            pose.y + length * math.sin(pose.theta) + head * math.sin(pose.theta + side),
        )
        draw.line([(x1, y1), (hx, hy)], fill=colour, width=width)


def draw_scene(scene, footsteps, nav_history, robot, overlay=None, size: int = SIZE) -> np.ndarray:
    """Render one episode so far as an RGB array of shape (size, size, 3)."""
    xs = [0.0] + [p.x for p in nav_history] + [o.x for o in scene.all_obstacles]
    ys = [0.0] + [p.y for p in nav_history] + [o.y for o in scene.all_obstacles]
    xs.append(scene.goal.x)
    ys.append(scene.goal.y)
    cx, cy = 0.5 * (min(xs) + max(xs)), 0.5 * (min(ys) + max(ys))
    span = max(max(xs) - min(xs), max(ys) - min(ys)) + 2 * MARGIN_M
    scale = size / span

    def to_px(x: float, y: float) -> tuple[float, float]:
        return (size / 2 + (x - cx) * scale, size / 2 - (y - cy) * scale)

    image = Image.new("RGB", (size, size), "white")
    draw = ImageDraw.Draw(image)
    if overlay is not None and overlay.ray_endpoints is not None and overlay.believed is not None:
        origin = to_px(overlay.believed.x, overlay.believed.y)
        for ex, ey in overlay.ray_endpoints:
            draw.line([origin, to_px(ex, ey)], fill=(150, 150, 40), width=1)
    for obstacle in scene.obstacles:
        x0, y0 = to_px(obstacle.x - obstacle.r, obstacle.y + obstacle.r)
        x1, y1 = to_px(obstacle.x + obstacle.r, obstacle.y - obstacle.r)
        draw.ellipse([x0, y0, x1, y1], fill=(70, 110, 220))
    if scene.ball is not None:
        b = scene.ball
        x0, y0 = to_px(b.x - b.r, b.y + b.r)
        x1, y1 = to_px(b.x + b.r, b.y - b.r)
        draw.ellipse([x0, y0, x1, y1], fill=(240, 150, 30))
    hl, hw = 0.5 * robot.foot_length, 0.5 * robot.foot_width
    corners_of = ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))
    if overlay is not None:  # the commanded put-downs of the current double step, filled pale
        for foot, fill in zip(overlay.footsteps, ((250, 200, 200), (200, 235, 205))):  # right, left
            draw.polygon([to_px(*foot.transform_point(dx, dy)) for dx, dy in corners_of], fill=fill)
    for side, foot in footsteps:
        corners = [foot.transform_point(dx, dy) for dx, dy in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
        colour = (40, 170, 60) if side is Side.LEFT else (210, 50, 50)
        draw.polygon([to_px(x, y) for x, y in corners], outline=colour, width=2)
    for pose in nav_history:
        _arrow(draw, to_px, pose, 0.12, (0, 0, 0))
    _arrow(draw, to_px, scene.goal, 0.2, (0, 190, 210), width=4)
    reached = overlay is not None and overlay.reached
    draw.ellipse([size - 40, size - 40, size - 12, size - 12], fill=(40, 190, 60) if reached else (220, 40, 40))
    bar = scale * 1.0
    draw.line([(size - 50 - bar, size - 20), (size - 50, size - 20)], fill=(0, 0, 0), width=3)
    draw.text((size - 50 - bar, size - 36), "1 m", fill=(0, 0, 0))
    return np.asarray(image)
