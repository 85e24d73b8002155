"""Filming an env: offscreen frames of its episodes, written as H.264 MP4. `motorlab video RUN_DIR`
films a run's policy (motorlab.media.videos), `mpc --video` a planner's episode.

Rendering uses MuJoCo's own offscreen renderer on the unwrapped env's model and
data, so it works for Gymnasium's MuJoCo envs and MyoSuite alike; set
MUJOCO_GL=egl (the CLI does) to render without a display, on a CPU with Mesa.
Other simulators render their own rgb_array frames (Upkie: PyBullet's CPU renderer).
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np

from motorlab.envs import EnvConfig, env_dt, facts, make_env
from motorlab.envs.disturbances import mujoco_model_data
from motorlab.errors import MotorlabError
from motorlab.runs import atomic_path

MAX_FPS = 50  # browsers and players want at most this; faster envs are subsampled


class MujocoCamera:
    """Frames from MuJoCo's offscreen renderer on the env's own model and data."""

    def __init__(self, env, width: int, height: int, camera: str | int | None):
        import mujoco

        model, self.data = mujoco_model_data(env)
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        if camera is None and env.spec is not None:
            camera = facts(env.spec.id).camera  # the env's catalogue entry (None for the bundled ones)
        if camera is None:
            camera = 0 if model.ncam else -1  # the model's first camera, else the free camera
        elif isinstance(camera, str) and camera.lstrip("-").isdigit():
            camera = int(camera)
        names = [model.camera(i).name for i in range(model.ncam)]
        if isinstance(camera, str) and camera not in names:
            raise MotorlabError(f"no camera {camera!r} in this model; cameras: {', '.join(names) or 'none (use -1, the free camera)'}.")
        self.camera = camera
        try:
            self.renderer = mujoco.Renderer(model, height, width)
        except Exception as e:  # no usable OpenGL: say how to get one
            raise MotorlabError(f"offscreen rendering failed ({e}); set MUJOCO_GL=egl and install "
                                "libegl1 libegl-mesa0 libgl1-mesa-dri (make demo does).") from None

    def grab(self) -> np.ndarray:
        self.renderer.update_scene(self.data, camera=self.camera)
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()


class EnvCamera:
    """Frames from the env's own `render()` (render_mode "rgb_array"), for simulators
    other than MuJoCo (Upkie's PyBullet camera)."""

    camera = "env"

    def __init__(self, env):
        if env.render_mode != "rgb_array":
            raise MotorlabError("video needs a MuJoCo env or one that renders rgb_array frames.")
        self.env = env

    def grab(self) -> np.ndarray:
        import gymnasium as gym

        name = self.env.spec.id if self.env.spec else "the env"
        try:
            frame = self.env.render()
        except gym.error.DependencyNotInstalled as e:  # e.g. classic control's pygame
            raise MotorlabError(f"{name} cannot render here: {' '.join(str(e).split())}") from None
        if frame is None or np.ndim(frame) != 3:
            raise MotorlabError(f"{name} cannot render: its render() gives no rgb_array frame, which a video needs.")
        return np.asarray(frame)

    def close(self) -> None:
        pass


def make_video_env(env_cfg: EnvConfig):
    """The env for recording: MuJoCo envs as they are (motorlab renders their model
    itself), any other env asked to render rgb_array frames."""
    env = make_env(env_cfg, shaped=False)
    if mujoco_model_data(env)[0] is None:
        env.close()
        env = make_env(env_cfg, shaped=False, render_mode="rgb_array")
    return env


def record_episode(env, policy, cam, seed: int, every: int = 1) -> tuple[list[np.ndarray], float]:
    """Frames (every `every` env steps, and the last) and the return of one episode of `policy`."""
    obs, _ = env.reset(seed=seed)
    policy.reset(1)
    frames, ret, done, t = [], 0.0, False, 0
    while not done:
        if t % every == 0:
            frames.append(cam.grab())
        obs, r, terminated, truncated, _ = env.step(policy.act(obs[None])[0])
        ret += float(r)
        done = terminated or truncated
        t += 1
    frames.append(cam.grab())
    return frames, ret


@contextlib.contextmanager
def filming(env, width: int, height: int, camera):
    """(env, camera, every, fps) for recording `env`; the renderer and the env are closed when the
    block ends, whatever an episode raised."""
    try:
        cam, every, fps = video_settings(env, width, height, camera)
        try:
            yield env, cam, every, fps
        finally:
            cam.close()
    finally:
        env.close()


def video_settings(env, width: int, height: int, camera):
    """(camera, every, fps) for recording env at most MAX_FPS frames per second."""
    cam = MujocoCamera(env, width, height, camera) if mujoco_model_data(env)[0] is not None else EnvCamera(env)
    dt = env_dt(env) or 1.0 / MAX_FPS
    every = max(1, math.ceil((1.0 / dt) / MAX_FPS))
    return cam, every, (1.0 / dt) / every


def write_mp4(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """H.264 (yuv420p, what browsers play) via imageio's ffmpeg, to a temp file renamed into place."""
    import imageio.v2 as imageio

    with atomic_path(path, suffix=".mp4") as tmp, imageio.get_writer(
            tmp, format="FFMPEG", fps=fps, codec="libx264", pixelformat="yuv420p", macro_block_size=8,
            ffmpeg_log_level="error") as writer:
        for frame in frames:
            writer.append_data(frame)
