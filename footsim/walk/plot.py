"""Look at the walk: foot and trunk trajectories of a few double steps, drawn to a PNG
(``footsim-walkplot``, :mod:`footsim.tools.walkplot`).

The plot shows the start sequence, the double steps and (optionally) the stop: x, y, z and yaw of
both soles and the trunk over time (half-step boundaries dotted), and a top view with the
footprints where each foot was put down.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from footsim.walk.engine import QuinticWalk, WalkTrajectory
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, StepLimits
from footsim.walk.params import WalkParams

if TYPE_CHECKING:
    from matplotlib.axes import Axes

_COLOURS = {"left": "tab:blue", "right": "tab:red", "trunk": "black"}


def concatenate(trajectories: list[WalkTrajectory]) -> dict[str, np.ndarray]:
    """Stack the per-tick arrays of consecutive engine calls."""
    keys = ("t", "phase", "support", "state", "joint_targets", "left_foot", "right_foot", "trunk", "reachable")
    return {k: np.concatenate([getattr(tr, k) for tr in trajectories]) for k in keys}


def simulate(
    orders: list[DoubleStep],
    stop: bool = True,
    params: WalkParams | None = None,
    limits: StepLimits | None = None,
    control_dt: float = 0.002,
) -> tuple[QuinticWalk, list[WalkTrajectory]]:
    params = params or WalkParams()
    geometry = FootstepGeometry(limits or StepLimits(), foot_distance=params.foot_distance)
    engine = QuinticWalk(params, geometry, control_dt=control_dt)
    trajectories = [engine.double_step(order) for order in orders]
    if stop:
        trajectories.append(engine.stop())
    return engine, trajectories


def plot_walk(trajectories: list[WalkTrajectory], engine: QuinticWalk, out: str, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    data = concatenate(trajectories)
    t = data["t"]
    series = {"left": data["left_foot"], "right": data["right_foot"], "trunk": data["trunk"]}
    boundaries = t[1:][(np.diff(data["support"].astype(int)) != 0) | (np.diff(data["state"]) != 0)]

    fig = plt.figure(figsize=(13, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(4, 2, width_ratios=[1.4, 1])
    labels = [("x [m]", 0), ("y [m]", 1), ("z [m]", 2), ("yaw [rad]", 5)]
    axes: list[Axes] = []
    for row, (label, channel) in enumerate(labels):
        ax = fig.add_subplot(grid[row, 0], sharex=axes[0] if axes else None)
        for name, poses in series.items():
            values = np.unwrap(poses[:, channel]) if channel == 5 else poses[:, channel]
            ax.plot(t, values, color=_COLOURS[name], lw=1.3, label=f"{name}" + (" sole" if name != "trunk" else ""))
        for b in boundaries:
            ax.axvline(b, color="0.75", lw=0.6, ls=":")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        axes.append(ax)
    axes[0].legend(loc="upper left", fontsize=8, ncol=3)
    axes[-1].set_xlabel("time [s]  (dotted: half-step boundaries)")
    unreachable = ~data["reachable"]
    if unreachable.any():
        axes[2].plot(t[unreachable], np.zeros(unreachable.sum()), "x", color="orange", ms=3, label="IK unreachable")
        axes[2].legend(loc="upper left", fontsize=8)

    top = fig.add_subplot(grid[:, 1])
    half_l, half_w = 0.5 * engine.geometry.foot_length, 0.5 * engine.geometry.foot_width
    corners = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])
    for name in ("left", "right"):
        poses = series[name]
        on_ground = poses[:, 2] <= 1e-9
        # A footprint wherever the foot is on the ground with a new pose (after each put-down).
        prints = [0] + [i for i in range(1, len(poses)) if on_ground[i] and not on_ground[i - 1]]
        for i in prints:
            x, y, yaw = poses[i, 0], poses[i, 1], poses[i, 5]
            c, s = np.cos(yaw), np.sin(yaw)
            pts = corners @ np.array([[c, s], [-s, c]]) + [x, y]
            top.add_patch(Polygon(pts, closed=True, fill=False, ec=_COLOURS[name], lw=1.2))
        top.plot(poses[:, 0], poses[:, 1], color=_COLOURS[name], lw=0.6, alpha=0.6)
    trunk = series["trunk"]
    top.plot(trunk[:, 0], trunk[:, 1], color=_COLOURS["trunk"], lw=1.3, label="trunk")
    top.set_aspect("equal")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title("top view: footprints at put-down, trunk path")
    top.grid(alpha=0.3)
    top.legend(loc="upper left", fontsize=8)
    fig.suptitle(title or "quintic walk")
    fig.savefig(out, dpi=110)
    plt.close(fig)
