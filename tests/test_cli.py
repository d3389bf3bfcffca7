"""End-to-end runs through the installed command lines (tiny budgets)."""

import csv
import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from budgets import tiny_training

pytestmark = pytest.mark.slow

TINY = tiny_training(256, "train.checkpoint_freq=128", "eval.n_scenes=5", tensorboard=True)


def run(*args, cwd=None, check=True):
    proc = subprocess.run([*args], capture_output=True, text=True, cwd=cwd, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"{args} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


def _reject_non_json(constant):
    raise AssertionError(f"summary.json holds {constant}, which strict JSON parsers reject")


def test_summary_json_is_strict_json_without_successes(tmp_path):
    from footsim.rl.evaluate import format_table, summarize, write_results

    records = [{"outcome": "timeout", "time_s": 50.0, "steps": 100, "x": 0.0, "y": 0.0, "theta": 0.0}] * 3
    summary = summarize(records)
    write_results(tmp_path, records, summary, plot=False)
    saved = json.loads((tmp_path / "summary.json").read_text(), parse_constant=_reject_non_json)
    assert saved["timeout"] == 1.0 and saved["success_time_mean"] is None and saved["success_steps_std"] is None
    assert "| — | — |" in format_table({"policy": saved}) == format_table({"policy": summary})


def test_scenes_train_eval_resume(tmp_path):
    scenes = tmp_path / "scenes.json"
    run("footsim-scenes", f"out={scenes}", "n=4", "seed=3", "obstacles=true")
    assert len(json.loads(scenes.read_text())["scenes"]) == 4

    run_dir = tmp_path / "run"
    out = run("footsim-train", *TINY, "task=nav_obstacles", f"hydra.run.dir={run_dir}").stdout
    assert "| Approach | Success |" in out
    for name in (
        "model.zip",
        "config.yaml",
        "vecnormalize.pkl",
        "checkpoints/latest.zip",
        "eval/summary.json",
        "eval/episodes.csv",
        "eval/goals.png",
    ):
        assert (run_dir / name).is_file(), name
    assert list((run_dir / "tb").iterdir()), "tensorboard logs"
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(next((run_dir / "tb").iterdir())))
    events.Reload()
    rates = {
        tag: events.Scalars(tag)[-1].value
        for tag in events.Tags()["scalars"]
        if tag.startswith("rollout/") and tag.endswith("_rate")
    }
    assert set(rates) == {f"rollout/{o}_rate" for o in ("success", "timeout", "fall", "collision", "sim_error")}
    assert (
        sum(rates.values()) == pytest.approx(1.0, abs=1e-6) and rates["rollout/collision_rate"] > 0
    )  # random steps collide
    summary = json.loads((run_dir / "eval/summary.json").read_text(), parse_constant=_reject_non_json)
    assert summary["episodes"] == 5
    assert sum(summary[k] for k in ("success", "timeout", "fall", "collision", "sim_error")) == pytest.approx(1)

    eval_dir = tmp_path / "eval"
    out = run(
        "footsim-eval", f"run={run_dir}", f"scenes={scenes}", "noise=localization", f"hydra.run.dir={eval_dir}"
    ).stdout
    assert "noise=localization" in out
    rows = (eval_dir / "episodes.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 4
    assert json.loads((eval_dir / "summary.json").read_text())["episodes"] == 4

    # resume: extend the budget by editing nothing but the saved total, then continue
    cfg = (run_dir / "config.yaml").read_text().replace("total_timesteps: 256", "total_timesteps: 512")
    (run_dir / "config.yaml").write_text(cfg)
    out = run(
        "footsim-train", f"resume={run_dir}", "agent.learning_rate=0.5", f"hydra.run.dir={tmp_path / 'resume_log'}"
    ).stdout
    assert "resuming" in out
    assert "ignoring agent.learning_rate=0.5" in out  # the saved config decides, and it says so
    info = json.loads((run_dir / "train_info.json").read_text())
    assert info["num_timesteps"] >= 512


@pytest.mark.xdist_group("tiny_runs")
def test_eval_refuses_a_task_the_policy_cannot_read_and_honours_one_it_can(tiny_runs, tmp_path):
    nav_run = tiny_runs("ppo", "agent=ppo")  # obstacle-free: a 17-D observation
    refused = tmp_path / "refused"
    proc = run(
        "footsim-eval", f"run={nav_run}", "task=nav_obstacles", "n_scenes=2", f"hydra.run.dir={refused}", check=False
    )
    assert proc.returncode != 0
    message = proc.stdout + proc.stderr
    assert f"task=nav_obstacles cannot be evaluated with the policy of {nav_run}" in message
    assert "goal_and_actions 17 = 17 inputs (its task nav)" in message and "rays 36 = 53 inputs" in message
    assert not (refused / "episodes.csv").exists()

    # the same observation: the task is taken as given (the run was trained with max_steps 100)
    honoured = tmp_path / "honoured"
    run("footsim-eval", f"run={nav_run}", "task=nav", "task.max_steps=2", "n_scenes=3", "plot=false",
        f"hydra.run.dir={honoured}")  # fmt: skip
    steps = [int(row["steps"]) for row in csv.DictReader((honoured / "episodes.csv").open())]
    assert len(steps) == 3 and max(steps) == 2


@pytest.mark.xdist_group("tiny_runs")
def test_eval_says_what_it_uses_instead_of_what_it_does_not_take_as_given(tiny_runs, tmp_path, capsys):
    from omegaconf import OmegaConf

    from footsim.config import conf_dir
    from footsim.rl.evaluate import eval_run_config

    nav_run = tiny_runs("ppo", "agent=ppo")

    run_cfg = eval_run_config(nav_run, OmegaConf.create({"backend": {"name": "mujoco"}}))
    out = capsys.readouterr().out
    assert out.startswith("backend=mujoco: walking with the mujoco backend's walk preset (conf/walk/mujoco.yaml); ")
    assert "ignoring the run's walk (walk." in out
    assert (
        run_cfg.backend.name == "mujoco"
        and run_cfg.walk.freq == OmegaConf.load(conf_dir() / "walk/bitbots_sim.yaml").freq
    )
    # a run with its own gait, evaluated on its own backend with another option: it keeps its walk
    tuned = OmegaConf.load(nav_run / "config.yaml")
    tuned.walk.freq = 1.5
    (tmp_path / "tuned").mkdir()
    OmegaConf.save(tuned, tmp_path / "tuned" / "config.yaml")
    backend = {"name": "pymunk", "collision_distance": 0.25}
    run_cfg = eval_run_config(tmp_path / "tuned", OmegaConf.create({"backend": backend}))
    assert capsys.readouterr().out == ""  # nothing replaced, nothing to say
    assert run_cfg.walk.freq == 1.5 and run_cfg.backend.collision_distance == 0.25
    # a run recorded with its own backend setting: backend=NAME with another key drops it, and says so
    tuned.backend.collision_distance = 0.3
    OmegaConf.save(tuned, tmp_path / "tuned" / "config.yaml")
    asked = {"name": "pymunk", "collision_model": "nav_distance"}
    run_cfg = eval_run_config(tmp_path / "tuned", OmegaConf.create({"backend": asked}))
    out = capsys.readouterr().out
    assert "ignoring the run's recorded backend.collision_distance=0.3" in out and out.startswith("backend=pymunk: ")
    assert run_cfg.backend.collision_distance == 0.1 and run_cfg.backend.collision_model == "nav_distance"

    out = run("footsim-eval", f"run={nav_run}", "controller=velocity", "n_scenes=1", "plot=false",
              f"hydra.run.dir={tmp_path}").stdout  # fmt: skip
    assert f"controller=velocity: evaluating the baseline; ignoring run={nav_run}" in out


@pytest.mark.xdist_group("tiny_runs")
def test_eval_walk_replaces_the_runs_walk(tiny_runs, tmp_path, capsys):
    from omegaconf import OmegaConf

    from footsim.config import conf_dir
    from footsim.rl.evaluate import eval_run_config

    nav_run = tiny_runs("ppo", "agent=ppo")
    preset = OmegaConf.load(conf_dir() / "walk/bitbots_sim.yaml")  # the file, read without footsim
    # as Hydra composes walk=bitbots_sim walk.trunk_pitch=0.3: the preset's keys, one changed
    walk = {k: v for k, v in OmegaConf.to_container(preset).items() if k != "defaults"}
    asked = {"backend": {"name": "mujoco"}, "walk": {**walk, "trunk_pitch": 0.3}}
    run_cfg = eval_run_config(nav_run, OmegaConf.create(asked))
    assert capsys.readouterr().out == ""  # the walk is as asked: no note about the backend's preset
    assert run_cfg.walk.trunk_pitch == 0.3 and preset.trunk_pitch != 0.3
    assert run_cfg.walk.freq == preset.freq and run_cfg.backend.name == "mujoco"

    # through the command line: walk.KEY over the preset; an unknown walk key fails naming it
    out = tmp_path / "walk"
    run("footsim-eval", f"run={nav_run}", "walk=bitbots_sim", "walk.trunk_pitch=0.3", "n_scenes=1", "plot=false",
        f"hydra.run.dir={out}")  # fmt: skip
    assert (out / "episodes.csv").is_file()
    proc = run("footsim-eval", f"run={nav_run}", "walk=bitbots_sim", "+walk.stride=2", "n_scenes=1", "plot=false",
               f"hydra.run.dir={tmp_path / 'bad'}", check=False)  # fmt: skip
    assert proc.returncode != 0 and "stride" in proc.stdout + proc.stderr
    # walk.KEY without walk=W: a message that says what to add, not Hydra's "not in struct"
    proc = run("footsim-eval", f"run={nav_run}", "walk.trunk_pitch=0.3", "n_scenes=1", "plot=false",
               f"hydra.run.dir={tmp_path / 'bare'}", check=False)  # fmt: skip
    assert proc.returncode != 0 and "walk.trunk_pitch=0.3 needs walk=NAME beside it" in proc.stderr
    assert "not in struct" not in proc.stderr and not (tmp_path / "bare").exists()


@pytest.mark.parametrize("arg", ["backend.collision_model=nav_distance", "+noise.sigma_x=0.1", "task.n_rays=8"])
def test_eval_group_keys_need_the_group_named(arg):
    from footsim.tools.evaluate import check_group_overrides

    group = arg.lstrip("+").split(".")[0]
    with pytest.raises(SystemExit, match=rf"{re.escape(arg)} needs {group}=NAME beside it"):
        check_group_overrides(["run=r", arg])
    check_group_overrides(["run=r", f"{group}=x", arg, "hydra.run.dir=d", "n_scenes=3"])  # named: passes


def test_baseline_evaluation_applies_the_randomization_preset(tmp_path):
    finals = {}
    for preset in ("none", "default"):
        out_dir = tmp_path / preset
        out = run(
            "footsim-eval",
            "controller=velocity",
            "n_scenes=3",
            "plot=false",
            f"randomization={preset}",
            f"hydra.run.dir={out_dir}",
        ).stdout
        assert ("randomization=default" in out) == (preset == "default")
        rows = (out_dir / "episodes.csv").read_text().splitlines()[1:]
        finals[preset] = [row.split(",")[6:9] for row in rows]  # final_x, final_y, final_theta
    # default randomization adds footstep landing noise in 2D: the executed paths differ
    assert finals["none"] != finals["default"]


@pytest.mark.parametrize(
    "override,message",
    [
        ("backend=bogus", "backend"),
        ("train.n_envs=0", "train.n_envs must be a positive integer"),
        ("noise.sigma_x=-0.1", "noise.sigma_x must be a number >= 0"),
        ("task.scenes.ball_radius=-0.1", "task.scenes.ball_radius must be a positive number"),
        ("agent.lr_schedule=cosine", "agent.lr_schedule must be one of"),
        ("train.select.scenes_seed=-7", "train.select.scenes_seed must be a non-negative integer"),
    ],
)
def test_bad_config_fails_at_start_naming_the_key(tmp_path, override, message):
    proc = run("footsim-train", *TINY, override, f"hydra.run.dir={tmp_path}", check=False)
    assert proc.returncode != 0
    assert message in proc.stdout + proc.stderr


def test_scenes_cli_rejects_bad_n(tmp_path):
    proc = run("footsim-scenes", f"out={tmp_path / 'x.json'}", "n=0", check=False)
    assert proc.returncode != 0 and "n must be > 0" in proc.stderr


@pytest.mark.parametrize("module", ["scenes", "bench", "walkcheck", "calibrate", "capability", "walkplot", "reproduce"])
def test_key_value_tools_print_their_usage_on_help(module, capsys):
    """``--help`` prints the tool's usage line (its module docstring, which names the command) and
    exits 0 instead of refusing the argument; nothing runs."""
    import importlib

    tool = importlib.import_module(f"footsim.tools.{module}")
    with pytest.raises(SystemExit) as stop:
        tool.main(["--help"])
    printed = capsys.readouterr().out
    assert stop.value.code in (0, None) and printed.startswith(f"``footsim-{module}")


@pytest.mark.parametrize(
    "command",
    [
        ["footsim-walkcheck", "backends=mujoco,bogus"],
        ["footsim-calibrate", "backend=bogus", "out=OUT/cal.json"],
        ["footsim-transfer-matrix", "backends=pymunk,bogus", "out=OUT/matrix"],
    ],
)
def test_unknown_backend_on_the_command_line_is_named_before_any_work(tmp_path, command):
    proc = run(*[c.replace("OUT", str(tmp_path)) for c in command], check=False)
    assert proc.returncode != 0
    assert (
        proc.stderr.strip()
        .splitlines()[-1]
        .endswith("unknown backend(s) bogus; valid backends: pymunk, mujoco, dm_control, pybullet")
    )
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_first_ctrl_c_only_requests_a_stop_and_the_second_interrupts():
    import signal

    from footsim.rl.train import StopOnInterrupt

    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with StopOnInterrupt() as stop:
            assert not stop.requested
            signal.raise_signal(signal.SIGINT)  # no KeyboardInterrupt here
            assert stop.requested
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(signal.SIGINT)
        with StopOnInterrupt() as stop:
            pass
        assert not stop.requested and signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize("vec_env", ["dummy", "subproc"])
def test_ctrl_c_saves_a_checkpoint_and_exits_130_without_a_traceback(tmp_path, vec_env):
    import os
    import signal
    import time

    # A shell without job control starts background jobs with SIGINT ignored, and a child
    # inherits that (Python then never raises KeyboardInterrupt): give it the default handler.
    # checkpoint_freq=2 saves at almost every step, so the signal often arrives during a save.
    proc = subprocess.Popen(
        [
            "footsim-train",
            *TINY,
            "train.total_timesteps=10000000",
            "train.checkpoint_freq=2",
            f"train.vec_env={vec_env}",
            f"hydra.run.dir={tmp_path}",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    latest = tmp_path / "checkpoints" / "latest.json"
    deadline = time.monotonic() + 300
    while not latest.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    if not latest.exists():
        proc.kill()
        pytest.fail(f"no checkpoint before Ctrl-C:\n{proc.communicate()[1][-3000:]}")
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err[-3000:]
    assert f"interrupted: checkpoint saved; continue with footsim-train resume={tmp_path}" in out
    assert "Traceback" not in err
    steps = json.loads(latest.read_text())["num_timesteps"]
    assert steps > 0
    from stable_baselines3 import PPO

    assert PPO.load(tmp_path / "checkpoints" / "latest.zip", device="cpu").num_timesteps == steps
    assert not [p.name for p in (tmp_path / "checkpoints").iterdir() if p.name.startswith(".")]  # no temporaries


def test_conf_is_found_from_a_built_wheel(tmp_path):
    repo = Path(__file__).resolve().parents[1]
    run(sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp_path / "dist"), str(repo))
    wheel = next((tmp_path / "dist").glob("footsim-*.whl"))
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        assert "footsim/conf/config.yaml" in names and "footsim/conf/task/nav.yaml" in names
        zf.extractall(tmp_path / "site")
    code = (
        "import footsim.config as c, footsim.env as e; print(c.conf_dir());"
        "env = e.FootstepEnv(obstacles=True); print(env.observation_space.shape)"
    )
    proc = run(sys.executable, "-c", code, cwd=tmp_path)
    # PYTHONPATH makes the unpacked wheel shadow the editable install
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(tmp_path / "site"), "PATH": "/usr/bin:/bin"},
    )
    assert proc.returncode == 0, proc.stderr
    assert str(tmp_path / "site" / "footsim" / "conf") in proc.stdout and "(53,)" in proc.stdout
