"""Checkpoints keep the run's schedule over a resume."""

from types import SimpleNamespace

from footsim.rl import train


def test_a_resumed_run_checkpoints_at_the_multiples_of_the_whole_run(monkeypatch, tmp_path):
    saved = []
    monkeypatch.setattr(train, "save_checkpoint", lambda model, run_dir: saved.append(model.num_timesteps))
    callback = train._make_checkpoint_callback(tmp_path, 20000)
    callback.model = SimpleNamespace(num_timesteps=30002)  # resumed at 30 002 steps
    callback._on_training_start()
    for steps in (30004, 39998, 40000, 40002, 59998, 60002):
        callback.model.num_timesteps = steps
        callback._on_step()
    assert saved == [40000, 60002]  # the first step at or past 40 000 and 60 000, not 30 002 + k 20 000
