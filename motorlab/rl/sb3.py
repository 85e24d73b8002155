"""Stable-Baselines3 training (PPO, SAC, TD3) with motorlab's tracking."""

from __future__ import annotations

from pathlib import Path

from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from motorlab.envs import make_env
from motorlab.errors import MotorlabError
from motorlab.policies import SB3Policy, save_sb3_policy
from motorlab.rl.config import TrainConfig
from motorlab.rl.schedules import parse_schedule
from motorlab.rl.tracking import Tracker
from motorlab.runs import atomic_write_bytes

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}


class TrackingCallback(BaseCallback):
    """Feeds episodes and evaluations to the Tracker; stops when solved.

    On-policy algorithms change their policy only between rollouts, so they are
    evaluated at the start of each rollout (right after the update); off-policy
    ones every `eval_every` steps.
    """

    def __init__(self, tracker: Tracker, eval_every: int, on_policy: bool, until_solved: bool):
        super().__init__()
        self.tracker, self.eval_every, self.on_policy, self.until_solved = tracker, eval_every, on_policy, until_solved
        self.next_eval = eval_every
        self.solved = False

    def policy_now(self) -> SB3Policy:
        # SB3Policy switches the network to eval mode; SB3 switches it back in train().
        venv = self.model.get_env()
        if isinstance(venv, VecNormalize):
            return SB3Policy(self.model.policy, venv.obs_rms.mean, venv.obs_rms.var, venv.clip_obs, venv.epsilon)
        return SB3Policy(self.model.policy)

    def _maybe_evaluate(self) -> None:
        if self.num_timesteps >= self.next_eval:
            self.next_eval = (self.num_timesteps // self.eval_every + 1) * self.eval_every
            self.solved = self.tracker.evaluate(self.num_timesteps, self.policy_now()) or self.solved

    def _on_rollout_start(self) -> None:
        if self.on_policy:
            self._maybe_evaluate()

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", []):
            if "episode" in info:
                self.tracker.episode(self.num_timesteps, float(info["episode"]["r"]), int(info["episode"]["l"]))
        if not self.on_policy:
            self._maybe_evaluate()
        return not (self.until_solved and self.solved)


def build_model(cfg: TrainConfig, run_dir: Path) -> BaseAlgorithm:
    """The SB3 algorithm on a vectorized (optionally normalized) env."""
    env_cfg = cfg.env
    vec_cls = SubprocVecEnv if cfg.n_envs > 1 else DummyVecEnv
    venv = make_vec_env(lambda: make_env(env_cfg), n_envs=cfg.n_envs, seed=cfg.seed, vec_env_cls=vec_cls)
    if cfg.normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=False, clip_obs=10.0)
    kwargs = dict(cfg.hyperparams)
    if cfg.lr is not None:
        kwargs["learning_rate"] = parse_schedule(cfg.lr, "learning-rate")
    if cfg.clip_range is not None:
        if cfg.algo != "ppo":
            raise MotorlabError(f"--clip-range applies to PPO only, not {cfg.algo}; drop it or use --algo ppo.")
        kwargs["clip_range"] = parse_schedule(cfg.clip_range, "clip-range")
    try:
        return ALGORITHMS[cfg.algo]("MlpPolicy", venv, seed=cfg.seed, device=cfg.device, verbose=0,
                                    tensorboard_log=str(run_dir / "tensorboard"), **kwargs)
    except TypeError as e:
        raise MotorlabError(f"bad hyperparameter for {cfg.algo.upper()}: {e}; see the SB3 documentation of {cfg.algo.upper()}.") from None


def train_sb3(cfg: TrainConfig, run_dir: Path, tracker: Tracker) -> int:
    """Train, save model.zip (for continuing) and the pickle-free policy. Returns env steps used."""
    model = build_model(cfg, run_dir)
    on_policy = cfg.algo == "ppo"
    eval_every = cfg.eval_every or (model.n_steps * cfg.n_envs if on_policy else 1000)
    callback = TrackingCallback(tracker, eval_every, on_policy, cfg.until_solved)
    model.learn(total_timesteps=cfg.timesteps, callback=callback, progress_bar=cfg.progress,
                tb_log_name=cfg.algo.upper())
    steps = int(model.num_timesteps)
    if tracker.last_eval_steps < steps and not callback.solved:
        # The last update used every step so far and has not been evaluated yet.
        tracker.evaluate(steps, callback.policy_now())
    if callback.solved and on_policy and tracker.steps_to_success is not None:
        steps = tracker.steps_to_success  # the next rollout was cut after its first step
    _save_model(model, run_dir)
    venv = model.get_env()
    save_sb3_policy(run_dir, model, cfg.algo, venv if isinstance(venv, VecNormalize) else None)
    model.get_env().close()
    return steps


def _save_model(model: BaseAlgorithm, run_dir: Path) -> None:
    """SB3's zip (optimizer state included), written atomically. Loading it unpickles,
    so motorlab itself reads policy.safetensors instead."""
    import io

    buf = io.BytesIO()
    model.save(buf)
    atomic_write_bytes(run_dir / "model.zip", buf.getvalue())
