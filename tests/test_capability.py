"""The capability map: the grid, the landing error, the CSV, compare and the command line."""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math

import numpy as np
import pytest

from footsim.calibration import capability as cap
from footsim.geometry import Pose2D
from footsim.tools.capability import main
from footsim.walk.footsteps import DoubleStep, FeetState, FootstepGeometry, StepLimits


def rows(grid: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(float(v) for v in row) for row in grid}


def test_default_grid_is_the_same_step_for_both_feet_at_five_levels():
    grid = cap.capability_grid()
    assert grid.shape == (125, 6)
    assert np.array_equal(grid[:, :3], grid[:, 3:])
    for axis in range(3):
        assert sorted(set(grid[:, axis])) == [-1.0, -0.5, 0.0, 0.5, 1.0]
    cells = rows(grid)
    assert len(cells) == 125  # no cell twice
    for corner in itertools.product((-1.0, 1.0), repeat=3):
        assert (*corner, *corner) in cells
    assert (0.0,) * 6 in cells


def test_full_grid_covers_every_corner_of_the_six_dimensional_box():
    grid = cap.capability_grid("full")
    assert grid.shape == (3**6, 6)
    cells = rows(grid)
    assert len(cells) == 729
    assert all(corner in cells for corner in itertools.product((-1.0, 1.0), repeat=6))
    assert (0.0,) * 6 in cells


def test_explicit_levels_hold_the_axes_left_out_at_zero():
    grid = cap.capability_grid("x:-1,0,1/y:0/theta:0")
    assert rows(grid) == {(-1.0, 0.0, 0.0, -1.0, 0.0, 0.0), (0.0,) * 6, (1.0, 0.0, 0.0, 1.0, 0.0, 0.0)}
    assert rows(cap.capability_grid("theta:0.5")) == {(0.0, 0.0, 0.5, 0.0, 0.0, 0.5)}


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("diagonal", ["same[:N]", "'diagonal'"]),
        ("same:1", ["N >= 2", "'1'"]),
        ("x:2", ["x levels", "[-1, 1]", "'2'"]),
        ("z:0", ["axes x, y, theta", "'z:0'"]),
    ],
)
def test_a_bad_grid_names_itself(spec, words):
    with pytest.raises(ValueError) as err:
        cap.capability_grid(spec)
    for word in words:
        assert word in str(err.value)


def test_landing_error_is_the_distance_from_the_geometrys_landing():
    # From the stance at the origin a forward step of 0.1 m per foot puts the right foot at
    # (0.1, -d/2) and the left foot 0.1 m ahead of it: (0.2, +d/2), both heading 0.
    geometry = FootstepGeometry(StepLimits(), foot_distance=0.18)
    before = geometry.initial_feet()
    step = DoubleStep.from_array([0.1, 0.0, 0.0, 0.1, 0.0, 0.0])
    exact = FeetState(Pose2D(0.2, 0.09, 0.0), Pose2D(0.1, -0.09, 0.0))
    assert cap.landing_error(geometry, before, step, exact) == pytest.approx((0.0, 0.0), abs=1e-12)
    # left foot 3 cm short and turned 0.1 rad, right foot 4 cm to the side: means over the feet
    off = FeetState(Pose2D(0.17, 0.09, 0.1), Pose2D(0.1, -0.05, 0.0))
    assert cap.landing_error(geometry, before, step, off) == pytest.approx((0.035, 0.05))


def test_on_the_2d_backend_the_feet_land_where_the_geometry_puts_them():
    cells = cap.capability_map("pymunk", grid="x:-1,1/y:-1,1/theta:-1,1", repeats=2)
    assert len(cells) == 8
    for cell in cells:
        assert (cell.n, cell.falls, cell.sim_errors, cell.warmup_failures, cell.landed) == (2, 0, 0, 0, 2)
        assert cell.position_error_max == pytest.approx(0.0, abs=1e-12)
        assert cell.yaw_error_max == pytest.approx(0.0, abs=1e-12)
    assert cap.summary(cells)["stable_share"] == 1.0


def example_cells() -> list[cap.Cell]:
    return [
        cap.Cell((1.0, -0.5, 0.0, 1.0, -0.5, 0.0), 2, 1, 0, 0, 1, 0.0123456789012345, 0.0123456789012345, 0.1, 0.1),
        cap.Cell((0.0,) * 6, 2, 0, 0, 0, 2, 0.002, 0.003, 1e-4, 2e-4),
        cap.Cell((-1.0, 0.0, 0.0, -1.0, 0.0, 0.0), 2, 2, 0, 1, 0, math.nan, math.nan, math.nan, math.nan),
        cap.Cell((0.0, 0.0, 0.5, 0.0, 0.0, 0.5), 3, 0, 1, 0, 2, 0.01, 0.02, 0.03, 0.04),
    ]


def test_the_csv_round_trips(tmp_path):
    cells = example_cells()
    path = tmp_path / "capability.csv"
    path.write_text(cap.cells_to_csv(cells))
    back = cap.read_map(tmp_path)  # the directory finds its capability.csv
    assert len(back) == len(cells)
    for a, b in zip(cells, back):
        np.testing.assert_equal(dataclasses.astuple(b), dataclasses.astuple(a))  # NaN == NaN here
    header = path.read_text().splitlines()[0].split(",")
    assert header[:7] == [*cap.ACTION_COLUMNS, "fall_rate"]
    assert path.read_text().splitlines()[1].split(",")[6] == "0.5"  # 1 fall in 2 trials


def test_summary_counts_stable_cells_and_the_median_landing_error():
    s = cap.summary(example_cells())
    assert s["stable_share"] == 0.25  # only the in-place cell: no fall and no sim error
    assert s["median_position_error"] == pytest.approx(0.01)  # of 0.0123…, 0.002, 0.01
    assert (s["trials"], s["falls"], s["sim_errors"], s["warmup_failures"]) == (9, 3, 1, 1)


def test_compare_of_a_map_with_itself_is_zero_everywhere(tmp_path):
    cells = example_cells()
    diff = cap.map_difference(cells, cells)
    assert set(diff) == {c.action for c in cells}
    for cell in cells:
        d = diff[cell.action]
        assert d.fall_rate == 0.0
        if cell.landed:
            assert (d.position_error, d.yaw_error) == (0.0, 0.0)
        else:
            assert math.isnan(d.position_error) and math.isnan(d.yaw_error)
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "capability.csv").write_text(cap.cells_to_csv(cells))
    out = tmp_path / "gap.png"
    main([f"compare={tmp_path / 'a'},{tmp_path / 'a'}", f"out={out}"])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_maps_without_a_common_cell_cannot_be_compared():
    a, b = example_cells()[:1], example_cells()[1:2]
    with pytest.raises(ValueError, match="no cell in common"):
        cap.map_difference(a, b)


def test_the_command_writes_the_map_and_prints_the_summary(tmp_path, capsys):
    main(["backend=pymunk", "grid=same:3", "repeats=1", f"out={tmp_path}"])
    printed = capsys.readouterr().out
    assert "stable share of the action box: 100.0 % of 27 cells" in printed
    assert len(cap.read_map(tmp_path)) == 27
    assert (tmp_path / "capability.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_backend_settings_reach_the_measured_backend(tmp_path, capsys):
    # The 2D backend's fall model is a backend setting: fed a map where every forward step at the
    # limit falls, the measured map must show exactly those falls (the 2D robot never falls alone).
    main(["backend=pymunk", "grid=same:3", "repeats=1", f"out={tmp_path / 'stable'}"])
    rows = list(csv.DictReader(io.StringIO((tmp_path / "stable" / "capability.csv").read_text())))
    for row in rows:  # a cell's fall rate is read as falls / n
        forward = float(row["right_x"]) == 1.0
        row["falls"], row["fall_rate"] = (row["n"], "1.0") if forward else ("0", "0.0")
    given = tmp_path / "given.csv"
    with given.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    main(["backend=pymunk", "grid=same:3", "repeats=1", f"backend.fall_model={given}", f"out={tmp_path / 'falling'}"])
    assert f"pymunk, fall_model={given}" in capsys.readouterr().out
    measured = cap.read_map(tmp_path / "falling")
    assert [c.fall_rate for c in measured] == [float(r["fall_rate"]) for r in rows]
    assert sum(c.falls for c in measured) == 9  # x at the limit: 3 levels of y times 3 of theta


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["backend=nope"], ["unknown backend", "nope", "pymunk"]),
        (["backend=pymunk", "backend.colour=red"], ["backend pymunk", "unknown key", "'colour'"]),
        (["compare=a,b", "backend.physics_dt=0.001"], ["compare=", "backend.KEY=VALUE"]),
        (["compare=a,b", "walk.trunk_pitch=0.3"], ["compare=", "walk.KEY=VALUE"]),
        (["backend=pymunk", "walk.stride=2"], ["walk", "unknown key", "'stride'"]),
        (["backend=pymunk", "repeats=0"], ["repeats", "'0'"]),
        (["backend=pymunk", "seed=x"], ["seed", "'x'"]),
        (["backend=pymunk", "grid=same:1"], ["grid", "'1'"]),
        (["backend=pymunk", "colour=red"], ["unknown key", "'colour'"]),
        (["backend=pymunk", "walk=fastest"], ["walk preset", "'fastest'", "bitbots_sim"]),
        (["backend=pymunk", "randomization=wild"], ["randomization preset", "'wild'", "default"]),
        ([], ["backend=NAME"]),
        (["compare=only_one"], ["compare", "two map directories", "'only_one'"]),
        (["compare=/nonexistent/a,/nonexistent/b"], ["no capability map", "/nonexistent/a"]),
    ],
)
def test_a_bad_argument_fails_naming_it(argv, words):
    with pytest.raises(SystemExit) as err:
        main(argv)
    for word in words:
        assert word in str(err.value)


@pytest.mark.slow
def test_mujoco_map_of_three_forward_steps(tmp_path):
    pytest.importorskip("mujoco")
    main(["backend=mujoco", "grid=x:-0.5,0,0.5/y:0/theta:0", "repeats=1", f"out={tmp_path}"])
    cells = cap.read_map(tmp_path)
    assert [c.action[0] for c in cells] == [-0.5, 0.0, 0.5]
    for cell in cells:
        assert (cell.n, cell.sim_errors) == (1, 0)
    in_place = cells[1]
    assert (in_place.falls, in_place.landed) == (0, 1)
    # the soles land within a few centimetres and degrees of the footstep geometry's landing
    assert in_place.position_error_mean < 0.03 and in_place.yaw_error_mean < math.radians(5)


@pytest.mark.slow
def test_walk_settings_reach_the_measured_backend(tmp_path, capsys):
    # MuJoCo's robot walks in place on bitbots_sim (the walk check's required "in place"); with the
    # trunk leaning 0.45 rad forward it falls within two double steps (docs/walkcheck/mujoco_creep.md).
    pytest.importorskip("mujoco")
    for name, extra in (("upright", []), ("leaning", ["walk.trunk_pitch=0.45"])):
        main(["backend=mujoco", "grid=x:0/y:0/theta:0", "repeats=1", *extra, f"out={tmp_path / name}"])
    assert "walk=backend default, trunk_pitch=0.45" in capsys.readouterr().out
    upright, leaning = cap.read_map(tmp_path / "upright"), cap.read_map(tmp_path / "leaning")
    assert (upright[0].falls, leaning[0].falls) == (0, 1)


def test_the_x_y_panels_together_show_every_same_step_cell():
    keys = [tuple(row[:3]) for row in cap.capability_grid()]
    xy, others = cap.slice_panels(keys)
    assert [panel[3] for panel in xy] == [-1.0, -0.5, 0.0, 0.5, 1.0]  # one x–y panel per theta level
    assert all(panel[:3] == ("x", "y", "theta") for panel in xy)
    assert others == [("x", "theta", "y", 0.0), ("y", "theta", "x", 0.0)]
