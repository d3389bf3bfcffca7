"""Episode videos at the simulator's pace (``footsim-eval ... video=true``).

An :class:`EpisodeFilm` turns one episode into frames at ``fps`` frames per simulated second:
frame ``n`` shows the robot at the first control tick at or after ``n / fps`` s.  On a 3D
backend it is the driver's frame hook (``Physics3DBackend.frame_hook``,
:class:`footsim.backends.base.FrameHook`): the driver renders between runs of control ticks,
cut where a frame is due, so the episode is the one it is without frames.  On the 2D backend,
whose feet jump to their put-downs, the frames after a double step animate it from the walk
timing: each half step (half the double step's duration) starts with ``double_support_ratio``
of it in double support, then the flying foot moves from its old to its new pose (a smoothstep
in position and heading).  Every frame carries the overlay of
:meth:`footsim.env.FootstepEnv.render_overlay` (goal, believed pose, rays when the task observes
obstacles, the double step's commanded put-downs) and a caption (label, simulated time, double
step); the last one names the outcome and is held for :data:`END_HOLD_S`.

:class:`ClipWriter` writes the frames as they come (nothing is kept in memory): MP4 (H.264)
through imageio's ffmpeg plugin (``pip install 'footsim[video]'``), else an animated GIF at
most :data:`GIF_MAX_FPS` frames a second (every k-th frame), with one warning naming the extra.
:func:`side_by_side` films the same scene and policy on several envs in lock step into one clip.
"""

from __future__ import annotations

import functools
import math
import os
import tempfile
import warnings
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from footsim.geometry import Pose2D, wrap_angle
from footsim.walk.footsteps import Side

#: The last frame (with the outcome) is shown this long at the end of a clip [s].
END_HOLD_S = 1.0
#: GIF players slow frame delays below 20 ms (many to 100 ms): the GIF fallback keeps every k-th
#: frame so that it plays at most this many frames a second, in real time.
GIF_MAX_FPS = 10.0
VIDEO_EXTRA = "pip install 'footsim[video]'"
OUTCOME_COLOURS = {"success": (40, 170, 60)}
_warned_gif = False


def mp4_available() -> bool:
    """Is imageio's ffmpeg plugin (the ``video`` extra) installed?"""
    try:
        import imageio.v2  # noqa: F401
        import imageio_ffmpeg  # type: ignore[import-untyped]  # noqa: F401
    except ImportError:
        return False
    return True


def check_fps(fps: float, key: str = "video_fps") -> float:
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"{key} must be a positive number of frames per simulated second, got {fps!r}")
    return float(fps)


class ClipWriter:
    """Frames into ``path`` (its suffix is replaced: ``.mp4``, or ``.gif`` without the ``video``
    extra) as they come, written to a temporary file beside it and moved into place at
    :meth:`close` (an interrupted clip leaves no half file).  Frames of one clip share a size;
    odd sizes are padded by a pixel (H.264's 4:2:0 needs even ones)."""

    def __init__(self, path: str | os.PathLike, fps: float, mp4: bool | None = None):
        global _warned_gif
        self.fps = check_fps(fps)
        self.mp4 = mp4_available() if mp4 is None else bool(mp4)
        if not self.mp4 and not _warned_gif:
            warnings.warn(
                f"footsim video: imageio's ffmpeg plugin is missing ({VIDEO_EXTRA}); writing animated GIFs "
                f"at most {GIF_MAX_FPS:g} fps instead of MP4",
                stacklevel=2,
            )
            _warned_gif = True
        self.path = Path(path).with_suffix(".mp4" if self.mp4 else ".gif")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, self._tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.", suffix=self.path.suffix)
        os.close(fd)
        self.frames = 0  # frames appended
        self._every = 1 if self.mp4 else max(1, math.ceil(self.fps / GIF_MAX_FPS))
        self._gif: list[Image.Image] = []
        self._writer = None
        if self.mp4:
            import imageio.v2 as imageio

            self._writer = imageio.get_writer(
                self._tmp, format="FFMPEG", fps=self.fps, codec="libx264", quality=7, macro_block_size=1
            )

    def append(self, frame: np.ndarray) -> None:
        frame = np.asarray(frame, dtype=np.uint8)[:, :, :3]
        pad = ((0, frame.shape[0] % 2), (0, frame.shape[1] % 2), (0, 0))
        if any(p[1] for p in pad):
            frame = np.pad(frame, pad, mode="edge")
        if self._writer is not None:
            self._writer.append_data(frame)
        elif self.frames % self._every == 0:
            self._gif.append(Image.fromarray(frame).quantize(colors=255))
        self.frames += 1

    def close(self) -> Path:
        """Finish the file and move it into place; returns its path."""
        try:
            if self._writer is not None:
                self._writer.close()
            elif self._gif:
                first, *rest = self._gif
                delay = int(round(1000 * self._every / self.fps))
                first.save(self._tmp, format="GIF", save_all=True, append_images=rest, duration=delay, loop=0)
            os.chmod(self._tmp, 0o666 & ~_umask())
            os.replace(self._tmp, self.path)
        finally:
            if os.path.exists(self._tmp):
                os.unlink(self._tmp)
        return self.path

    def abort(self) -> None:
        """Drop the clip (an error while filming)."""
        if self._writer is not None:
            try:
                self._writer.close()
            except Exception:  # pragma: no cover - the clip is dropped anyway
                pass
        if os.path.exists(self._tmp):
            os.unlink(self._tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@functools.lru_cache(maxsize=8)
def _font(size: int):
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # a Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def caption(frame: np.ndarray, lines: Sequence[str], colour=(255, 255, 255), size: int = 16) -> np.ndarray:
    """``frame`` with ``lines`` written top left on a dark band."""
    image = Image.fromarray(np.asarray(frame, dtype=np.uint8)[:, :, :3])
    draw = ImageDraw.Draw(image, "RGBA")
    font = _font(size)
    height = (size + 4) * len(lines) + 6
    width = max((draw.textlength(line, font=font) for line in lines), default=0) + 12
    draw.rectangle([0, 0, width, height], fill=(0, 0, 0, 150))
    for i, line in enumerate(lines):
        draw.text((6, 4 + i * (size + 4)), line, fill=colour, font=font)
    return np.asarray(image)


def hstack(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Frames side by side, each padded (black, at the bottom) to the tallest."""
    height = max(f.shape[0] for f in frames)
    padded = [np.pad(f, ((0, height - f.shape[0]), (0, 0), (0, 0))) for f in frames]
    return np.concatenate(padded, axis=1)


class EpisodeFilm:
    """One episode of ``env`` as frames at ``fps`` per simulated second, handed to ``sink``.

    Use: :meth:`start` after ``env.reset``, :meth:`stepped` after each ``env.step`` (its info),
    :meth:`finish` at the end (holds the outcome frame), :meth:`detach` always.  While attached,
    it is the frame hook of a 3D backend."""

    def __init__(self, env, fps: float, sink: Callable[[np.ndarray], None], label: str = ""):
        self.env = env.unwrapped
        self.backend = self.env.backend
        self.fps = check_fps(fps)
        self.period = 1.0 / self.fps
        self.sink = sink
        self.label = label
        self.frames = 0  # frames given to the sink
        self.t0 = 0.0  # simulated time at the start of the current double step
        self.steps = 0
        self._dt = 0.0
        self._overlay: Any = None  # a RenderOverlay once started
        self._3d = getattr(self.backend, "kind", "2d") == "3d" and hasattr(self.backend, "frame_hook")
        self.last: np.ndarray | None = None

    # -- the episode ------------------------------------------------------------------------
    def start(self) -> None:
        """After ``env.reset``: the frame at time 0, and the hook on a 3D backend."""
        self.t0, self.steps, self.frames = 0.0, 0, 0
        self._overlay = self.env.render_overlay()
        self._emit(self.backend.render(self._overlay), 0.0)
        if self._3d:
            self.backend.frame_hook = self

    def stepped(self, info: dict) -> None:
        """After ``env.step`` (its ``info``): the 2D backend's frames of this double step."""
        t1 = float(info["time_s"])
        if not self._3d:
            self._frames_2d(self.t0, t1)
        self.t0 = t1
        self.steps = int(info["steps"])
        self._overlay = self.env.render_overlay()

    def finish(self, info: dict) -> None:
        """The last frame with the outcome, held :data:`END_HOLD_S`."""
        self.detach()
        outcome = str(info["outcome"])
        frame = self._captioned(self.backend.render(self.env.render_overlay()), self.t0, outcome)
        for _ in range(max(1, round(END_HOLD_S * self.fps))):
            self.sink(frame)
            self.frames += 1
        self.last = frame

    def detach(self) -> None:
        if self._3d and getattr(self.backend, "frame_hook", None) is self:
            self.backend.frame_hook = None

    # -- FrameHook (3D) ---------------------------------------------------------------------
    def begin(self, control_dt: float, footsteps: tuple[Pose2D, Pose2D]) -> int:
        self._dt = float(control_dt)
        self._overlay = replace(self._overlay, footsteps=tuple(footsteps))
        return self._due()

    def frame(self, ticks: int) -> int:
        self._emit(self.backend.render(self._overlay), self.t0 + ticks * self._dt)
        return max(self._due(), ticks + 1)

    def _due(self) -> int:
        """Ticks into the current double step at which the next frame is due."""
        return max(0, math.ceil((self.frames * self.period - self.t0) / self._dt - 1e-6))

    # -- 2D ---------------------------------------------------------------------------------
    def _frames_2d(self, t0: float, t1: float) -> None:
        from footsim.backends.pymunk2d.render import draw_scene

        backend = self.backend
        history = list(backend.history)
        earlier = history[:-2]
        before = {side: next(pose for s, pose in reversed(earlier) if s is side) for side in (Side.LEFT, Side.RIGHT)}
        (_, right), (_, left) = history[-2], history[-1]
        overlay = replace(self._overlay, footsteps=(right, left))
        half = 0.5 * (t1 - t0)
        ds = float(backend.walk.double_support_ratio)
        nav = list(backend.nav_history[:-1])
        while self.frames * self.period <= t1 + 1e-9:
            t = self.frames * self.period
            first = t < t0 + half
            u = ((t - t0) / half) if first else ((t - t0 - half) / half)
            s = min(1.0, max(0.0, (u - ds) / (1.0 - ds))) if half > 0 else 1.0
            s = s * s * (3.0 - 2.0 * s)
            if first:
                feet = [*earlier, (Side.RIGHT, _between(before[Side.RIGHT], right, s))]
            else:
                feet = [*earlier, history[-2], (Side.LEFT, _between(before[Side.LEFT], left, s))]
            at_end = t >= t1 - 1e-9
            shown = (history, backend.nav_history) if at_end else (feet, nav)
            frame = draw_scene(backend.scene, shown[0], shown[1], backend.robot, overlay)
            self._emit(frame, t)

    # -- frames -----------------------------------------------------------------------------
    def _emit(self, frame: np.ndarray | None, t: float) -> None:
        if frame is None:
            raise RuntimeError(f"backend {self.backend.name} renders no frames (video needs a renderer)")
        self.sink(self._captioned(frame, t))
        self.frames += 1

    def _captioned(self, frame: np.ndarray, t: float, outcome: str | None = None) -> np.ndarray:
        lines = [self.label] if self.label else []
        if outcome is None:
            lines.append(f"t = {t:5.2f} s   double step {self.steps + 1}")
        else:
            lines += [f"t = {t:5.2f} s   {self.steps} double steps", outcome]
        colour = (255, 255, 255) if outcome is None else OUTCOME_COLOURS.get(outcome, (235, 60, 60))
        return caption(frame, lines, colour=colour, size=max(12, frame.shape[0] // 30))


def _between(a: Pose2D, b: Pose2D, s: float) -> Pose2D:
    return Pose2D(a.x + s * (b.x - a.x), a.y + s * (b.y - a.y), wrap_angle(a.theta + s * wrap_angle(b.theta - a.theta)))


def film_episode(env, controller, scene, seed: int, path: str | os.PathLike, fps: float, label: str = ""):
    """Run one episode (``footsim.rl.evaluate.run_episode``) while filming it into ``path``;
    returns ``(record, clip path, frames written)``."""
    from footsim.rl.evaluate import run_episode

    writer = ClipWriter(path, fps)
    film = EpisodeFilm(env, fps, writer.append, label=label)
    try:
        record, _ = run_episode(env, controller, scene, seed=seed, film=film)
    except BaseException:
        film.detach()
        writer.abort()
        raise
    return record, writer.close(), writer.frames


def side_by_side(
    envs: Sequence, controllers: Sequence, labels: Sequence[str], scene, seed: int, path: str | os.PathLike, fps: float
) -> tuple[list[dict], Path, int]:
    """The same scene and seed on each env (with its controller), stepped in lock step, filmed
    into one clip: the frames of equal simulated time side by side, each captioned with its
    label; an episode that ended earlier shows its last frame (with its outcome) until all have.
    Returns the episodes' records (as ``run_episode``'s), the clip's path and its frame count."""
    from footsim.rl.evaluate import EpisodeRecord

    writer = ClipWriter(path, fps)
    queues: list[deque] = [deque() for _ in envs]
    films = [EpisodeFilm(env, fps, queue.append, label=label) for env, queue, label in zip(envs, queues, labels)]
    held: list[Any] = [None] * len(envs)  # an ended episode's last frame

    def flush() -> None:
        # a composite frame when every episode has its next frame (or has ended: its last one)
        while any(queues) and all(queue or held[i] is not None for i, queue in enumerate(queues)):
            writer.append(hstack([queue.popleft() if queue else held[i] for i, queue in enumerate(queues)]))

    try:
        episodes = [EpisodeRecord(env, controller, scene, seed) for env, controller in zip(envs, controllers)]
        for episode, film in zip(episodes, films):
            episode.begin()
            film.start()
        while not all(e.done for e in episodes):
            for i, (episode, film) in enumerate(zip(episodes, films)):
                if episode.done:
                    continue
                info = episode.step()
                film.stepped(info)
                if episode.done:
                    film.finish(info)
                    held[i] = film.last
            flush()
        flush()
    except BaseException:
        for film in films:
            film.detach()
        writer.abort()
        raise
    return [e.record() for e in episodes], writer.close(), writer.frames
