"""`motorlab video RUN_DIR`: episodes of a run's policy as H.264 MP4, filmed offscreen
(the cameras and the MP4 writer: motorlab.report.video)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from motorlab.envs import EnvConfig
from motorlab.errors import MotorlabError
from motorlab.evaluation import trained_env_settings
from motorlab.policies import load_policy
from motorlab.report.video import filming, make_video_env, record_episode, write_mp4
from motorlab.runs import read_config, require_run_dir, write_json


def render_video(run_dir: Path, episodes: int = 5, seed: int = 0, camera: str | None = None,
                 width: int = 640, height: int = 480, out: Path | None = None,
                 start: Callable[[], Path] | None = None) -> dict[str, Any]:
    """Render `episodes` deterministic episodes of the run's policy to `<out>/episode_<k>.mp4`
    (default out: RUN_DIR/videos), with an index videos.json beside them.

    Args:
        start: called once the env has rendered a first frame and the policy is loaded, before
            anything is written; returns the folder to write (a step kind's `start`). A mistake
            (an env that cannot render, a policy that does not fit it) so leaves no folder behind.

    Returns:
        The files, frame counts, fps, episode returns, camera and size.

    Raises:
        MotorlabError: not a finished run, an env that cannot render, a policy that does not fit it.
    """
    if episodes <= 0:
        raise MotorlabError(f"--episodes must be positive, got {episodes}.")
    run_dir = require_run_dir(Path(run_dir))
    config = read_config(run_dir)
    env_cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    files, returns, frames_per = [], [], []
    with filming(make_video_env(env_cfg), width, height, camera) as (env, cam, every, fps):
        policy = load_policy(config.get("policy", str(run_dir)), env, env_cfg.id, seed)
        env.reset(seed=seed)
        cam.grab()  # the env renders: checked before the folder is touched
        folder = start() if start is not None else Path(out) if out else run_dir / "videos"
        for k in range(episodes):
            frames, ret = record_episode(env, policy, cam, seed + k, every)
            path = folder / f"episode_{k}.mp4"
            write_mp4(path, frames, fps)
            files.append(str(path))
            returns.append(ret)
            frames_per.append(len(frames))
    summary = {"videos": files, "frames": frames_per, "fps": fps, "returns": returns, "camera": cam.camera,
               "width": width, "height": height}
    write_json(folder / "videos.json", summary)
    return summary
