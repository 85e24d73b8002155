"""Stable-Baselines3 training (PPO, SAC, TD3) with motorlab's tracking."""

from __future__ import annotations

import inspect
import io
import sys
import typing
from pathlib import Path

from pydantic import TypeAdapter, ValidationError
from pydantic.errors import PydanticSchemaGenerationError
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import TensorBoardOutputFormat
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from motorlab import trackers
from motorlab.envs import make_env
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.evaluation import EpisodeSuccess, success_mode
from motorlab.faults import fault_of
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

    def __init__(self, tracker: Tracker, eval_every: int, on_policy: bool, until_solved: bool,
                 run_dir: Path | None = None, checkpoint_every: int = 0, start: int = 0):
        super().__init__()
        self.tracker, self.eval_every, self.on_policy, self.until_solved = tracker, eval_every, on_policy, until_solved
        self.next_eval = (start // eval_every + 1) * eval_every if start else eval_every
        self.run_dir, self.checkpoint_every = run_dir, checkpoint_every
        self.next_checkpoint = (start // checkpoint_every + 1) * checkpoint_every if checkpoint_every else None
        self.solved = False

    def _on_training_start(self) -> None:
        # training success only where the env says what success is (its flag): without one, a
        # return target would judge stochastic exploration episodes (0% beside a solved policy)
        self.outcome = EpisodeSuccess(self.training_env.num_envs, None, success_mode(self.tracker.cfg.env))
        for output in self.logger.output_formats:  # SB3's TensorBoard scalars also go to the tracked run, if any
            if isinstance(output, TensorBoardOutputFormat):
                trackers.mirror(output.writer)

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

    def _maybe_checkpoint(self) -> None:
        if self.next_checkpoint is not None and self.num_timesteps >= self.next_checkpoint:
            from motorlab.rl.checkpoint import save_checkpoint

            save_checkpoint(self.run_dir, self.model, self.tracker.state())
            self.next_checkpoint = (self.num_timesteps // self.checkpoint_every + 1) * self.checkpoint_every

    def _on_rollout_start(self) -> None:
        if self.on_policy:  # between updates: the cleanest place to evaluate and to checkpoint
            self._maybe_evaluate()
            self._maybe_checkpoint()

    def _on_step(self) -> bool:
        for i, info in enumerate(self.locals.get("infos", [])):
            self.outcome.step(i, info)
            if "episode" in info:
                ret = float(info["episode"]["r"])
                self.tracker.episode(self.num_timesteps, ret, int(info["episode"]["l"]),
                                     success=self.outcome.end(i, ret), fault=fault_of(info))
        if not self.on_policy:
            self._maybe_evaluate()
            self._maybe_checkpoint()
        return not (self.until_solved and self.solved)


def build_model(cfg: TrainConfig, run_dir: Path) -> BaseAlgorithm:
    """The SB3 algorithm on a vectorized (optionally normalized) env."""
    env_cfg = cfg.env
    vec_cls = SubprocVecEnv if cfg.n_envs > 1 else DummyVecEnv
    venv = make_vec_env(lambda: make_env(env_cfg), n_envs=cfg.n_envs, seed=cfg.seed, vec_env_cls=vec_cls)
    if cfg.normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=False, clip_obs=10.0)
    kwargs = check_hyperparams(cfg.algo, cfg.hyperparams)
    if cfg.lr is not None:
        kwargs["learning_rate"] = parse_schedule(cfg.lr, "learning-rate")
    if cfg.clip_range is not None:
        kwargs["clip_range"] = parse_schedule(cfg.clip_range, "clip-range")
    name = cfg.algo.upper()
    try:
        return ALGORITHMS[cfg.algo]("MlpPolicy", venv, seed=cfg.seed, device=cfg.device, verbose=0,
                                    tensorboard_log=str(run_dir / "tensorboard"), **kwargs)
    except (TypeError, ValueError, AssertionError) as e:  # SB3 checks its arguments with asserts
        venv.close()
        raise MotorlabError(f"bad hyperparameters for {name} ({e or type(e).__name__}); "
                            f"see the Stable-Baselines3 documentation of {name}.") from None


def check_hyperparams(algo: str, params: dict) -> dict:
    """Unknown names and wrongly typed values, judged by the SB3 class's own signature.

    Returns:
        The values converted to the annotated types (TOML/JSON lists become tuples, 1e3 an int).

    Raises:
        MotorlabError: naming the parameter, what it should be and close matches.
    """
    cls = ALGORITHMS[algo]
    fixed = {"self", "policy", "env", "seed", "device", "verbose", "tensorboard_log", "_init_setup_model"}
    allowed = [p for p in inspect.signature(cls.__init__).parameters if p not in fixed]
    hints = _init_annotations(cls)
    checked = dict(params)
    for key, value in params.items():
        if key not in allowed:
            raise MotorlabError(f"unknown hyperparameter {key!r} for {algo.upper()}{did_you_mean(key, allowed)}.")
        if key not in hints:
            continue
        try:
            checked[key] = TypeAdapter(hints[key]).validate_python(value)
        except PydanticSchemaGenerationError:
            continue  # a type pydantic cannot check (e.g. a class); SB3 checks it
        except ValidationError:
            hint = getattr(hints[key], "__name__", str(hints[key]).replace("typing.", ""))
            raise MotorlabError(f"hyperparameter {key}={value!r} for {algo.upper()} should be {hint}.") from None
    return checked


def train_sb3(cfg: TrainConfig, model: BaseAlgorithm, run_dir: Path, tracker: Tracker) -> int:
    """Train `model` (from build_model; restored from a checkpoint when resuming) to the
    budget, checkpointing as it goes; save model.zip (for continuing with SB3) and the
    pickle-free policy. Returns env steps used."""
    on_policy = cfg.algo == "ppo"
    eval_every = cfg.eval_every or (model.n_steps * cfg.n_envs if on_policy else 1000)
    every = cfg.checkpoint_every if cfg.checkpoint_every is not None else max(1, cfg.timesteps // 10)
    start = int(model.num_timesteps)
    callback = TrackingCallback(tracker, eval_every, on_policy, cfg.until_solved, run_dir, every, start)
    if start < cfg.timesteps and not (cfg.until_solved and tracker.steps_to_success is not None):
        # resumed: SB3 counts on from num_timesteps; the schedules see the same total budget
        model.learn(total_timesteps=cfg.timesteps - start, callback=callback, progress_bar=cfg.progress,
                    tb_log_name=cfg.algo.upper(), reset_num_timesteps=start == 0)
    steps = int(model.num_timesteps)
    callback.solved = callback.solved or (cfg.until_solved and tracker.steps_to_success is not None)
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
    buf = io.BytesIO()
    model.save(buf)
    atomic_write_bytes(run_dir / "model.zip", buf.getvalue())


def _init_annotations(cls: type) -> dict:
    """Resolved annotations of `cls.__init__` and its bases (SB3 annotates with strings), each
    resolved on its own with typing.get_type_hints: names SB3 imports only for type checking do
    not resolve and are left to SB3."""
    hints: dict = {}
    for base in reversed(cls.__mro__):
        init = base.__dict__.get("__init__")
        namespace = vars(sys.modules[base.__module__])
        for name, ann in getattr(init, "__annotations__", {}).items():
            holder = _annotated(name, ann)
            try:
                hints[name] = typing.get_type_hints(holder, globalns=namespace)[name]
            except Exception:  # a name SB3 imports under TYPE_CHECKING only
                hints.pop(name, None)
    return hints


def _annotated(name: str, ann) -> object:
    """An object carrying one annotation, for typing.get_type_hints to resolve."""

    def holder() -> None: ...

    holder.__annotations__ = {name: ann}
    return holder
