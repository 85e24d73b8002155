"""Policies from Python: train, evaluate, film, test zero-shot, measure robustness, compare.

Each function is its CLI command: the same settings (keyword arguments named as the options,
`--n-envs` is `n_envs`), the same run folder, the same errors (`MotorlabError`, the CLI's message).
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from motorlab.api import running
from motorlab.api.checks import api_function
from motorlab.api.running import Track
from motorlab.api.views import FOLDER_TYPES, PolicyFunction, Result
from motorlab.kinds.evaluate import EVALUATE, ZEROSHOT
from motorlab.kinds.media import COMPARE, VIDEO
from motorlab.kinds.robustness import ROBUSTNESS
from motorlab.kinds.train import TRAIN

if TYPE_CHECKING:
    import gymnasium as gym

PolicyLike = str | Path | Result


@api_function
def train(env: str, algo: str | None = None, timesteps: int | None = None, *, preset: str | None = None,
          seed: int | None = None, out: str | Path | None = None, progress: bool = True, track: Track = None,
          overwrite: bool = False, **settings: Any) -> Run:
    """Train a policy on `env` (`motorlab train ENV`) and return its run.

    Args:
        env: a Gymnasium env id (InvertedPendulum-v5), or MODULE:ID for your own env.
        algo: ppo, sac, td3 or lqr (default: the preset's, else ppo).
        timesteps: the env-step budget (default 100,000).
        preset: named settings: fast, sb3-ppo, sb3-sac, sar-sac, sar-sac-fast, upkie-balancer.
        seed: the run's seed (default 0).
        out: the run folder (default `runs/train-<time>`).
        progress: show a progress bar (in Jupyter too).
        track: "mlflow", "wandb" (or "mlflow=URI", "wandb=PROJECT"): log the run there too.
        overwrite: replace a finished run in `out` (without it, one there is refused).
        **settings: any other `motorlab train` option, named as in `motorlab recipes --kinds`:
            until_solved=True, delay=0.2, history=10, n_envs=4, lr="linear:3e-4,0", reward=...,
            `sar=<a fit result or sar.npz>`, env_kwargs={...}, hyperparams={"n_steps": 1024}, ...

    Returns:
        The run: `.summary`, `.policy`, `.evaluate()`, `.video()`, `.plot()`, `.path`.

    Raises:
        MotorlabError: a wrong setting (one line, as the CLI prints it), or an env that does not exist.

    Example:
        >>> run = motorlab.train("InvertedPendulum-v5", preset="fast", until_solved=True)
        >>> run.steps_to_success, run.evaluate(delay=0.2)["return_mean"]
    """
    fields = {"env": env, "algo": algo, "timesteps": timesteps, "preset": preset, "seed": seed,
              "progress": progress, **settings}
    checked = running.settings(TRAIN, **fields)
    return running.run(TRAIN, checked, out, progress, track, overwrite)  # type: ignore[return-value]


@api_function
def evaluate(policy: PolicyLike, env: str | None = None, *, episodes: int | None = None, seed: int | None = None,
             workers: int | None = None, out: str | Path | None = None, progress: bool = True,
             overwrite: bool = False, **env_settings: Any) -> Result:
    """Evaluate a policy deterministically (`motorlab evaluate POLICY`).

    Args:
        policy: a `Run` or run folder, or a built-in controller: "pid", "pid:kp=[...],kd=[...]",
            "zero", "random".
        env: the env id (default: the run's training env; needed for built-in controllers).
        episodes: evaluation episodes (default 10).
        seed: the first episode's reset seed (default 0).
        workers: env processes (default: as many as help).
        overwrite: replace a finished run in `out` (without it, one there is refused).
        **env_settings: the env as evaluated, on top of the run's own: delay=0.2, delay_on="action",
            history, obs_noise, latency, push_force, kwargs={...}, success=...

    Returns:
        Its numbers: `result["return_mean"]`, `["success_rate"]`, `["episode_lengths"]`, ...
    """
    env_fields = {"id": env, **{_env_field(k): running.path_of(v) for k, v in env_settings.items()}}
    checked = EVALUATE.make(policy=running.path_of(policy), env={k: v for k, v in env_fields.items() if v is not None},
                            episodes=episodes, seed=seed, workers=workers)
    return running.run(EVALUATE, checked, out, progress, overwrite=overwrite)


@api_function
def video(run: PolicyLike, episodes: int | None = None, *, out: str | Path | None = None,
          **settings: Any) -> Result:
    """Render episodes of a run's policy to MP4 files (`motorlab video RUN`), offscreen.

    Args:
        run: a training `Run` or its folder (or an evaluation's: its policy on its env).
        episodes: episodes to film, one MP4 each (default 5).
        out: the folder for the videos (default RUN/videos).
        **settings: camera, width, height, seed.

    Returns:
        The videos folder: `.videos` lists the files, `["returns"]` each episode's return.
    """
    return running.run_kind(VIDEO, out, run=run, episodes=episodes, **settings)


@api_function
def zeroshot(runs: list[PolicyLike], envs: list[str], *, episodes: int | None = None, seed: int | None = None,
             workers: int | None = None, out: str | Path | None = None, progress: bool = True) -> Result:
    """Zero-shot success of trained policies on envs they never saw (`motorlab zeroshot`)."""
    return running.run_kind(ZEROSHOT, out, progress, runs=list(runs), envs=list(envs), episodes=episodes, seed=seed,
                          workers=workers)


@api_function
def robustness(policies: list[PolicyLike], vary: str | list[str] | dict[str, Any], *, env: str | None = None,
               episodes: int | None = None, seed: int | None = None, workers: int | None = None,
               out: str | Path | None = None, progress: bool = True, **env_settings: Any) -> Result:
    """How far each policy holds as a disturbance grows (`motorlab robustness`).

    Args:
        policies: runs, run folders or built-in controllers ("pid").
        vary: the grids, one disturbance at a time: "delay=0:0.3:7" (start:stop:count), a list
            of those, or a dict {"delay": [0, 0.1, 0.2], "obs_noise": "0:0.05:6"}.
        env: the env id for built-in controllers (default: the first run's).
        **env_settings: the env every policy meets besides the grid: push_body="pole", delay_on=...

    Returns:
        Its folder: curves.csv, plots/robustness.png, `["<policy>.<disturbance>.threshold"]`, ...
    """
    grids = vary if isinstance(vary, list) else [vary] if isinstance(vary, str) else [
        f"{key}={value if isinstance(value, str) else ','.join(map(str, value))}" for key, value in vary.items()]
    fixed = {_env_field(k): v for k, v in {"id": env, **env_settings}.items() if v is not None}
    return running.run_kind(ROBUSTNESS, out, progress, policies=list(policies), vary=grids, episodes=episodes,
                          seed=seed, workers=workers, env=fixed or None)


@api_function
def compare(groups: dict[str, list[PolicyLike]], *, title: str | None = None, out: str | Path | None = None) -> Result:
    """Learning curves of settings across seeds, with rliable's IQMs (`motorlab compare`).

    Args:
        groups: label -> that setting's training runs, one per seed.
    """
    return running.run_kind(COMPARE, out, groups={k: list(v) for k, v in groups.items()}, title=title)


def _env_field(name: str) -> str:
    """An env setting as `EnvConfig` names it: the options' and train's `env_kwargs` is its `kwargs`."""
    from motorlab.envs import ENV_KEYS

    return ENV_KEYS.get(name, name)


class Run(Result):
    """A training run (`motorlab.train`, `motorlab train`): a `Result` with a policy.

    `run.policy(obs)` acts on observations of the env as trained (its delay and history
    wrappers included: `run.env()` makes that env).
    """

    @property
    def steps_to_success(self) -> int | None:
        """Env steps until the policy was consistently solved (None: not within the budget)."""
        return self.summary.get("steps_to_success")

    @cached_property
    def policy(self) -> PolicyFunction:
        """The trained policy, loaded pickle-free from policy.json + policy.safetensors."""
        from motorlab.policies import load_run_policy

        return PolicyFunction(load_run_policy(self.path))

    @api_function
    def env(self, **env_settings: Any) -> gym.Env:
        """The env the run trained on, with its wrappers; `env_settings` (delay, history, kwargs,
        ...) change it."""
        from motorlab.envs import EnvConfig, make_env
        from motorlab.evaluation import trained_env_settings
        from motorlab.kinds.evaluate import merge_env

        return make_env(EnvConfig.model_validate(merge_env(trained_env_settings(self.path), env_settings)))

    @api_function
    def evaluate(self, env: str | None = None, episodes: int | None = None, seed: int | None = None,
                 workers: int | None = None, out: str | Path | None = None, progress: bool = True,
                 **env_settings: Any) -> Result:
        """Evaluate the policy deterministically (`motorlab evaluate RUN`): on its training env, or
        `env`, changed by `env_settings` (delay=0.2, history, obs_noise, ...)."""
        return evaluate(self, env, episodes=episodes, seed=seed, workers=workers, out=out, progress=progress,
                        **env_settings)

    @api_function
    def video(self, episodes: int | None = None, out: str | Path | None = None, **settings: Any) -> list[Path]:
        """Render episodes of the policy to MP4 (`motorlab video RUN`); returns the video files."""
        return video(self, episodes=episodes, out=out, **settings).videos

    @api_function
    def plot(self) -> list[Path]:
        """Draw plots/learning_curve.png and plots/observation_trace.png (`motorlab plot RUN`)."""
        from motorlab.media.figures import plot_run

        return plot_run(self.path)


FOLDER_TYPES[TRAIN.name] = Run
