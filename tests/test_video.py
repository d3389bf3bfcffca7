"""Videos at the simulator's pace (footsim.rl.video): filming never changes an episode, the clips
have one frame per 1/fps simulated seconds (read back by ffmpeg itself, not by our writer), the
2D backend's swing foot moves between put-downs, and one camera frames the 3D backends alike."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.rl.evaluate import evaluate, run_episode
from footsim.rl.video import END_HOLD_S, ClipWriter, EpisodeFilm, film_episode
from footsim.scene import Obstacle, Scene
from footsim.tasks.scenes import sample_scenes

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg", reason="the video extra (imageio[ffmpeg])")

SMALL = [320, 240]


class Walk:
    """A fixed forward-and-turn double step (no policy needed)."""

    def reset(self, scene, info, seed) -> None:
        pass

    def __call__(self, obs, info) -> np.ndarray:
        return np.array([0.6, 0.0, 0.2, 0.6, 0.0, 0.2])


def _env(backend: str, max_steps: int = 4, **kwargs) -> FootstepEnv:
    cfg = backend if backend == "pymunk" else {"name": backend, "render_size": SMALL}
    task = {"name": "nav_obstacles", "max_steps": max_steps}
    return FootstepEnv(backend=cfg, task=task, render_mode="rgb_array", **kwargs)


def _expected_frames(seconds: float, fps: float) -> int:
    """Frames at 0, 1/fps, … up to the episode's end, then the outcome frame held END_HOLD_S."""
    return 1 + math.floor(seconds * fps + 1e-6) + round(END_HOLD_S * fps)


@pytest.mark.parametrize("backend", ["pymunk", "mujoco"])
def test_episodes_csv_is_identical_with_and_without_video(backend, tmp_path):
    if backend == "mujoco":
        pytest.importorskip("mujoco")
    env = _env(backend, max_steps=3 if backend == "mujoco" else 12)
    try:
        scenes = sample_scenes(env.sampler, 3, 11)
        plain = evaluate(env, Walk(), scenes, seed=5, progress=False)
        filmed = evaluate(env, Walk(), scenes, seed=5, progress=False, video_dir=tmp_path, video_episodes=3)
    finally:
        env.close()
    assert filmed == plain  # every column of every episode, bit for bit
    assert sorted(p.name for p in tmp_path.glob("*.mp4")) == [f"episode_{i:03d}.mp4" for i in range(3)]
    for i, record in enumerate(plain):
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / f"episode_{i:03d}.mp4"))
        assert frames == _expected_frames(record["time_s"], 30.0)


@pytest.mark.parametrize("backend", ["mujoco", "pybullet"])
def test_a_3d_clip_has_fps_frames_per_simulated_second(backend, tmp_path):
    pytest.importorskip(backend)
    env = _env(backend, max_steps=3)
    try:
        scene = Scene(goal=Pose2D(1.5, 0.2, 0.0), obstacles=(Obstacle(-0.8, 0.9, 0.2),))
        record, path, written = film_episode(env, Walk(), scene, seed=0, path=tmp_path / "clip", fps=24.0)
        unfilmed, _ = run_episode(env, Walk(), scene, seed=0)
    finally:
        env.close()
    assert record == unfilmed
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert path.suffix == ".mp4" and frames == written
    # the simulated time, at 24 fps, plus the held last frame: real time
    assert frames == _expected_frames(record["time_s"], 24.0)
    assert seconds == pytest.approx(record["time_s"] + END_HOLD_S, abs=2 / 24)


def test_the_3d_frames_come_during_the_double_step_at_the_due_ticks():
    pytest.importorskip("mujoco")
    env = _env("mujoco", max_steps=2)
    try:
        times: list[float] = []
        film = EpisodeFilm(env, 10.0, lambda frame: None)
        emit = film._emit
        film._emit = lambda frame, t: (times.append(t), emit(frame, t))  # type: ignore[method-assign]
        record, _ = run_episode(env, Walk(), Scene(goal=Pose2D(2.0, 0.0, 0.0)), seed=0, film=film)
    finally:
        env.close()
    dt = env.backend.control_dt
    # frame n at the first control tick at or after n / 10 s, up to the episode's end
    expected = [math.ceil(n / 10 / dt - 1e-6) * dt for n in range(math.floor(record["time_s"] * 10 + 1e-6) + 1)]
    np.testing.assert_allclose(times, expected, atol=1e-9)
    assert env.backend.frame_hook is None  # detached after the episode


def test_the_2d_swing_foot_moves_between_put_downs():
    env = _env("pymunk")
    frames: list[np.ndarray] = []
    try:
        film = EpisodeFilm(env, 30.0, frames.append)
        env.reset(seed=0, options={"scene": Scene(goal=Pose2D(2.0, 0.0, 0.0))})
        film.start()
        _, _, _, _, info = env.step(np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]))
        film.stepped(info)
    finally:
        env.close()
    duration = info["time_s"]  # the walk's 1 / freq
    assert len(frames) == 1 + math.floor(duration * 30 + 1e-6)
    # the right foot (red outlines) moves during the first half step: the frames differ from one
    # another, not only at the put-downs
    first_half = frames[1 : len(frames) // 2]
    changes = [int((a != b).any(axis=2).sum()) for a, b in zip(first_half, first_half[1:])]
    assert sum(c > 50 for c in changes) >= len(changes) // 2


def test_without_the_ffmpeg_plugin_a_gif_is_written_and_said_once(tmp_path, monkeypatch):
    import footsim.rl.video as video

    monkeypatch.setattr(video, "_warned_gif", False)
    frame = np.zeros((24, 32, 3), dtype=np.uint8)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for name in ("a", "b"):
            writer = ClipWriter(tmp_path / name, fps=30.0, mp4=False)
            for k in range(30):
                writer.append(frame + k)
            writer.close()
    said = [w for w in caught if "footsim[video]" in str(w.message)]
    assert len(said) == 1
    from PIL import Image

    gif = Image.open(tmp_path / "a.gif")
    assert gif.n_frames == 10  # every 3rd of 30 frames: 10 fps
    assert gif.info["duration"] == 100  # [ms]: real time


def test_bad_fps_is_refused_naming_the_key():
    with pytest.raises(ValueError, match="video_fps"):
        ClipWriter("/tmp/never", fps=0)


def test_side_by_side_steps_each_episode_as_alone_and_pads_the_shorter(tmp_path):
    pytest.importorskip("mujoco")
    from footsim.rl.video import side_by_side

    scene = Scene(goal=Pose2D(1.5, 0.0, 0.0))
    envs = [_env("pymunk", max_steps=2), _env("mujoco", max_steps=3)]
    try:
        alone = [run_episode(env, Walk(), scene, seed=4)[0] for env in envs]
        records, path, written = side_by_side(
            envs, [Walk(), Walk()], ["pymunk", "mujoco"], scene, seed=4, path=tmp_path / "both", fps=20.0
        )
    finally:
        for env in envs:
            env.close()
    assert records == alone  # lock step changes neither episode
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert frames == written == max(_expected_frames(r["time_s"], 20.0) for r in alone)
    import imageio.v2 as imageio

    first = imageio.get_reader(str(path)).get_data(0)
    assert first.shape == (600, 600 + SMALL[0], 3)  # the 2D drawing (600 px) beside the 3D frame, padded
    assert (first[SMALL[1] :, 600:] < 10).all()  # below the shorter frame: black padding
