"""The timestep-convergence comparisons of footsim.calibration.walkcheck, on hand-made final poses
against hand-computed distances, circular means and standard errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from footsim.calibration import walkcheck as wc
from footsim.geometry import Pose2D

NAMES = [s.name for s in wc.required_sequences()]


def _runs(poses_per_member: list[Pose2D], fell: list[bool] | None = None) -> list[dict[str, dict]]:
    """An ensemble whose every required sequence ends at the member's pose."""
    fell = fell or [False] * len(poses_per_member)
    return [
        {name: {"pose": pose, "fell": f, "sim_error": None} for name in NAMES}
        for pose, f in zip(poses_per_member, fell, strict=True)
    ]


def test_ensembles_compare_by_their_circular_mean_heading_and_mean_position():
    # Headings either side of +-pi: the circular mean of pi - 0.01 and -pi + 0.01 is pi, not 0.
    a = _runs([Pose2D(0.0, 0.0, math.pi - 0.01), Pose2D(0.02, 0.0, -math.pi + 0.01)])
    b = _runs([Pose2D(0.01, 0.01, math.pi - 0.02), Pose2D(0.01, -0.01, math.pi)])
    rows, text = wc.ensemble_rows(a, b, "### t", "dt, dt/2")
    row = rows[0]
    assert row["falls"] == (0, 0)
    assert row["distance"] == pytest.approx(0.0, abs=1e-12)  # both means at (0.01, 0)
    assert row["heading"] == pytest.approx(0.01, abs=1e-9)  # pi against pi - 0.01
    # sample spreads: headings +-0.01 about their means -> sd 0.01 * sqrt(2); positions 0.01 from the mean
    assert row["heading_sd"] == pytest.approx((0.01 * math.sqrt(2), 0.01 * math.sqrt(2)))
    assert row["position_sd"] == pytest.approx((0.01 * math.sqrt(2), 0.01 * math.sqrt(2)))
    assert row["heading_se"] == pytest.approx(math.sqrt(2 * (2e-4 / 2)))  # sqrt(sd_a^2/2 + sd_b^2/2)
    assert row["converged"]
    assert text.startswith("### t") and "| in place | 0, 0 | 0.000 | 0.6 ± 0.8 | 0.014; 0.8, 0.014; 0.8 | yes |" in text


def test_ensembles_that_differ_in_falls_or_by_more_than_the_bound_have_not_converged():
    still = [Pose2D(0.0, 0.0, 0.0)] * 3
    turned = [Pose2D(0.0, 0.0, math.radians(2.5))] * 3
    moved = [Pose2D(0.03, 0.0, 0.0)] * 3
    assert not wc.ensemble_rows(_runs(still), _runs(turned), "", "")[0][0]["converged"]
    assert not wc.ensemble_rows(_runs(still), _runs(moved), "", "")[0][0]["converged"]
    one_fell = wc.ensemble_rows(_runs(still), _runs(still, fell=[True, False, False]), "", "")[0][0]
    assert one_fell["falls"] == (0, 1) and not one_fell["converged"]
    # every member fell in both: the same outcome, nothing to compare
    all_fell = wc.ensemble_rows(_runs(still, [True] * 3), _runs(moved, [True] * 3), "", "")[0][0]
    assert all_fell["converged"] and math.isnan(all_fell["distance"])


def test_ensemble_convergence_runs_the_same_pushes_at_both_timesteps(monkeypatch):
    calls = []

    def fake_runs(backend, walk, robot, overrides, pushes=(None,)):
        calls.append((dict(overrides), [p.copy() for p in pushes]))
        poses = [Pose2D(0.0, 0.0, 0.0)] * len(pushes)
        return _runs(poses), (0.002, 0.008)

    monkeypatch.setattr(wc, "_required_runs", fake_runs)
    rows, text = wc.ensemble_convergence("mujoco", members=5, push=0.01, seed=3)
    (coarse, coarse_pushes), (fine, fine_pushes) = calls
    assert coarse == {} and fine == {"physics_dt": 0.001, "control_dt": 0.008}
    assert len(coarse_pushes) == 5
    assert all(np.array_equal(p, q) for p, q in zip(coarse_pushes, fine_pushes, strict=True))
    assert all(np.linalg.norm(p) == pytest.approx(0.01) and p[2] == 0.0 for p in coarse_pushes)
    assert len({round(math.atan2(p[1], p[0]), 6) for p in coarse_pushes}) == 5  # different directions
    assert "2 ms vs 1 ms, ensembles of 5 runs pushed by 0.01 N" in text and all(r["converged"] for r in rows)


def test_a_walkcheck_page_names_its_command_and_each_backends_timesteps():
    from footsim.tools.walkcheck import header

    page = header(
        ["walk=bitbots_sim", "backend.physics_dt=0.0005"], "bitbots_sim", ["mujoco"], {"physics_dt": 0.0005}, False
    )
    assert page.startswith("# footsim-walkcheck, walk=bitbots_sim")
    assert "Command: `footsim-walkcheck walk=bitbots_sim backend.physics_dt=0.0005`" in page
    assert "mujoco 0.5 ms physics, 8 ms targets" in page and "ensemble" not in page
    # PyBullet's defaults: 1/960 s ticks, targets every eighth one (1/120 s)
    assert "pybullet 1.04167 ms physics, 8.33333 ms targets" in header([], "", ["pybullet"], {}, True)
