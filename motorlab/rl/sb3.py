"""Stable-Baselines3 training with motorlab's tracking, for every SB3 algorithm in algos/
(each says its class, policy, HER, settings checks and evaluation cadence; on- or off-policy is its type).

Training envs keep a Dict observation (goal-conditioned tasks) as a Dict: the networks are SB3's
MultiInputPolicy, and --her relabels goals with SB3's HerReplayBuffer. Everything after training
(evaluation, videos, export) gives the policy flat observations; `SB3Policy` turns them back.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import os
import sys
import tempfile
import time
import typing
from pathlib import Path

import gymnasium as gym
from pydantic import TypeAdapter, ValidationError
from pydantic.errors import PydanticSchemaGenerationError
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import TensorBoardOutputFormat
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

from motorlab import algos, processes, trackers, user_modules
from motorlab.algos import OnPolicy, SB3Algorithm
from motorlab.envs import make_env
from motorlab.envs.spaces import is_dict
from motorlab.envs.wrappers import user_code_error
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.evaluation import EpisodeSuccess, success_mode
from motorlab.faults import fault_of
from motorlab.policies import SB3Policy, flat_statistics, normalization, save_sb3_policy
from motorlab.rl.config import TrainConfig
from motorlab.rl.monitor import TrainingMonitor
from motorlab.rl.schedules import parse_schedule
from motorlab.runs import atomic_write_bytes

# The SB3 algorithms (those that take hyperparameters), by name: `algo in ALGORITHMS` asks that.
ALGORITHMS: dict[str, SB3Algorithm] = {name: a for name, a in algos.registry().items() if isinstance(a, SB3Algorithm)}


class MonitorCallback(BaseCallback):
    """Feeds episodes and evaluations to the TrainingMonitor; stops when solved.

    On-policy algorithms change their policy only between rollouts, so they are
    evaluated at the start of each rollout (right after the update); off-policy
    ones every `eval_every` steps, or every `eval_minutes` minutes of training.
    With `minutes`, training stops at the first step past that many minutes of
    training (the monitor's train_seconds: evaluations and checkpoints not counted).
    """

    def __init__(self, monitor: TrainingMonitor, eval_every: int, on_policy: bool, until_solved: bool,
                 run_dir: Path | None = None, checkpoint_every: int = 0, start: int = 0,
                 minutes: float | None = None, eval_minutes: float | None = None):
        super().__init__()
        self.monitor, self.eval_every, self.on_policy, self.until_solved = monitor, eval_every, on_policy, until_solved
        self.next_eval = (start // eval_every + 1) * eval_every if start else eval_every
        self.budget_s = minutes * 60 if minutes is not None else None
        self.eval_period_s = eval_minutes * 60 if eval_minutes is not None else None
        if self.eval_period_s is not None:  # resumed: the next multiple of the period after the training so far
            self.next_eval_s = (monitor.train_seconds() // self.eval_period_s + 1) * self.eval_period_s
        self.run_dir, self.checkpoint_every = run_dir, checkpoint_every
        self.next_checkpoint = (start // checkpoint_every + 1) * checkpoint_every if checkpoint_every else None
        self.solved = False
        self.algorithm = ALGORITHMS[monitor.cfg.algo]

    def _on_training_start(self) -> None:
        # training success only where the env says what success is (its flag): without one, a
        # return target would judge stochastic exploration episodes (0% beside a solved policy)
        self.outcome = EpisodeSuccess(self.training_env.num_envs, None, success_mode(self.monitor.cfg.env))
        for output in self.logger.output_formats:  # SB3's TensorBoard scalars also go to the tracked run, if any
            if isinstance(output, TensorBoardOutputFormat):
                trackers.mirror(output.writer)

    def policy_now(self) -> SB3Policy:
        # SB3Policy switches the network to eval mode; SB3 switches it back in train().
        venv = self.model.get_env()
        stats = normalization(venv, self.model.observation_space) if isinstance(venv, VecNormalize) else None
        if stats is not None:
            return SB3Policy(self.model.policy, *flat_statistics(stats), venv.clip_obs, venv.epsilon,
                             algorithm=self.algorithm)
        return SB3Policy(self.model.policy, algorithm=self.algorithm)

    def _maybe_evaluate(self) -> None:
        if self.eval_period_s is not None:
            trained = self.monitor.train_seconds()
            if trained < self.next_eval_s:
                return
            self.next_eval_s = (trained // self.eval_period_s + 1) * self.eval_period_s
        elif self.num_timesteps >= self.next_eval:
            self.next_eval = (self.num_timesteps // self.eval_every + 1) * self.eval_every
        else:
            return
        self.solved = self.monitor.evaluate(self.num_timesteps, self.policy_now()) or self.solved

    def _maybe_checkpoint(self) -> None:
        if self.next_checkpoint is not None and self.num_timesteps >= self.next_checkpoint:
            from motorlab.rl.checkpoint import save_checkpoint

            started = time.perf_counter()
            save_checkpoint(self.run_dir, self.model, self.monitor.state())
            self.monitor.pause(started)
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
                self.monitor.episode(self.num_timesteps, ret, int(info["episode"]["l"]),
                                     success=self.outcome.end(i, ret), fault=fault_of(info))
        if not self.on_policy:
            self._maybe_evaluate()
            self._maybe_checkpoint()
        if self.budget_s is not None and self.monitor.train_seconds() >= self.budget_s:
            self.monitor.out_of_time = True
            return False
        return not (self.until_solved and self.solved)


def build_model(cfg: TrainConfig, run_dir: Path) -> BaseAlgorithm:
    """The SB3 algorithm on a vectorized (optionally normalized) env: MlpPolicy on a Box observation,
    MultiInputPolicy on a Dict one; with --her, SB3's HerReplayBuffer.

    Raises:
        MotorlabError: settings SB3 refuses (one line naming them).
    """
    env_cfg = cfg.env
    vec_cls = SubprocVecEnv if cfg.n_envs > 1 else DummyVecEnv
    parent, imports = os.getpid(), user_modules.imported_names()
    _worker_report(parent).unlink(missing_ok=True)

    def env_fn() -> gym.Env:
        if os.getpid() == parent:
            return make_env(env_cfg, dict_obs=True)
        report = _worker_report(parent)
        try:
            processes.serve_parent(parent)  # a SubprocVecEnv worker: stopped by this process, and with it
            user_modules.adopt(imports)  # SB3 starts workers from a fork server: its environment may be stale
            return _ReportsFailure(make_env(env_cfg, dict_obs=True), report)
        except BaseException as e:  # SB3's worker would die with the trainer seeing only a reset pipe
            error = e if isinstance(e, MotorlabError) else user_code_error(f"making {env_cfg.id}", e)
            _leave_report(report, f"an env worker of --n-envs could not make its env: {error}")
            os._exit(2)  # quietly: the trainer says it, once (SB3's worker would print its traceback)

    try:
        venv = make_vec_env(env_fn, n_envs=cfg.n_envs, seed=cfg.seed, vec_env_cls=vec_cls)
    except (EOFError, BrokenPipeError, ConnectionResetError):  # a worker stopped before it sent its spaces
        raise MotorlabError(_worker_failure()) from None
    if cfg.normalize:  # a Dict observation: running statistics per key
        venv = VecNormalize(venv, norm_obs=True, norm_reward=False, clip_obs=10.0)
    algo = ALGORITHMS[cfg.algo]
    name = algo.title
    try:
        policy = algo.policy(is_dict(venv.observation_space), cfg.env.id)
        kwargs = check_hyperparams(cfg.algo, cfg.hyperparams)
        if cfg.her:
            kwargs.update(her_settings(kwargs, episode_steps(venv)))
    except MotorlabError:
        venv.close()
        raise
    if cfg.lr is not None:
        kwargs["learning_rate"] = parse_schedule(cfg.lr, "learning-rate")
    if cfg.clip_range is not None:
        kwargs["clip_range"] = parse_schedule(cfg.clip_range, "clip-range")
    try:
        return algo.sb3_class()(policy, venv, seed=cfg.seed, device=cfg.device, verbose=0,
                                tensorboard_log=str(run_dir / "tensorboard"), **kwargs)
    except (TypeError, ValueError, AssertionError) as e:  # SB3 checks its arguments with asserts
        venv.close()
        raise MotorlabError(f"bad hyperparameters for {name} ({e or type(e).__name__}); "
                            f"see the Stable-Baselines3 documentation of {name}.") from None


# HER's defaults (Andrychowicz et al. 2017, and SB3's): 4 relabelled goals per transition, each
# a goal achieved later in the same episode
HER_DEFAULTS = {"goal_selection_strategy": "future", "n_sampled_goal": 4}


def her_settings(kwargs: dict, episode: int | None) -> dict:
    """The keyword arguments --her adds to SAC's or TD3's: HerReplayBuffer with HER_DEFAULTS under the
    user's replay_buffer_kwargs, and learning_starts of at least one episode (HER samples goals from
    finished episodes only; SB3 raises mid-training when asked to sample before one ended).

    Raises:
        MotorlabError: a learning_starts given below the episode length.
    """
    out = {"replay_buffer_class": HerReplayBuffer,
           "replay_buffer_kwargs": {**HER_DEFAULTS, **(kwargs.get("replay_buffer_kwargs") or {})}}
    if episode is not None:
        starts = kwargs.get("learning_starts")
        if starts is None:
            out["learning_starts"] = max(episode, 100)  # SB3's default, or a whole episode
        elif starts < episode:
            raise MotorlabError(f"--her samples goals from finished episodes, so learning_starts ({starts}) must be "
                                f"at least the episode length ({episode} steps); raise it or leave it out.")
    return out


def episode_steps(venv: VecEnv) -> int | None:
    """The time limit of the vectorized envs' episodes (None: none)."""
    spec = venv.get_attr("spec", [0])[0]
    return spec.max_episode_steps if spec is not None else None


def check_hyperparams(algo: str, params: dict) -> dict:
    """Unknown names and wrongly typed values, judged by the SB3 class's own signature.

    Returns:
        The values converted to the annotated types (TOML/JSON lists become tuples, 1e3 an int).

    Raises:
        MotorlabError: naming the parameter, what it should be and close matches.
    """
    title = ALGORITHMS[algo].title
    cls = ALGORITHMS[algo].sb3_class()
    fixed = {"self", "policy", "env", "seed", "device", "verbose", "tensorboard_log", "_init_setup_model"}
    allowed = [p for p in inspect.signature(cls.__init__).parameters if p not in fixed]
    hints = _init_annotations(cls)
    checked = dict(params)
    for key, value in params.items():
        if key not in allowed:
            raise MotorlabError(f"unknown hyperparameter {key!r} for {title}{did_you_mean(key, allowed)}.")
        if key not in hints:
            continue
        try:
            checked[key] = TypeAdapter(hints[key]).validate_python(value)
        except PydanticSchemaGenerationError:
            continue  # a type pydantic cannot check (e.g. a class); SB3 checks it
        except ValidationError:
            hint = getattr(hints[key], "__name__", str(hints[key]).replace("typing.", ""))
            raise MotorlabError(f"hyperparameter {key}={value!r} for {title} should be {hint}.") from None
    return checked


def train_sb3(cfg: TrainConfig, model: BaseAlgorithm, run_dir: Path, monitor: TrainingMonitor) -> int:
    """Train `model` (from build_model; restored from a checkpoint when resuming) to the
    budget, checkpointing as it goes; save model.zip (for continuing with SB3) and the
    pickle-free policy. Returns env steps used."""
    algo = ALGORITHMS[cfg.algo]
    on_policy = isinstance(algo, OnPolicy)  # its type says when the policy changes, so when to evaluate
    eval_every = cfg.eval_every or algo.eval_every(model, cfg.n_envs)
    every = cfg.checkpoint_every if cfg.checkpoint_every is not None else max(1, cfg.timesteps // 10)
    start = int(model.num_timesteps)
    callback = MonitorCallback(monitor, eval_every, on_policy, cfg.until_solved, run_dir, every, start,
                               minutes=cfg.minutes, eval_minutes=cfg.eval_every_minutes)
    if cfg.minutes is not None and monitor.train_seconds() >= cfg.minutes * 60:  # resumed past it
        monitor.out_of_time = True
    out_of_time = monitor.out_of_time
    if start < cfg.timesteps and not (cfg.until_solved and monitor.steps_to_success is not None) and not out_of_time:
        # resumed: SB3 counts on from num_timesteps; the schedules see the same total budget
        try:
            model.learn(total_timesteps=cfg.timesteps - start, callback=callback, progress_bar=cfg.progress,
                        tb_log_name=algo.title, reset_num_timesteps=start == 0)
        except (EOFError, BrokenPipeError, ConnectionResetError):  # a SubprocVecEnv worker is gone
            raise MotorlabError(_worker_failure()) from None
    steps = int(model.num_timesteps)
    # stopped once solved: the saved policy is the one the solving evaluation judged
    stopped = cfg.until_solved and monitor.steps_to_success is not None
    if monitor.last_eval_steps < steps and not stopped:
        # The last update used every step so far and has not been evaluated yet.
        monitor.evaluate(steps, callback.policy_now())
    if stopped and on_policy:
        # the next rollout was cut after its first step, which no update used: the policy saved
        # learned from steps_to_success steps. Without --until-solved training goes on to the
        # budget whatever an evaluation solved, and the steps trained are all of them.
        steps = monitor.steps_to_success
    _save_model(model, run_dir)
    venv = model.get_env()
    save_sb3_policy(run_dir, model, cfg.algo, venv if isinstance(venv, VecNormalize) else None)
    model.get_env().close()
    return steps


def _worker_report(parent: int) -> Path:
    """Where a SubprocVecEnv worker of process `parent` leaves the line saying why it stopped."""
    return Path(tempfile.gettempdir()) / f"motorlab-env-worker-{parent}.txt"


class _ReportsFailure(gym.Wrapper):
    """A SubprocVecEnv worker's env: when it fails as the user's code can (a MotorlabError, e.g. its step
    raising: envs.wrappers.user_code_error's one line), the line is left for the trainer and the worker
    leaves quietly. Without it SB3's worker prints a traceback and the trainer sees only a closed pipe."""

    def __init__(self, env: gym.Env, report: Path):
        super().__init__(env)
        self._report = report

    def step(self, action):
        try:
            return self.env.step(action)
        except MotorlabError as e:
            self._leave(e)

    def reset(self, **kwargs):
        try:
            return self.env.reset(**kwargs)
        except MotorlabError as e:
            self._leave(e)

    def _leave(self, e: MotorlabError) -> None:
        _leave_report(self._report, f"an env worker of --n-envs: {e}")
        os._exit(2)


def _leave_report(report: Path, line: str) -> None:
    """The worker's one line for the trainer (`_worker_failure` reads it), written whole (temp file, then rename):
    several workers may fail at once, and the trainer must never read half a line."""
    with contextlib.suppress(OSError):
        tmp = report.with_name(f"{report.name}.{os.getpid()}.tmp")
        tmp.write_text(line)
        os.replace(tmp, report)


def _worker_failure() -> str:
    """The line a SubprocVecEnv worker left before it stopped (removed once read), or what is known."""
    report = _worker_report(os.getpid())
    try:
        line = report.read_text().strip()
        report.unlink()
        return line
    except OSError:
        return ("an env worker of --n-envs stopped unexpectedly (killed, or out of memory); run with --n-envs 1 to "
                "see the env's own error.")


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
