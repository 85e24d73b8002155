"""The oracle: MPC that plans on the true simulator, the limit MPC on a learned model can reach.

`SimulatorScorer` scores the batched CEM's candidate action sequences (motorlab.planning.mpc) by
rolling each through a private copy of the env, from the controlled env's physics state, and
summing the env's own rewards (`env.step`'s: any Gymnasium MuJoCo env, a user's with its own reward
too). The ending step of a candidate that terminates is paid; the steps after it are not simulated.
A time limit is not a termination: the copy's truncations are ignored, as a learned model's planner
knows none. A candidate that makes MuJoCo reset a diverging state, or whose reward is NaN or Inf,
scores NaN: the planner rejects it (where the controlled env's NumericalGuard would end the episode).

The state the planner passes around is MuJoCo's integration state, `mj_getState(model, data, state,
mjSTATE_INTEGRATION)` as float64 (`physics_state`): time, qpos, qvel, act, the solver's warm start,
mocap poses, userdata, plugin state, active equalities, ctrl and the applied forces, i.e. everything
`mj_step` reads (a superset of mjSTATE_FULLPHYSICS, and of Gymnasium's `set_state(qpos, qvel)`);
`mj_setState` + `mj_forward` put it into the copy, which then steps exactly as the controlled env
would (tests/planning/test_oracle.py checks it to the last bit on InvertedPendulum-v5 and Reacher-v5).

What a user's env must satisfy for the oracle to be exact: its reward and termination are functions
of that MuJoCo state, the model and the action, and of what its `reset(seed)` draws (the scorer
resets its copy with each episode's seed, so a goal drawn at reset, in the model or in a Python
attribute, is the controlled env's too). State kept elsewhere and changed by `step` (a step counter,
the last action in a Python attribute) is not copied: the copy's own is used. Env settings that keep
such state or draw noise every step (delay, latency, action noise, pushes, MyoSuite's motor noise and
fatigue) are refused.

Speed: a plan costs population x horizon x iterations Python `env.step` calls, one candidate after
another. The scorer steps the env past its bookkeeping wrappers (time limit, order and checker,
NumericalGuard, observation flattening and stacking: ~20% of a step) and checks for divergence once
per candidate: ~9 us a step on the pendulum, ~23 us on the arm (RK4, two substeps), i.e. ~40 and
~105 ms a control step at horizon 15, population 100, 3 iterations on an idle CPU core. Neither threads
(the reward code holds the GIL: two were measured no faster) nor `mujoco.rollout` help (it gives the
physics, not the env's reward; recomputing that from its states would not be exact for a reward that
reads derived quantities, such as Reacher's body positions, which `mj_step` leaves one substep behind).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import gymnasium as gym
import mujoco
import numpy as np
import torch
from gymnasium.wrappers import FlattenObservation, FrameStackObservation, OrderEnforcing, PassiveEnvChecker, TimeLimit
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from motorlab.envs import EnvConfig, make_env
from motorlab.envs.disturbances import mujoco_model_data
from motorlab.envs.wrappers import NumericalGuard
from motorlab.errors import MotorlabError
from motorlab.planning.mpc_episodes import env_config, require_plannable
from motorlab.planning.planners.cem import CEMPlanner

STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # what `physics_state` reads and the scorer sets

# EnvConfig settings that keep state outside the simulation, or draw random numbers every step that
# change what the env does: a copy of the physics state cannot reproduce them, so the oracle refuses them
_HIDDEN_STATE = {
    "delay": "--delay keeps its filter's state outside the simulation",
    "latency": "--latency keeps its queue of actions outside the simulation",
    "action_noise": "--action-noise draws new noise on every action",
    "push_body": "--push-body pushes at random times",
    "motor_noise": "--motor-noise draws new noise on every excitation",
    "fatigue": "--fatigue keeps the muscles' fatigue outside the simulation",
}


# Wrappers that change neither the action nor the reward nor the termination (the scorer ignores time
# limits, and does NumericalGuard's work itself): the scorer steps past them, ~20% faster per step
_BOOKKEEPING = (NumericalGuard, TimeLimit, OrderEnforcing, PassiveEnvChecker, FlattenObservation, FrameStackObservation)
_BAD = [int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
        int(mujoco.mjtWarning.mjWARN_BADQACC)]


def step_target(env: gym.Env) -> gym.Env:
    """The outermost layer of `env` whose `step` may change the action, reward or termination: `env`
    past its bookkeeping wrappers (exact types: a subclass may do more), e.g. the bare Gymnasium env,
    or a synergy action wrapper (--sar), or a wrapper a user's env registers."""
    while type(env) in _BOOKKEEPING:
        env = env.env
    return env


def _mujoco(env, env_id: str | None = None):
    """The env's MjModel and MjData; one line naming the env (`env_id`, else its spec's id or class) if it has none."""
    model, data = mujoco_model_data(env)
    if model is None:
        env_id = env_id or getattr(env.unwrapped.spec, "id", None) or type(env.unwrapped).__name__
        raise MotorlabError(f"the oracle plans on the simulator by copying its MuJoCo state, and {env_id} is not "
                            "a MuJoCo env (no MjModel at env.unwrapped.model); plan on a learned model instead "
                            f"(`motorlab mbrl {env_id}`).")
    return model, data


def physics_state(env) -> np.ndarray:
    """The MuJoCo integration state of `env` (float64, (mj_stateSize(model, STATE),)): what the oracle plans from.

    Raises:
        MotorlabError: `env` is not a MuJoCo env.
    """
    model, data = _mujoco(env)
    state = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state, STATE)
    return state


def set_physics_state(env, state: np.ndarray) -> None:
    """Put a state from `physics_state` into `env`, its derived quantities (positions of bodies, ...) recomputed."""
    model, data = _mujoco(env)
    mujoco.mj_setState(model, data, np.asarray(state, dtype=np.float64), STATE)
    mujoco.mj_forward(model, data)


def refuse_hidden_state(cfg: EnvConfig) -> None:
    """Refuse, in one line, env settings whose state a copy of the simulation cannot hold."""
    for field, why in _HIDDEN_STATE.items():
        value = getattr(cfg, field)
        if value is not None and value != "off":
            raise MotorlabError(f"the oracle plans on a copy of the simulation's state, and {why}: drop it to "
                                f"measure the oracle on {cfg.id}.")


class SimulatorScorer:
    """A `Scorer` (motorlab.planning.mpc) on the true simulator: each candidate's return when its actions
    are stepped through a private copy of the env (made from the same EnvConfig, sharing no MjData with
    the controlled env) from its start state.

    `states` (N, S) are `physics_state`s, float64; `goals` are not read (pass (N, 0)). Returns (N,) float64.
    Call `reset(seed)` when the controlled env resets with `seed`, so that what its reset draws outside
    the physics state matches.
    """

    def __init__(self, env: EnvConfig | str):
        self.cfg = env_config(env)
        refuse_hidden_state(self.cfg)
        self.env = make_env(self.cfg, shaped=False)  # the env's own reward, as MPC's evaluation reports it
        try:
            self.model, self.data = _mujoco(self.env, self.cfg.id)
        except MotorlabError:
            self.env.close()
            raise
        self.state_size = mujoco.mj_stateSize(self.model, STATE)
        self._target = step_target(self.env)
        self.env.reset(seed=0)  # a Gymnasium env steps only after a reset

    def reset(self, seed: int | None = None) -> None:
        """Reset the copy as the controlled env was (the same seed)."""
        self.env.reset(seed=seed)

    def close(self) -> None:
        self.env.close()

    def __call__(self, states: torch.Tensor, actions: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        if states.dtype != torch.float64 or states.shape[-1] != self.state_size:
            raise MotorlabError(f"the simulator scorer takes MuJoCo states as float64 (N, {self.state_size}) "
                                f"(motorlab.planning.oracle.physics_state), got {tuple(states.shape)} {states.dtype}.")
        starts = states.cpu().numpy()
        plans = actions.cpu().numpy()
        model, data, step = self.model, self.data, self._target.step
        returns = np.zeros(len(plans))
        seen = self._instabilities()
        for i, plan in enumerate(plans):
            mujoco.mj_setState(model, data, starts[i], STATE)
            mujoco.mj_forward(model, data)  # a reward that reads body positions before simulating finds them
            total = 0.0
            for action in plan:
                reward, terminated = step(action)[1:3]
                total += reward
                if terminated:  # the ending step is paid, the steps after it are not
                    break
            count = self._instabilities()
            returns[i] = total if count == seen else np.nan  # MuJoCo reset a diverging state: rejected
            seen = count
        return torch.from_numpy(returns).to(actions.device)

    def _instabilities(self) -> int:
        """How often MuJoCo has reset the copy's diverging state (its bad qpos, qvel, qacc warnings)."""
        return int(self.data.warning.number[_BAD].sum())


@dataclass(frozen=True, eq=False)
class OracleResult:
    """Episodes of the oracle: MPC (CEM) planning on the true simulator."""

    env: str  # the env's id
    returns: np.ndarray  # (episodes,) the env's own return of each episode
    lengths: np.ndarray  # (episodes,) its steps
    plan_ms: np.ndarray  # (control steps,) the planning time of every control step, all episodes in turn
    seeds: tuple[int, ...]  # each episode's reset seed
    horizon: int
    population: int
    iterations: int
    elites: int
    seed: int  # the planner's

    @property
    def plan_ms_median(self) -> float:
        return float(np.median(self.plan_ms))


def oracle_episodes(env: EnvConfig | str, episodes: int, seeds: list[int], *, horizon: int = 15,
                    population: int = 100, iterations: int = 3, elites: int = 10, noise_beta: float = 0.0,
                    seed: int = 0, progress: bool = False) -> OracleResult:
    """Episodes of MPC that plans on the true simulator: the limit a learned model's MPC can reach.

    Every control step, CEM (motorlab.planning.planners.cem.CEMPlanner, warm-started from the last plan, reset
    at each episode) plans from the env's physics state, scoring candidates with `SimulatorScorer`.

    Args:
        env: an env id, or an EnvConfig (its settings that keep state outside the simulation refused).
        episodes: how many episodes; episode i resets with `seeds[i]`.
        seeds: the reset seeds, one per episode.
        horizon, population, iterations, elites, noise_beta: the CEM's settings.
        seed: the planner's seed.
        progress: show a progress bar.

    Returns:
        The returns, lengths and planning times, with the settings used.

    Raises:
        MotorlabError: not one seed per episode, bad planner settings, an env that is not MuJoCo,
            whose actions are not bounded Boxes, or with a setting the copy cannot reproduce.
    """
    cfg = env_config(env)
    if episodes <= 0:
        raise MotorlabError(f"episodes must be positive, got {episodes}.")
    seeds = [int(s) for s in seeds]
    if len(seeds) != episodes:
        raise MotorlabError(f"give one reset seed per episode: {episodes} episodes, {len(seeds)} seeds.")
    refuse_hidden_state(cfg)
    controlled = make_env(cfg, shaped=False)
    scorer = None
    try:
        require_plannable(controlled, cfg.id, user="the oracle")
        _mujoco(controlled, cfg.id)
        scorer = SimulatorScorer(cfg)
        space = controlled.action_space
        planner = CEMPlanner(scorer, space.low, space.high, horizon=horizon, population=population,
                             iterations=iterations, elites=elites, seed=seed, noise_beta=noise_beta)
        goals = torch.zeros((1, 0))
        returns, lengths, plan_ms = [], [], []
        columns = (TextColumn("oracle {task.description}"), BarColumn(),
                   TextColumn("{task.completed}/{task.total} episodes"), TimeElapsedColumn())
        with Progress(*columns, disable=not progress) as bar:
            task = bar.add_task(cfg.id, total=episodes)
            for s in seeds:
                controlled.reset(seed=s)
                scorer.reset(s)
                planner.reset(1)
                total, steps, done = 0.0, 0, False
                while not done:
                    start = time.perf_counter()
                    state = torch.from_numpy(physics_state(controlled))[None]
                    action = planner.plan(state, goals)[0].numpy()
                    plan_ms.append((time.perf_counter() - start) * 1000)
                    _, reward, terminated, truncated, _ = controlled.step(action)
                    total += float(reward)
                    steps += 1
                    done = terminated or truncated
                returns.append(total)
                lengths.append(steps)
                bar.advance(task)
    finally:
        controlled.close()
        if scorer is not None:
            scorer.close()
    return OracleResult(cfg.id, np.array(returns), np.array(lengths), np.array(plan_ms), tuple(seeds), horizon,
                        population, iterations, elites, seed)
