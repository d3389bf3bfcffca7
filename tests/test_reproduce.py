"""footsim-reproduce (footsim.results.reproduce): the study plan, the training commands it gives, and an
end-to-end reproduction on a small plan and zoo checked against footsim-eval and hand-computed statistics."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import shutil
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest

from footsim import config as fconf
from footsim import zoo
from footsim.results import reproduce as rp
from footsim.rl.common import load_run_config
from footsim.tools.reproduce import main as reproduce_main
from footsim.tools.reproduce import parse_args


def test_study_plan_v1_training_commands_compose_to_its_conditions():
    """Each trained condition's footsim-train overrides compose with today's configs, and give the
    backend, task and noise the condition says its policies are evaluated under."""
    plan = rp.load_plan()
    assert plan.scene_sets["standard"] == (20220101, 500)
    assert plan.scene_sets["heldout"][0] != 20220101
    trained = [c for c in plan.conditions.values() if not c.policies]
    study_trained = {"2d_nav", "2d_nav_noise", "2d_obst_beta", "2d_obst_beta_10m_noise", "mj_nav", "mj_obst_beta"}
    assert {c.name for c in trained} >= study_trained
    for cond in trained:
        cfg = fconf.compose("config", [*cond.train, "seed=0"])
        evaluated = (cond.backend, cond.task, cond.noise, cond.randomization)
        noise = cfg.eval.noise or cfg.noise.name  # a run may be reported under another noise than it trains under
        assert (cfg.backend.name, cfg.task.name, noise, cfg.randomization.name) == evaluated, cond.name
        assert cfg.train.select.noise in (None, cond.noise), cond.name  # and validated under the reported one
    study = ("2d_nav", "2d_obst", "2d_nav_noise", "2d_obst_beta", "2d_obst_beta_10m_odometry")
    study += ("2d_obst_beta_tuned", "2d_obst_beta_7m", "2d_obst_beta_10m", "2d_obst_beta_10m_noise")
    study += ("mj_nav", "mj_nav_long", "mj_nav_noise", "mj_obst_beta", "mj_obst_beta_long")
    study += ("mj_nav_300k", "mj_obst_beta_400k", "mj_nav_scratch")
    study += ("mj_obst_beta_tilt", "mj_obst_beta_contact")
    study += ("mj_nav_start", "mj_obst_beta_start", "mj_obst_beta_start_noise")
    for name in study:  # the study's conditions
        cond = plan.conditions[name]
        assert len(cond.seeds) >= (5 if cond.backend == "pymunk" else 3), name  # issue 26: >= 5 in 2D, >= 3 in 3D
    # issue 26 item 1: {2D, MuJoCo} x {obstacle-free, obstacles} x {no noise, localization noise}
    cells = {(c.backend, c.task, c.noise) for c in trained if len(c.seeds) >= (5 if c.backend == "pymunk" else 3)}
    for backend in ("pymunk", "mujoco"):
        for task in ("nav", "nav_obstacles"):
            for noise in ("none", "localization"):
                assert (backend, task, noise) in cells, (backend, task, noise)
    for controller in plan.baselines:
        fconf.compose("eval", [f"controller={controller}"])  # every baseline names a controller preset
    assert plan.entry(plan.conditions["2d_nav_on_mujoco"], 3) == "2d_nav_s3"  # evaluates 2d_nav's policies
    # issue 26 item 3: trained on pymunk, MuJoCo and PyBullet (with and without randomization), evaluated
    # with and without it, obstacle-free and with obstacles
    assert {m.task for m in plan.matrices} == {"nav", "nav_obstacles"}
    for matrix in plan.matrices:
        trained = [plan.conditions[c] for c in matrix.rows.values()]
        assert {c.backend for c in trained} == {"pymunk", "mujoco", "pybullet"} <= set(matrix.backends)
        assert set(matrix.randomizations) == {"none", "default"} and all(c.task == matrix.task for c in trained)
    randomized = [
        plan.conditions[c] for c in plan.matrices[0].rows.values() if plan.conditions[c].randomization != "none"
    ]
    assert {c.backend for c in randomized} == {"mujoco", "pybullet"}


def _plan(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "plan.yaml"
    path.write_text(textwrap.dedent(body))
    return path


BASE = """
scene_sets: {standard: {seed: 20220101, n_scenes: 6}, heldout: {seed: 7, n_scenes: 4}}
conditions:
  nav:
    title: tiny obstacle-free
    backend: pymunk
    task: nav
    seeds: [0, 1]
    train: [train.total_timesteps=128]
"""


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("    backend: pymunk\n", ""), r"conditions\.nav\.backend is missing"),
        (
            lambda t: t.replace("    seeds: [0, 1]", "    seeds: [0, one]"),
            r"conditions\.nav\.seeds must be a list of integers",
        ),
        (lambda t: t + "    parent: nope\n", r"conditions\.nav\.parent: no condition 'nope'"),
        (lambda t: t + "    walk: fast\n", r"conditions\.nav: unknown key\(s\) \['walk'\]"),
        (
            lambda t: t + "    split_scenes: true\n",
            r"conditions\.nav\.split_scenes must be true or false, and true needs n_scenes",
        ),
        (
            lambda t: t + "    split_scenes: true\n    n_scenes: 1\n",
            r"conditions\.nav\.n_scenes: 1 scenes cannot be split over 2 seeds",
        ),
        (lambda t: t.replace("n_scenes: 4", "n_scenes: 0"), r"scene_sets\.heldout\.n_scenes must be > 0"),
        (lambda t: t + "    n_scenes: all\n", r"conditions\.nav\.n_scenes must be a positive integer"),
        (lambda t: t + "baselines: {velocity: [obst]}\n", r"baselines\.velocity: no condition 'obst'"),
        (lambda t: t + "media: [{file: a.mp4, caption: c}]\n", r"media\[0\]\.command is missing"),
        (
            lambda t: t + "paths: [{condition: nav, set: standard, scenes: [6]}]\n",
            r"paths\[0\]\.scenes: scene indices 0\.\.5 of set 'standard', got \[6\]",
        ),
        (
            lambda t: t + "thesis: [{question: q, thesis: t, figures: [{label: s, condition: nav, metric: wins}]}]\n",
            r"thesis\[0\]\.figures\[0\]\.metric: 'wins' is not one of",
        ),
        (
            lambda t: (
                t + "thesis: [{question: q, thesis: t, figures: [{label: s, condition: nav, metric: success, "
                "target: 'about 1'}]}]\n"
            ),
            r"thesis\[0\]\.figures\[0\]\.target: expected",
        ),
    ],
)
def test_bad_plan_fails_naming_the_key(tmp_path, edit, message):
    with pytest.raises(rp.PlanError, match=message):
        rp.load_plan(_plan(tmp_path, edit(BASE)))


def test_select_and_training_commands(tmp_path, capsys):
    plan = rp.load_plan()
    assert all(c.backend == "pymunk" for c in rp.select(plan, "2d"))
    assert {c.name for c in rp.select(plan, "2d") if not c.policies} == {
        "2d_nav",
        "2d_obst",
        "2d_nav_noise",
        "2d_obst_beta",
        "2d_obst_beta_long",
        "2d_obst_beta_tuned",
        "2d_obst_beta_7m",
        "2d_obst_beta_10m",
        "2d_obst_beta_hint",
        "2d_obst_beta_10m_noise",
        "2d_obst_beta_10m_odometry",
        "c2d_obst_beta",
        "quickstart",
        "quickstart_beta",
    }
    assert {c.backend for c in rp.select(plan, "3d")} == {"mujoco", "dm_control", "pybullet"}
    with pytest.raises(rp.PlanError, match=r"only=4d: '4d' is neither 2d, 3d, matrix, zoo nor a condition"):
        rp.select(plan, "4d")
    trained = rp.select(plan, "zoo")  # each condition that ships policies of its own, none evaluating another's
    assert {"2d_nav", "mj_nav", "pb_obst_beta_rand"} <= {c.name for c in trained}
    assert all(c.policies is None and c.shipped for c in trained)
    assert len(trained) == sum(1 for c in plan.conditions.values() if c.policies is None and c.shipped)

    runs = tmp_path / "runs"
    commands = rp.train_commands(plan, rp.select(plan, "mj_nav"), runs, None)
    # the parent condition first (its 5 seeds), then the fine-tunes from the same seed's parent run
    assert [c[-1] for c in commands] == [f"hydra.run.dir={runs}/2d_nav/seed{s}" for s in range(5)] + [
        f"hydra.run.dir={runs}/mj_nav/seed{s}" for s in range(3)
    ]
    assert commands[5][:2] == ["footsim-train", "backend=mujoco"]
    assert f"init_from={runs}/2d_nav/seed0" in commands[5] and "seed=0" in commands[5]
    multirun = rp.train_commands(plan, rp.select(plan, "2d_nav_noise"), runs, "slurm")
    assert multirun[1][:3] == ["footsim-train", "-m", "+launcher=slurm"]
    assert "seed=0,1,2,3,4" in multirun[1] and f"init_from={runs}/2d_nav/seed${{seed}}" in multirun[1]
    assert multirun[1][-2:] == [f"hydra.sweep.dir={runs}/2d_nav_noise", "hydra.sweep.subdir=seed${seed}"]

    (runs / "2d_nav" / "seed0" / "eval").mkdir(parents=True)
    (runs / "2d_nav" / "seed0" / "eval" / "summary.json").write_text("{}")
    reproduce_main(["train=true", "only=2d_nav", f"runs_dir={runs}", "dry_run=true", f"zoo={tmp_path / 'zoo'}"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("done already: footsim-train +experiment=thesis_2d seed=0")
    assert out[1] == f"footsim-train +experiment=thesis_2d seed=1 hydra.run.dir={runs}/2d_nav/seed1"
    assert len(out) == 5 and not (tmp_path / "zoo").exists()  # a dry run trains and adds nothing


def test_footsim_reproduce_alone_checks_each_zoo_policy_on_the_standard_set(tmp_path):
    plan = rp.load_plan()
    only, sets = rp.scope(plan, None, None, everything=False)
    assert (only, sets) == ("zoo", ["standard"])
    jobs, missing = rp.plan_jobs(plan, rp.select(plan, only), zoo.zoo_dir(), None, sets, True)
    assert not missing and {j.scene_set for j in jobs} == {"standard"}
    policies = {j.name for j in jobs if j.kind == "policy"}
    assert policies == set(zoo.names())  # every shipped policy, each once, in its own condition
    assert all(j.condition == zoo.load_index()["entries"][j.name]["condition"] for j in jobs if j.kind == "policy")
    # the baselines under those conditions, and each baseline under at least one of them (the ones under
    # a condition that judges zoo policies another way, e.g. 2d_obst_beta_10m_thesis_collision, are kept)
    own = {c.name for c in rp.select(plan, only)}
    baselines = {(j.condition, j.name) for j in jobs if j.kind == "baseline"}
    assert baselines == {(c, b) for b, conds in plan.baselines.items() for c in conds if c in own}
    assert {b for _, b in baselines} == set(plan.baselines)
    # all=true: every condition on every set; only= or sets= alone: as given
    assert rp.scope(plan, None, None, everything=True) == (None, None)
    assert rp.scope(plan, "mj_nav", None, everything=False) == ("mj_nav", None)
    assert rp.scope(plan, None, ["heldout"], everything=False) == (None, ["heldout"])
    with pytest.raises(rp.PlanError, match="all=true re-evaluates every condition .* drop only= and sets="):
        rp.scope(plan, "2d", None, everything=True)
    with pytest.raises(SystemExit, match="drop only= and sets="):
        reproduce_main(["all=true", "sets=standard", f"out={tmp_path}", f"page={tmp_path / 'p.md'}"])
    # a plan without a reproduce: scope re-evaluates everything
    bare = rp.load_plan(_plan(tmp_path, BASE))
    assert rp.scope(bare, None, None, everything=False) == (None, None)


def test_jobs_default_to_the_usable_cores():
    assert parse_args([])["jobs"] == len(os.sched_getaffinity(0))
    assert parse_args(["jobs=3"])["jobs"] == 3
    with pytest.raises(SystemExit, match="jobs must be > 0, got 0"):
        parse_args(["jobs=0"])
    with pytest.raises(SystemExit, match="jobs must be an integer, got 'many'"):
        parse_args(["jobs=many"])


def test_backend_settings_evaluate_the_study_at_other_physics(tmp_path):
    pytest.importorskip("mujoco")
    assert parse_args(["backends.mujoco.physics_dt=0.001"])["backends"] == {"mujoco": {"physics_dt": 0.001}}
    with pytest.raises(SystemExit, match=r"backends\.mujoco: expected backends\.BACKEND\.KEY=VALUE"):
        parse_args(["backends.mujoco=1"])
    with pytest.raises(rp.PlanError, match=r"backends\.mujoco: backend mujoco: unknown key\(s\) \['physics_dtt'\]"):
        rp.check_backend_settings({"mujoco": {"physics_dtt": 0.001}})
    with pytest.raises(rp.PlanError, match=r"backends\.mujoko: unknown backend 'mujoko'"):
        rp.check_backend_settings({"mujoko": {"physics_dt": 0.001}})

    plan = rp.load_plan()
    settings = {"mujoco": {"physics_dt": 0.0005}}
    jobs, _ = rp.plan_jobs(plan, rp.select(plan, "mj_nav"), zoo.zoo_dir(), None, ["standard"], True, settings)
    assert jobs and all(j.backend_settings == (("physics_dt", 0.0005),) for j in jobs)
    policy = next(j for j in jobs if j.kind == "policy")
    baseline = next(j for j in jobs if j.kind == "baseline")
    on_mujoco = next(
        j
        for j in rp.plan_jobs(
            plan, rp.select(plan, "2d_nav_on_mujoco"), zoo.zoo_dir(), None, ["standard"], False, settings
        )[0]
    )  # a 2D policy on MuJoCo
    # the policy recorded 2 ms, the baseline and the 2D policy get the preset's 1 ms; with the setting
    # every one runs at 0.5 ms
    for job, dt in (
        (policy, 0.0005),
        (baseline, 0.0005),
        (on_mujoco, 0.0005),
        (dataclasses.replace(policy, backend_settings=()), 0.002),
        (dataclasses.replace(baseline, backend_settings=()), 0.001),
        (dataclasses.replace(on_mujoco, backend_settings=()), 0.001),
    ):
        env, _ = rp.job_env_and_controller(job, zoo.zoo_dir())
        try:
            assert env.backend.physics_dt == pytest.approx(dt), job
        finally:
            env.close()

    # evaluations at other physics never replace the data files' own
    out = tmp_path / "results"
    out.mkdir()
    shutil.copy(Path(__file__).resolve().parents[1] / "docs" / "results" / "runs.csv", out / "runs.csv")
    before = (out / "runs.csv").read_text()
    with pytest.raises(SystemExit, match=r"holds mj_nav/standard/.* give out=DIR and page=FILE elsewhere"):
        args = ["only=mj_nav", "sets=standard", "backends.mujoco.physics_dt=0.0005"]
        reproduce_main([*args, f"out={out}", f"page={tmp_path / 'R.md'}"])
    assert (out / "runs.csv").read_text() == before and not (tmp_path / "R.md").exists()


def test_the_plans_backend_settings_go_into_its_trainings_and_evaluations(tmp_path):
    plan = rp.load_plan()
    assert plan.backends == {"mujoco": {"physics_dt": 0.002}, "dm_control": {"physics_dt": 0.002}}
    (command,) = rp.train_commands(plan, [plan.conditions["mj_nav"]], tmp_path, None)[5:6]
    assert command[command.index("agent.log_std_init=-1.0") + 1] == "backend.physics_dt=0.002"
    assert fconf.compose("config", plan.train_overrides(plan.conditions["mj_nav"])).backend.physics_dt == 0.002
    assert not any("physics_dt" in o for o in plan.train_overrides(plan.conditions["2d_nav"]))
    # every evaluation on MuJoCo or dm-control runs at them, the CLI's backends.* over them
    conds = rp.select(plan, "mj_nav,mj_nav_on_dm_control,2d_nav_on_mujoco,2d_nav_on_pybullet")
    evaluated_at = {"mujoco": {"physics_dt": 0.002}, "dm_control": {"physics_dt": 0.002}}
    jobs, _ = rp.plan_jobs(plan, conds, zoo.zoo_dir(), None, ["standard"], True, evaluated_at)
    assert {(j.backend, j.backend_settings) for j in jobs} == {
        ("mujoco", (("physics_dt", 0.002),)),
        ("dm_control", (("physics_dt", 0.002),)),
        ("pybullet", ()),
    }
    assert "The study trains and evaluates at these backend settings" in rp.render_page(
        plan, [], [], zoo.zoo_dir(), "d"
    )
    # a plan's own line that sets the key keeps it
    pinned = dataclasses.replace(plan.conditions["mj_nav"], train=("backend=mujoco", "backend.physics_dt=0.004"))
    assert plan.train_overrides(pinned) == ["backend=mujoco", "backend.physics_dt=0.004"]
    with pytest.raises(rp.PlanError, match=r"backends\.mujoco: backend mujoco: unknown key\(s\) \['dt'\]"):
        rp.load_plan(_plan(tmp_path, BASE + "backends: {mujoco: {dt: 0.002}}\n"))


@pytest.mark.parametrize(
    "scope, message",
    [
        ("{only: 4d}", r"reproduce\.only: only=4d: '4d' is neither"),
        ("{sets: [test]}", r"reproduce\.sets: a list of the plan's scene sets"),
        ("{only: zoo, every: true}", r"reproduce: unknown key\(s\) \['every'\]"),
        ("[zoo]", r"reproduce must be a mapping"),
    ],
)
def test_a_bad_reproduce_scope_fails_naming_the_key(tmp_path, scope, message):
    with pytest.raises(rp.PlanError, match=message):
        rp.load_plan(_plan(tmp_path, BASE + f"reproduce: {scope}\n"))


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def small_study(tmp_path_factory, tiny_runs):
    """A zoo with two tiny runs (seeds 0 and 1) as the plan's entries nav_s0 and nav_s1."""
    root = tmp_path_factory.mktemp("study")
    for seed in (0, 1):
        run = tiny_runs(f"study_seed{seed}", f"seed={seed}")
        zoo.add(run, f"nav_s{seed}", root / "zoo", condition="nav", check_scenes=2)
    plan = _plan(
        root,
        BASE
        + """
baselines: {velocity: [nav]}
tables: [{title: Tiny, conditions: [nav]}]
paths: [{condition: nav, set: standard, scenes: [1]}]
thesis:
  - question: Obstacle-free
    thesis: success 1.0
    figures: [{label: success, condition: nav, metric: success, target: ">= 0.99"}]
""",
    )
    return root, plan


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_reproduce_end_to_end(small_study, tmp_path, capsys):
    root, plan = small_study
    out, page = tmp_path / "results", tmp_path / "RESULTS.md"
    args = [f"plan={plan}", f"zoo={root / 'zoo'}", f"out={out}", f"page={page}", "shard_size=1", "progress=false"]
    reproduce_main(args)
    assert "no data files before" in capsys.readouterr().out
    runs = _rows(out / "runs.csv")
    assert [(r["scene_set"], r["kind"], r["name"], r["n_scenes"]) for r in runs] == [
        ("heldout", "baseline", "velocity", "4"),
        ("heldout", "policy", "nav_s0", "4"),
        ("heldout", "policy", "nav_s1", "4"),
        ("standard", "baseline", "velocity", "6"),
        ("standard", "policy", "nav_s0", "6"),
        ("standard", "policy", "nav_s1", "6"),
    ]

    # a policy row is what footsim-eval gives for that zoo entry on the same scenes
    env = {**os.environ, "FOOTSIM_ZOO": str(root / "zoo")}
    ev = tmp_path / "ev"
    proc = subprocess.run(
        ["footsim-eval", "run=zoo:nav_s1", "n_scenes=6", "plot=false", f"hydra.run.dir={ev}"],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((ev / "summary.json").read_text())
    row = runs[5]
    for metric in ("success", "timeout", "collision", "success_time_mean", "success_steps_mean"):
        expected = summary[metric]
        assert (row[metric] == "") if expected is None else float(row[metric]) == pytest.approx(expected), metric

    # conditions.csv: the mean over the two seeds and the IQM (trim_mean cuts nothing of two values)
    stats = {(r["scene_set"], r["name"], r["metric"]): r for r in _rows(out / "conditions.csv")}
    for metric in ("success", "timeout"):
        seeds = [float(runs[4][metric]), float(runs[5][metric])]
        cell = stats[("standard", "policy", metric)]
        assert float(cell["mean"]) == pytest.approx(sum(seeds) / 2) and float(cell["iqm"]) == pytest.approx(
            sum(seeds) / 2
        )
        assert cell["n"] == "2"
        if seeds[0] == seeds[1]:
            assert float(cell["ci_low"]) == float(cell["ci_high"]) == seeds[0]
        else:  # two values: the resample means are min, mid, max; the 95 % interval spans min..max
            assert (float(cell["ci_low"]), float(cell["ci_high"])) == (min(seeds), max(seeds))
    assert (
        stats[("standard", "velocity", "success")]["n"] == "1"
        and stats[("standard", "velocity", "success")]["ci_low"] == ""
    )

    text = page.read_text()
    assert "## Tiny" in text and "footsim-reproduce only=nav" in text
    assert "standard: seed 20220101, 6 scenes" in text and "heldout: seed 7, 4 scenes" in text
    assert "nav_s0, nav_s1 (trained at commit" in text and "| Obstacle-free | success 1.0 |" in text
    assert (out / "success_by_seed.png").is_file()
    # the path plot of scene 1: nav_s0 and the velocity baseline, each the episode the evaluation ran
    assert f"`{os.path.relpath(out)}/paths_nav_standard_1.png`" in text and "policy nav_s0, velocity" in text
    assert (out / "paths_nav_standard_1.png").stat().st_size > 0
    from footsim.planners.report import episode_path
    from footsim.rl.evaluate import evaluate
    from footsim.tasks.scenes import sample_scenes

    loaded = rp.load_plan(plan)
    for job in rp.path_jobs(loaded, loaded.paths[0], root / "zoo"):
        env, controller = rp.job_env_and_controller(job, root / "zoo")
        scenes = sample_scenes(env.sampler, 6, 20220101)
        outcome, footsteps, navs = episode_path(env, controller, scenes[1], seed=1)
        (record,) = evaluate(env, controller, scenes, seed=0, progress=False, indices=[1])
        assert (outcome, len(navs) - 1) == (record["outcome"], record["steps"]), job.name
        assert len(footsteps) == 2 + 2 * record["steps"]  # the standing feet, then two per double step
        env.close()

    # a block of a set (a split matrix cell) runs the same episodes as the whole set does there
    job = rp.Job("nav", "standard", "policy", "nav_s1", 1, "pymunk", "nav", "none", 20220101, 6)
    whole = rp.evaluate_shard(job, 0, 6, str(root / "zoo"))
    block = dataclasses.replace(job, first_scene=2, n_scenes=3)
    assert rp.evaluate_shard(block, 0, 3, str(root / "zoo")) == whole[2:5]
    assert [r["scene"] for r in whole[2:5]] == [2, 3, 4]
    # a shard on the env a worker kept from the job's earlier shards runs what a fresh env runs
    rp.release_built()
    assert rp.evaluate_shard(job, 0, 2, str(root / "zoo")) == whole[:2]
    kept = rp._BUILT[0][2]
    assert rp.evaluate_shard(job, 2, 6, str(root / "zoo")) == whole[2:]
    assert rp._BUILT[0][2] is kept  # the same env object: reused, not rebuilt
    rp.release_built()

    # again, in two worker processes: the same cells (episode i keeps scene i and seed i in any shard)
    before = (out / "runs.csv").read_text()
    reproduce_main([*args, "jobs=2", "strict=true"])
    assert "no cell differs" in capsys.readouterr().out
    assert (out / "runs.csv").read_text() == before

    # the plan's reproduce: scope: only the standard set is re-evaluated, the held-out rows are kept
    scoped = tmp_path / "scoped.yaml"
    scoped.write_text(Path(plan).read_text() + "reproduce: {only: zoo, sets: [standard]}\n")
    reproduce_main([*args[1:], f"plan={scoped}", "strict=true"])
    report = capsys.readouterr().out
    assert "evaluated 3 policies and baselines (18 episodes)" in report and "no cell differs" in report
    assert "3 of the data files' 6 evaluations were not re-evaluated by this selection" in report
    assert (out / "runs.csv").read_text() == before
    assert "`footsim-reproduce` alone re-evaluates `only=zoo sets=standard`" in page.read_text()
    reproduce_main(args)  # the page of the plan without a scope again
    capsys.readouterr()

    # a committed cell that the evaluation does not give back is reported, and strict=true fails
    lines = before.splitlines()
    cells = lines[5].split(",")
    cells[lines[0].split(",").index("success")] = "0.123"  # success of nav_s0 on the standard set
    lines[5] = ",".join(cells)
    (out / "runs.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(SystemExit) as exit_info:
        reproduce_main([*args, "only=nav", "sets=standard", "baselines=false", "strict=true"])
    assert exit_info.value.code == 1
    report = capsys.readouterr().out
    assert f"nav/standard/policy/nav_s0 success: 0.123 -> {float(runs[4]['success']):.6g}" in report
    assert (out / "runs.csv").read_text() == before  # rows not re-evaluated (held-out, baseline) are kept

    # a quick look on fewer scenes does not replace the full evaluations
    with pytest.raises(SystemExit, match=r"holds 6-scene evaluations .* n_scenes=3 would replace them"):
        reproduce_main([*args, "n_scenes=3"])
    assert (out / "runs.csv").read_text() == before


def test_reproduce_refuses_unknown_keys_and_sets(tmp_path):
    with pytest.raises(SystemExit, match="unknown key 'scenes'"):
        reproduce_main(["scenes=10"])
    with pytest.raises(SystemExit, match="jobs must be > 0"):
        reproduce_main(["jobs=0"])
    with pytest.raises(SystemExit, match=r"no scene set 'test'"):
        reproduce_main(["sets=test", f"out={tmp_path}", f"page={tmp_path / 'p.md'}", f"zoo={tmp_path}"])


def test_differences_names_each_changed_cell():
    old = [{"condition": "a", "scene_set": "s", "kind": "policy", "name": "x", "success": "1.0", "fall": ""}]
    new = [{"condition": "a", "scene_set": "s", "kind": "policy", "name": "x", "success": 0.5, "fall": math.nan}]
    assert rp.differences(old, new, rp.KEY, ("success", "fall")) == ["a/s/policy/x success: 1 -> 0.5"]
    added = [*new, {"condition": "b", "scene_set": "s", "kind": "policy", "name": "y", "success": 1.0, "fall": 0.0}]
    assert rp.differences(old, added, rp.KEY, ("success",))[-1] == "b/s/policy/y: new row"


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_reproduce_refuses_a_stale_zoo_entry_before_evaluating(small_study, tmp_path):
    import shutil

    root, plan = small_study
    shutil.copytree(root / "zoo", tmp_path / "zoo")
    config = tmp_path / "zoo" / "nav_s1" / "config.yaml"
    config.write_text(config.read_text().replace("task:\n", "task:\n  goal_radius: 0.1\n", 1))
    args = [f"plan={plan}", f"zoo={tmp_path / 'zoo'}", f"out={tmp_path / 'out'}", f"page={tmp_path / 'p.md'}"]
    with pytest.raises(
        SystemExit, match=r"zoo entry 'nav_s1' no longer composes .* task: unknown key\(s\) \['goal_radius'\]"
    ):
        reproduce_main(args)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_an_entry_trained_from_another_policy_than_its_plan_parent_is_refused(small_study, tmp_path):
    """A child entry records its parent's weights digest; one whose digest is not the plan parent's
    entry of the same seed (here: seed 1 fine-tuned from seed 0's parent) is named before any evaluation."""
    import shutil

    root, _ = small_study
    shutil.copytree(root / "zoo", tmp_path / "zoo")
    entries = tmp_path / "zoo"
    parents = {s: zoo.weights_digest(entries / f"nav_s{s}" / "model.zip") for s in (0, 1)}
    assert parents[0] != parents[1]  # two seeds, two networks
    index = json.loads((entries / "index.json").read_text())
    for seed, parent_seed in ((0, 0), (1, 0)):
        shutil.copytree(entries / f"nav_s{seed}", entries / f"ft_s{seed}")
        prov_path = entries / f"ft_s{seed}" / "provenance.json"
        prov = json.loads(prov_path.read_text())
        prov["parent"] = {"zoo": None, "run": "elsewhere", "weights_sha256": parents[parent_seed]}
        prov_path.write_text(json.dumps(prov))
        index["entries"][f"ft_s{seed}"] = {**index["entries"][f"nav_s{seed}"], "condition": "ft"}
    (entries / "index.json").write_text(json.dumps(index))
    plan = rp.load_plan(
        _plan(tmp_path, BASE + "  ft:\n    backend: pymunk\n    task: nav\n    seeds: [0, 1]\n    parent: nav\n")
    )
    conditions = list(plan.conditions.values())
    problems = rp.lineage_problems(plan, conditions, entries)
    assert problems == [
        "ft_s1 was trained from other weights than zoo:nav_s1 (condition ft's parent nav, seed 1); "
        "retrain it (footsim-reproduce train=true only=ft)"
    ]
    with pytest.raises(zoo.ZooError, match="ft_s1 was trained from other weights than zoo:nav_s1"):
        rp.plan_jobs(plan, conditions, entries, None, ["standard"], baselines=False)
    prov_path = entries / "ft_s0" / "provenance.json"
    prov_path.write_text(json.dumps({**json.loads(prov_path.read_text()), "parent": {"zoo": None}}))
    assert rp.lineage_problems(plan, conditions, entries)[0] == (
        "ft_s0: its provenance records no parent weights, so zoo:nav_s0 cannot be checked"
    )


MATRIX = """
  obst:
    title: tiny obstacles
    backend: pymunk
    task: nav_obstacles
    seeds: [0]
    train: [task=nav_obstacles]
  obst_on_mujoco:
    backend: mujoco
    task: nav_obstacles
    policies: obst
matrices:
  - title: With obstacles!
    task: nav_obstacles
    rows: {2D: obst}
    backends: [pymunk, mujoco]
    randomization: [none, default]
    n_scenes: 3
    sets: [standard]
    note: dm-control shares MuJoCo's column.
"""


def test_matrix_cells_reuse_the_plans_conditions_and_derive_the_rest(tmp_path):
    plan = rp.load_plan(_plan(tmp_path, BASE + MATRIX))
    (matrix,) = plan.matrices
    assert (matrix.slug, matrix.scene_set, matrix.note) == (
        "with_obstacles",
        "standard",
        "dm-control shares MuJoCo's column.",
    )
    assert matrix.cells == {
        ("2D", "pymunk", "none"): "obst",  # the trained condition itself
        ("2D", "pymunk", "default"): "obst_on_pymunk_dr_default",
        ("2D", "mujoco", "none"): "obst_on_mujoco",  # the plan's own condition
        ("2D", "mujoco", "default"): "obst_on_mujoco_dr_default",
    }
    derived = plan.conditions["obst_on_mujoco_dr_default"]
    assert (derived.source, derived.backend, derived.task, derived.randomization) == (
        "obst",
        "mujoco",
        "nav_obstacles",
        "default",
    )
    assert (derived.n_scenes, derived.sets) == (3, ("standard",))
    assert derived.split_scenes and not plan.conditions["obst_on_mujoco"].split_scenes
    assert plan.conditions["obst_on_pymunk_dr_default"].n_scenes is None  # 2D cells take the whole set
    assert {c.name for c in rp.select(plan, "matrix")} == set(matrix.cells.values())
    # a derived cell is evaluated on its sets only, under its randomization, by the row's zoo entries
    (tmp_path / "zoo").mkdir()
    jobs, missing = rp.plan_jobs(plan, [derived], tmp_path / "zoo", None, ["standard", "heldout"], False)
    assert jobs == [] and missing == ["obst_s0"]


def test_scene_blocks_split_a_cells_scenes_over_its_seeds():
    assert rp.scene_blocks(50, 1) == [(0, 50)]
    assert rp.scene_blocks(50, 5) == [(0, 10), (10, 10), (20, 10), (30, 10), (40, 10)]
    assert rp.scene_blocks(50, 3) == [(0, 17), (17, 17), (34, 16)]
    with pytest.raises(rp.PlanError, match="2 scenes cannot be split over 3 seeds"):
        rp.scene_blocks(2, 3)


def test_a_derived_3d_cell_spreads_its_scenes_over_the_rows_seeds(tmp_path, monkeypatch):
    plan = rp.load_plan(_plan(tmp_path, BASE + MATRIX.replace("seeds: [0]", "seeds: [0, 1]")))
    monkeypatch.setattr(rp.zoo, "names", lambda root: ["obst_s0", "obst_s1"])
    monkeypatch.setattr(rp.zoo, "check_config", lambda name, root: None)
    cells = [plan.conditions[c] for c in ("obst_on_mujoco_dr_default", "obst_on_mujoco")]
    jobs, missing = rp.plan_jobs(plan, cells, tmp_path, None, ["standard"], False)
    assert missing == []
    assert [(j.condition, j.name, j.first_scene, j.n_scenes) for j in jobs] == [
        ("obst_on_mujoco_dr_default", "obst_s0", 0, 2),  # 3 scenes in all: seed 0 takes scenes 0-1,
        ("obst_on_mujoco_dr_default", "obst_s1", 2, 1),  # seed 1 scene 2
        ("obst_on_mujoco", "obst_s0", 0, 6),  # the plan's own condition: the whole set for every seed
        ("obst_on_mujoco", "obst_s1", 0, 6),
    ]
    text = _plan(tmp_path, BASE + MATRIX.replace("seeds: [0]", "seeds: [0, 1, 2, 3]"))
    with pytest.raises(rp.PlanError, match=r"matrices\[0\]\.n_scenes: 3 scenes cannot be split over the 4 seeds"):
        rp.load_plan(text)

    # a cap per backend: the derived MuJoCo cell takes its own; pymunk is never capped
    per_backend = rp.load_plan(_plan(tmp_path, BASE + MATRIX.replace("n_scenes: 3", "n_scenes: {mujoco: 2}")))
    assert per_backend.conditions["obst_on_mujoco_dr_default"].n_scenes == 2
    assert per_backend.conditions["obst_on_mujoco_dr_default"].split_scenes
    assert per_backend.conditions["obst_on_pymunk_dr_default"].n_scenes is None
    with pytest.raises(rp.PlanError, match=r"matrices\[0\]\.n_scenes: \['pybullet'\] are not among"):
        rp.load_plan(_plan(tmp_path, BASE + MATRIX.replace("n_scenes: 3", "n_scenes: {pybullet: 2}")))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda t: t.replace("rows: {2D: obst}", "rows: {2D: obst_on_mujoco}"),
            r"rows\.2D: 'obst_on_mujoco' is not a trained",
        ),
        (
            lambda t: t.replace("    sets: [standard]\n", "    sets: [test]\n"),
            r"matrices\[0\]\.sets: a list of the plan's scene",
        ),
        (lambda t: t.replace("    task: nav_obstacles\n    rows", "    rows"), r"matrices\[0\]\.task is missing"),
        (lambda t: t + "    colour: red\n", r"matrices\[0\]: unknown key\(s\) \['colour'\]"),
    ],
)
def test_bad_matrix_fails_naming_the_key(tmp_path, edit, message):
    with pytest.raises(rp.PlanError, match=message):
        rp.load_plan(_plan(tmp_path, edit(BASE + MATRIX)))


def _policy_row(condition: str, seed: int, success: float, n_scenes: int = 500) -> dict:
    """A runs.csv row of one policy seed on the standard set (the columns the page reads)."""
    return {
        "condition": condition,
        "scene_set": "standard",
        "kind": "policy",
        "seed": str(seed),
        "success": str(success),
        "n_scenes": str(n_scenes),
    }


def _success(mean: float, n: int, low: float = math.nan, high: float = math.nan) -> dict:
    return {
        "mean": repr(mean),
        "n": str(n),
        "ci_low": "" if math.isnan(low) else repr(low),
        "ci_high": "" if math.isnan(high) else repr(high),
    }


def test_matrix_page_and_the_retention_target(tmp_path):
    """The page's matrix: each cell's mean and interval (or its one seed), and what a 3D-trained row
    keeps on the other 3D backend, checked against the 0.9 target only for a randomized row."""
    body = (
        BASE.replace("    backend: pymunk\n", "    backend: mujoco\n    randomization: default\n").replace(
            "train: [train.total_timesteps=128]", "train: [backend=mujoco, randomization=default]"
        )
        + """
matrices:
  - title: nav
    task: nav
    rows: {"MuJoCo, randomized": nav}
    backends: [pymunk, mujoco, pybullet]
    randomization: [default]
"""
    )
    plan = rp.load_plan(_plan(tmp_path, body))
    (matrix,) = plan.matrices
    cells = {b: matrix.cells[("MuJoCo, randomized", b, "default")] for b in matrix.backends}
    assert cells["mujoco"] == "nav"
    cstats = {
        (cells["pymunk"], "standard", "policy", "policy", "success"): _success(1.0, 2, 1.0, 1.0),
        (cells["mujoco"], "standard", "policy", "policy", "success"): _success(0.8, 2, 0.7, 0.9),
        (cells["pybullet"], "standard", "policy", "policy", "success"): _success(0.68, 1),
    }
    text = "\n".join(rp.matrix_lines(plan, matrix, cstats, "docs/results"))
    assert (
        "| MuJoCo, randomized (nav, 2 seeds) | 1.000 [1.000, 1.000] | 0.800 [0.700, 0.900] | 0.680 (1 seed) |" in text
    )
    # 0.68 / 0.8 = 0.85 < 0.9; without runs.csv rows the episodes and the range are unknown
    assert "| MuJoCo, randomized | default | 0.800 [0.700, 0.900] | pybullet | — / — | 0.85 | — | not met |" in text
    cstats[(cells["pybullet"], "standard", "policy", "policy", "success")] = _success(0.76, 1)
    text = "\n".join(rp.matrix_lines(plan, matrix, cstats, "docs/results"))
    assert "| pybullet | — / — | 0.95 | — | met |" in text  # 0.76 / 0.8

    # with runs.csv rows: 2 seeds x 50 own episodes (40 + 40 successes), 25 elsewhere (19 successes)
    runs = [
        _policy_row(cells["mujoco"], 0, 0.8, 50),
        _policy_row(cells["mujoco"], 1, 0.8, 50),
        _policy_row(cells["pybullet"], 0, 0.76, 25),
    ]

    def wilson(k, n, z=1.959963984540054):  # the textbook score interval, by hand
        p = k / n
        centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
        return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)

    (own_low, own_high), (on_low, on_high) = wilson(80, 100), wilson(19, 25)
    text = "\n".join(rp.matrix_lines(plan, matrix, cstats, "docs/results", runs))
    expected_range = f"[{on_low / own_high:.2f}, {on_high / own_low:.2f}]"
    assert f"| pybullet | 100 / 25 | 0.95 | {expected_range} | met |" in text
    rp.plot_matrix(tmp_path / "m.png", matrix, cstats)
    assert (tmp_path / "m.png").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_a_job_runs_under_its_randomization(small_study):
    """A policy job and a baseline job build their env with the job's randomization preset."""
    root, plan = small_study
    common = dict(backend="pymunk", task="nav", noise="none", scenes_seed=1, n_scenes=2)
    for kind, name in (("policy", "nav_s0"), ("baseline", "velocity")):
        for rand in ("none", "default"):
            job = rp.Job("c", "standard", kind, name, 0, randomization=rand, **common)
            env, _ = rp.job_env_and_controller(job, root / "zoo")
            assert env.config["randomization"]["name"] == rand, (kind, rand)
            env.close()


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_a_policy_trained_on_other_scenes_is_evaluated_on_the_task_presets_scenes(small_study, tmp_path):
    """A zoo policy trained with goals drawn nearer (task.scenes.goal_sigma_xy 0.3) runs the
    standard set of the thesis sampler: the same scenes as the baseline's."""
    import shutil

    from omegaconf import OmegaConf

    from footsim.tasks.scenes import sample_scenes

    root, _ = small_study
    zoo_root = tmp_path / "zoo"
    shutil.copytree(root / "zoo", zoo_root)
    cfg = OmegaConf.load(zoo_root / "nav_s0" / "config.yaml")
    cfg.task.scenes.goal_sigma_xy = 0.3
    OmegaConf.save(cfg, zoo_root / "nav_s0" / "config.yaml")
    common = dict(seed=0, backend="pymunk", task="nav", noise="none", scenes_seed=20220101, n_scenes=3)
    sets = []
    for kind, name in (("policy", "nav_s0"), ("baseline", "velocity")):
        env, _ = rp.job_env_and_controller(rp.Job("c", "standard", kind, name, **common), zoo_root)
        sets.append([(s.goal.x, s.goal.y, s.goal.theta) for s in sample_scenes(env.sampler, 3, 20220101)])
        assert env.sampler.goal_sigma_xy == 1.0
        env.close()
    assert sets[0] == sets[1]


def test_steps_to_reach_reads_the_zoo_learning_curves(tmp_path):
    """The fine-tune's mean training curve first reaches the from-scratch run's final success rate at
    a hand-interpolated step."""
    body = (
        BASE
        + """
  scratch:
    backend: pymunk
    task: nav
    seeds: [0]
    train: []
thesis:
  - question: q
    thesis: t
    figures: [{label: steps, condition: nav, reaches: scratch}]
"""
    )
    plan = rp.load_plan(_plan(tmp_path, body))
    root = tmp_path / "zoo"
    curves = {  # step: success rate
        "nav_s0": [(0, 0.0), (100, 0.4), (200, 0.8)],
        "nav_s1": [(0, 0.2), (100, 0.6), (200, 1.0)],
        "scratch_s0": [(0, 0.0), (300, 0.5)],
    }
    for name, points in curves.items():
        (root / name).mkdir(parents=True)
        lines = ["step,success_rate"] + [f"{s},{r}" for s, r in points]
        (root / name / zoo.CURVE_FILE).write_text("\n".join(lines) + "\n")
    (root / "index.json").write_text(json.dumps({"format": 1, "entries": {n: {} for n in curves}}))
    # mean curve 0.1 + 0.004 * step reaches 0.5 at step 100 (on the 100-point grid over 0..200: 101.01)
    value, text = rp.figure_value({}, plan.thesis[0]["figures"][0], plan, root)
    assert value == pytest.approx(200 * 50 / 99)
    assert text == f"nav reaches scratch's final training success (0.50 at 300 steps) after {200 * 50 / 99:.0f} steps"
    with pytest.raises(rp.PlanError, match=r"thesis\[0\]\.figures\[0\]\.reaches: no condition 'nope'"):
        rp.load_plan(_plan(tmp_path, body.replace("reaches: scratch", "reaches: nope")))


def test_thesis_table_states_each_target_with_its_figure_and_lists_what_was_tried_below(tmp_path):
    body = (
        BASE
        + """
thesis:
  - question: Obstacle-free
    thesis: success 1.0
    figures:
      - {label: "success", condition: nav, metric: success, target: ">= 0.99"}
      - {label: "fall", condition: nav, metric: fall, target: "<= 0.01"}
    tried: [first attempt, second attempt]
"""
    )
    plan = rp.load_plan(_plan(tmp_path, body))
    cstats = {
        ("nav", "standard", "policy", "policy", "success"): {"mean": "0.987", "ci_low": "0.97", "ci_high": "1.0"},
        ("nav", "standard", "policy", "policy", "fall"): {"mean": "0.01", "ci_low": "0.0", "ci_high": "0.03"},
    }
    lines = rp.thesis_table(plan, cstats, tmp_path)
    row = next(line for line in lines if line.startswith("| Obstacle-free |"))
    # 0.987 < 0.99: not met; 0.01 <= 0.01: met (the boundary counts)
    assert row.endswith("| nav success ≥ 0.99: not met (0.987); nav fall ≤ 0.01: met (0.010) |")
    tried = lines[lines.index("### What was tried where a target is not met") :]
    assert tried[2:6] == ["**Obstacle-free**", "", "* first attempt", "* second attempt"]
    with pytest.raises(rp.PlanError, match=r"thesis\[0\]\.tried: expected a text or a list of texts"):
        rp.load_plan(_plan(tmp_path, body.replace("[first attempt, second attempt]", "{a: 1}")))


def test_a_change_between_conditions_with_the_same_seeds_carries_the_interval_of_its_per_seed_differences():
    """``minus:`` with runs.csv rows: the mean of the per-seed differences and scipy's percentile
    bootstrap of them (computed here directly); no interval when the seed sets differ."""
    from scipy.stats import bootstrap

    parent, child = [0.96, 0.95, 0.97, 0.94, 0.96], [0.90, 0.93, 0.91, 0.90, 0.95]
    runs = [_policy_row("noisefree", k, v) for k, v in enumerate(parent)]
    runs += [_policy_row("noise", k, v) for k, v in enumerate(child)]
    cstats = {
        (c, "standard", "policy", "policy", "success"): {"mean": str(sum(v) / 5), "ci_low": "", "ci_high": ""}
        for c, v in (("noisefree", parent), ("noise", child))
    }
    fig = {"label": "change", "condition": "noise", "metric": "success", "minus": "noisefree"}
    value, text = rp.figure_value(cstats, fig, runs=runs)
    diffs = [c - p for c, p in zip(child, parent, strict=True)]
    ci = bootstrap((diffs,), np.mean, n_resamples=10_000, method="percentile", rng=np.random.default_rng(0))
    low, high = ci.confidence_interval
    assert value == pytest.approx(-0.038)  # (4.59 - 4.78) / 5
    assert text == f"-0.038 [{low:+.3f}, {high:+.3f}] over 5 paired seeds (noise − noisefree)"
    assert low < -0.038 < high
    value, text = rp.figure_value(cstats, fig, runs=runs[:-1])  # the noise condition lacks seed 4
    assert text == "-0.038 (noise − noisefree)"


def test_a_matrix_cell_is_never_a_condition_that_acts_or_judges_otherwise(tmp_path):
    """A plan condition on the cell's backend that takes the Beta mean or its own backend settings
    is not the row's policy as trained: the cell is derived instead."""
    body = BASE + MATRIX.replace("  obst_on_mujoco:\n", "  obst_mean_on_mujoco:\n    beta_action: mean\n").replace(
        "matrices:",
        "  obst_nav_distance:\n    backend: pymunk\n    task: nav_obstacles\n    policies: obst\n"
        "    randomization: default\n    backend_settings: {collision_model: nav_distance}\nmatrices:",
    )
    (matrix,) = rp.load_plan(_plan(tmp_path, body)).matrices
    assert matrix.cells[("2D", "mujoco", "none")] == "obst_on_mujoco"
    assert matrix.cells[("2D", "pymunk", "default")] == "obst_on_pymunk_dr_default"


def test_rows_the_plan_no_longer_has_are_dropped(tmp_path):
    plan = rp.load_plan(_plan(tmp_path, BASE + MATRIX))
    rows = [
        {"condition": "nav", "scene_set": "heldout", "kind": "policy", "name": "nav_s0"},
        {"condition": "obst_on_mujoco_dr_default", "scene_set": "standard", "kind": "policy", "name": "obst_s0"},
        {"condition": "obst_on_mujoco_dr_default", "scene_set": "heldout", "kind": "policy", "name": "obst_s0"},
        {"condition": "gone", "scene_set": "standard", "kind": "baseline", "name": "velocity"},
        {"condition": "nav", "scene_set": "standard", "kind": "policy", "name": "nav_s2"},  # seeds: [0, 1]
        {"condition": "nav", "scene_set": "standard", "kind": "baseline", "name": "velocity"},  # no baselines
    ]
    kept, dropped = rp.planned_rows(plan, rows)
    assert kept == rows[:2]  # a matrix cell is evaluated on its matrix's sets only
    assert dropped == [
        "obst_on_mujoco_dr_default/heldout/policy/obst_s0",
        "gone/standard/baseline/velocity",
        "nav/standard/policy/nav_s2",
        "nav/standard/baseline/velocity",
    ]


def test_the_page_says_how_a_split_condition_covers_its_scenes(tmp_path):
    body = (
        BASE
        + """  nav_on_mujoco:
    backend: mujoco
    task: nav
    policies: nav
    n_scenes: 5
    split_scenes: true
    sets: [standard]
tables: [{title: Tiny, conditions: [nav, nav_on_mujoco]}]
thesis: []
"""
    )
    plan = rp.load_plan(_plan(tmp_path, body))

    def row(condition: str, seed: int, backend: str, first: int, n: int, success: float) -> dict:
        metrics = {m: 0.0 for m in rp.METRICS} | {"success": success, "success_time_mean": 3.0}
        info = dict(seed=seed, backend=backend, task="nav", noise="none", randomization="none")
        info |= dict(scenes_seed=20220101, first_scene=first, n_scenes=n)
        return {
            k: rp._text(v) for k, v in ({"condition": condition, "scene_set": "standard"} | info | metrics).items()
        } | {
            "kind": "policy",
            "name": f"nav_s{seed}",
        }

    runs = [
        row("nav", 0, "pymunk", 0, 6, 1.0),
        row("nav", 1, "pymunk", 0, 6, 1.0),
        row("nav_on_mujoco", 0, "mujoco", 0, 3, 2 / 3),  # 5 scenes over 2 seeds: 0-2 and 3-4
        row("nav_on_mujoco", 1, "mujoco", 3, 2, 0.5),
    ]
    cond_rows = [{k: rp._text(v) for k, v in r.items()} for r in rp.condition_rows(runs)]
    text = rp.render_page(plan, runs, cond_rows, tmp_path / "zoo", "docs/results")
    assert (
        "Scenes: standard: seed 20220101, 5 scenes in all, split over the seeds (nav_on_mujoco); "
        "standard: seed 20220101, 6 scenes." in text
    )
    (cell,) = [line for line in text.splitlines() if line.startswith("| nav_on_mujoco | standard | PPO | 2 |")]
    assert cell.split(" | ")[4].startswith(f"{(2 / 3 + 0.5) / 2:.3f}")  # the mean of the two seeds' blocks


STAGES = """  stage:
    backend: pymunk
    task: nav
    seeds: [0, 1]
    parent: nav
    shipped: false
    train: [train.total_timesteps=64]
  top:
    title: tiny, two stages on
    backend: pymunk
    task: nav
    seeds: [0, 1]
    parent: stage
    train: [train.total_timesteps=32]
"""


def test_a_training_stage_is_trained_and_listed_but_never_shipped_or_evaluated(tmp_path):
    plan = rp.load_plan(_plan(tmp_path, BASE + STAGES + "tables: [{title: Tiny, conditions: [top]}]\nthesis: []\n"))
    runs = tmp_path / "runs"
    commands = rp.train_commands(plan, rp.select(plan, "top"), runs, None)
    # nav's two seeds, then the stage's from them, then top's from the stage's
    assert [c[-1].rsplit("/", 2)[-2] for c in commands] == ["nav", "nav", "stage", "stage", "top", "top"]
    assert f"init_from={runs}/stage/seed1" in commands[-1]
    jobs, missing = rp.plan_jobs(plan, list(plan.conditions.values()), tmp_path / "zoo", None, ["standard"], True)
    assert {j.condition for j in jobs} == set() and "stage_s0" not in missing and "top_s0" in missing
    row = {"condition": "stage", "scene_set": "standard", "kind": "policy", "name": "stage_s0"}
    assert rp.planned_rows(plan, [row]) == ([], ["stage/standard/policy/stage_s0"])
    text = rp.render_page(plan, [], [], tmp_path / "zoo", "docs/results")
    training = text.split("Training:")[1].split("Zoo entries:")[0]
    assert training.index(
        "* stage: `footsim-train train.total_timesteps=64 seed=<S> init_from=runs/study/nav/seed<S>`"
    ) < (training.index("* top: "))
    assert "(a training stage: its policies are not in the zoo)" in training and "* nav:" not in training


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("tables: [{title: T, conditions: [stage]}]\n", r"tables\[0\]\.conditions: 'stage' is a training stage only"),
        ("baselines: {velocity: [stage]}\n", r"baselines\.velocity: 'stage' is a training stage only"),
        (
            "thesis: [{question: q, thesis: t, figures: [{label: s, condition: stage, metric: success}]}]\n",
            r"thesis\[0\]\.figures\[0\]\.condition: 'stage' is a training stage only",
        ),
    ],
)
def test_a_training_stage_cannot_be_shown(tmp_path, extra, message):
    with pytest.raises(rp.PlanError, match=message):
        rp.load_plan(_plan(tmp_path, BASE + STAGES + extra))


def test_a_condition_can_evaluate_its_policies_with_the_beta_mean(tmp_path, monkeypatch):
    body = BASE + "  nav_mean:\n    backend: pymunk\n    task: nav\n    policies: nav\n    beta_action: mean\n"
    plan = rp.load_plan(_plan(tmp_path, body))
    monkeypatch.setattr(rp.zoo, "names", lambda root: ["nav_s0", "nav_s1"])
    monkeypatch.setattr(rp.zoo, "check_config", lambda name, root: None)
    jobs, missing = rp.plan_jobs(plan, list(plan.conditions.values()), tmp_path, None, ["standard"], False)
    assert not missing
    assert {(j.condition, j.name, j.beta_action) for j in jobs} == {
        ("nav", "nav_s0", None),
        ("nav", "nav_s1", None),
        ("nav_mean", "nav_s0", "mean"),
        ("nav_mean", "nav_s1", "mean"),
    }
    with pytest.raises(rp.PlanError, match=r"conditions\.nav_mean\.beta_action must be mode or mean, got 'median'"):
        rp.load_plan(_plan(tmp_path, body.replace("beta_action: mean", "beta_action: median")))


def test_a_condition_can_evaluate_under_its_own_backend_settings(tmp_path, monkeypatch):
    """``backend_settings`` of a condition go over the plan's and the command line's for its jobs only,
    reach the env its policies and baselines run in, and a bad key fails naming the condition."""
    body = BASE + (
        "  nav_thesis:\n    backend: pymunk\n    task: nav\n    policies: nav\n"
        "    backend_settings: {collision_model: nav_distance}\n"
        "baselines: {velocity: [nav_thesis]}\n"
    )
    plan = rp.load_plan(_plan(tmp_path, body))
    monkeypatch.setattr(rp.zoo, "names", lambda root: ["nav_s0", "nav_s1"])
    monkeypatch.setattr(rp.zoo, "check_config", lambda name, root: None)
    cli = {"pymunk": {"collision_distance": 0.2, "collision_model": "footprint"}}
    jobs, _ = rp.plan_jobs(plan, list(plan.conditions.values()), tmp_path, None, ["standard"], True, cli)
    settings = {(j.condition, j.kind): dict(j.backend_settings) for j in jobs}
    assert settings[("nav", "policy")] == {"collision_distance": 0.2, "collision_model": "footprint"}
    assert settings[("nav_thesis", "policy")] == {"collision_distance": 0.2, "collision_model": "nav_distance"}
    assert settings[("nav_thesis", "baseline")] == settings[("nav_thesis", "policy")]
    # a path plot runs its episodes as the evaluation does
    path_spec = {"condition": "nav_thesis", "set": "standard", "scenes": [0]}
    assert {j.backend_settings for j in rp.path_jobs(plan, path_spec, tmp_path)} == {
        (("collision_model", "nav_distance"),)
    }
    baseline = next(j for j in jobs if j.kind == "baseline")
    env, _ = rp.job_env_and_controller(baseline, tmp_path)
    try:
        assert (env.backend.collision_model, env.backend.collision_distance) == ("nav_distance", 0.2)
    finally:
        env.close()
    bad = body.replace("collision_model: nav_distance", "collision_modle: nav_distance")
    with pytest.raises(rp.PlanError, match=r"conditions\.nav_thesis\.backend_settings: .*collision_modle"):
        rp.load_plan(_plan(tmp_path, bad))
    trained = BASE.replace(
        "    seeds: [0, 1]\n", "    seeds: [0, 1]\n    backend_settings: {collision_model: nav_distance}\n"
    )
    with pytest.raises(rp.PlanError, match=r"conditions\.nav\.backend_settings needs policies:"):
        rp.load_plan(_plan(tmp_path, trained))
    with pytest.raises(rp.PlanError, match=r"conditions\.nav_thesis\.backend_settings must be a mapping"):
        rp.load_plan(_plan(tmp_path, body.replace("{collision_model: nav_distance}", "[nav_distance]")))


def test_the_study_judges_the_2d_obstacle_policies_by_the_thesis_collision_check_too():
    """The plan's thesis-check conditions evaluate the 2d_obst_beta_10m[_noise] zoo policies, and a
    policy job's env takes pymunk's nav_distance check over the policy's recorded footprint check."""
    plan = rp.load_plan()
    for name, source in (
        ("2d_obst_beta_10m_thesis_collision", "2d_obst_beta_10m"),
        ("2d_obst_beta_10m_noise_thesis_collision", "2d_obst_beta_10m_noise"),
    ):
        cond = plan.conditions[name]
        assert cond.source == source and dict(cond.backend_settings) == {"collision_model": "nav_distance"}
    jobs, missing = rp.plan_jobs(
        plan, rp.select(plan, "2d_obst_beta_10m_thesis_collision"), zoo.zoo_dir(), None, ["standard"], False
    )
    assert not missing and len(jobs) == 5
    recorded = fconf.to_plain(load_run_config(zoo.entry_dir(jobs[0].name, zoo.zoo_dir())).backend)
    assert recorded["collision_model"] == "footprint"
    env, _ = rp.job_env_and_controller(jobs[0], zoo.zoo_dir())
    try:
        assert env.backend.collision_model == "nav_distance"
    finally:
        env.close()


def test_the_data_file_pair_is_replaced_together_or_not_at_all(tmp_path):
    from footsim.utils import atomic_write_texts

    runs, conditions = tmp_path / rp.RUNS_FILE, tmp_path / rp.CONDITIONS_FILE
    runs.write_text("old runs\n")
    conditions.write_text("old conditions\n")
    blocked = tmp_path / "not_a_dir"
    blocked.write_text("a file where the second file's directory would be\n")
    with pytest.raises(OSError):
        atomic_write_texts({runs: "new runs\n", blocked / rp.CONDITIONS_FILE: "new conditions\n"})
    assert runs.read_text() == "old runs\n"  # the first file's new text was written, but not moved in
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([rp.RUNS_FILE, rp.CONDITIONS_FILE, "not_a_dir"])
    atomic_write_texts({runs: "new runs\n", conditions: "new conditions\n"})
    assert (runs.read_text(), conditions.read_text()) == ("new runs\n", "new conditions\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([rp.RUNS_FILE, rp.CONDITIONS_FILE, "not_a_dir"])
