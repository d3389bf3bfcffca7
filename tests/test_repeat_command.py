"""scripts/repeat_command.py: what one repeated double-step command does on a backend."""

import importlib.util
import math
from pathlib import Path

import pytest

from footsim.geometry import Pose2D

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "repeat_command.py"


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("repeat_command", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_displacement_is_per_double_step_in_the_starting_frame(script):
    # Facing +y (theta = pi/2), two double steps of 0.1 m each along +y and 0.2 rad of turn in all:
    # 0.1 m forward, no lateral, 0.1 rad per double step.
    poses = [Pose2D(1.0, 2.0, math.pi / 2), Pose2D(1.0, 2.1, math.pi / 2 + 0.1), Pose2D(1.0, 2.2, math.pi / 2 + 0.2)]
    forward, lateral, turn = script.per_double_step(poses)
    assert (forward, lateral, turn) == pytest.approx((0.1, 0.0, 0.1))


def test_on_the_2d_backend_each_foot_moves_twice_its_step(script, capsys):
    # Each foot steps x ahead of its resting pose beside the other, which is itself x ahead: once
    # walking, both feet (and the robot) advance 2x per double step; x = 0.5 of the 0.156 m limit.
    script.main(["backend=pymunk", "action=0.5,0,0,0.5,0,0"])
    assert "forward +156.0 mm, lateral +0.0 mm, turn +0.000 deg" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["action=1,2"], ["action", "6 numbers"]),
        (["action=0,0,0,0,0,2"], ["action", "[-1, 1]"]),
        (["skip=5", "steps=5"], ["skip", "steps"]),
        (["colour=red"], ["unknown key", "'colour'"]),
    ],
)
def test_bad_arguments_fail_naming_them(script, argv, words):
    with pytest.raises(SystemExit) as err:
        script.main(["backend=pymunk", *argv])
    for word in words:
        assert word in str(err.value)
