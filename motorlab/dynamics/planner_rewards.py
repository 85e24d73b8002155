"""What the planner maximizes: rewards and terminations in torch, on the states of a state layout.

A `StateFn` takes batched torch tensors (state, action, next_state, goal) with shapes (..., S),
(..., A), (..., S), (..., G) and returns (...,): a reward (float) or a termination (bool). The
planner scores predicted paths with them; `resolve_task` picks them from one of three sources:

- `builtin`: the env's catalogue entry's task (motorlab.envs.catalog, `EnvFacts.planning`): for the
  bundled envs the rewards below, the Gymnasium envs' own (same weights, scored on the observation
  before or after the step as the env does; tests/dynamics/test_rewards.py checks them against the envs'
  transitions). Add one with `register(env_id, layout, reward, termination)`, or declare a user
  function for your env: `motorlab.register_env(ENV_ID, reward="module:function")`.
- `MODULE:FUNCTION`: the user's torch function (obs, action, next_obs) -> reward (or -> bool for a
  termination), batched over any leading dimensions; it sees the planner's state (the observation
  in the default "observation" layout). `load_function` imports it, `resolve_task` checks it on
  probe tensors.
- `learned`: a head of the forward model fitted with the dynamics (`Task.reward` is then None).
- `goal`: for a goal-conditioned env (a Dict observation with achieved_goal and desired_goal, e.g.
  Gymnasium-Robotics' mazes and Fetch tasks, which bundle no torch reward): minus the distance from
  the achieved_goal after the step to the desired_goal (`GoalDistance`). It is not the env's own
  reward (often sparse: 1 within a radius), but one a short horizon can climb; `auto` takes it
  where there is no builtin reward and no learned head.

See docs/model-based-rewards.md for which Gymnasium MuJoCo envs cannot be bundled and why.
"""

from __future__ import annotations

import importlib
import inspect
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

from motorlab.envs.catalog import Planning, facts, planned_ids, register_env
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.user_modules import import_modules

StateFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]
TorchReward = StateFn  # the name this module had before terminations

SOURCES = ("builtin", "learned", "goal")  # besides "auto", "none" (terminations) and MODULE:FUNCTION
PROBE_SHAPES = ((2, 3), (5,))  # leading shapes a user function is checked on


class _Builtin(NamedTuple):
    reward: StateFn
    termination: StateFn | None
    state_size: int | None  # the state size the functions index into (None: not checked)


def register(env_id: str, layout: str, reward: StateFn, termination: StateFn | None = None, *,
             state_size: int | None = None) -> None:
    """Make `reward` (and `termination`, a bool StateFn; None: the env never terminates) the bundled
    task of env_id under the named state layout, in the env catalogue. `state_size`: the state size
    they are written for (a model whose state differs, e.g. an env made with other observation
    options, is refused)."""
    kept = tuple(p for p in facts(env_id).planning if p.layout != layout)
    register_env(env_id, planning=(*kept, Planning(layout, reward, termination, state_size)))


def builtin_envs(layout: str | None = None) -> list[str]:
    """Env ids (and family patterns) with a bundled reward (under `layout`, or any), the bundled first."""
    return planned_ids(layout)


def _termination_envs() -> list[str]:
    return [e for e in planned_ids() if any(p.termination is not None for p in facts(e).planning)]


def _function(ref, what: str) -> StateFn | None:
    """A catalogue entry's reward or termination: a StateFn of this module named "module:function",
    a callable given to `register`, or a user's (obs, action, next_obs) function by name."""
    if ref is None or callable(ref):
        return ref
    module, _, name = ref.partition(":")
    if module == __name__:
        return globals()[name]
    return UserFunction(load_function(ref, what), ref, what)


def _entry(env_id: str, layout: str) -> _Builtin | None:
    """env_id's builtin task under the layout, from its catalogue entry (None where it has none)."""
    planning = next((p for p in facts(env_id).planning if p.layout == layout), None)
    if planning is None:
        return None
    return _Builtin(_function(planning.reward, "reward"), _function(planning.termination, "termination"),
                    planning.state_size)


# ---- the bundled rewards and terminations -----------------------------------------------

def _control_cost(action: torch.Tensor) -> torch.Tensor:
    return action.square().sum(-1)


def _norm(x: torch.Tensor) -> torch.Tensor:
    return torch.linalg.vector_norm(x, dim=-1)


# The "reacher" layout: the reference notebook's 8-number state (cos, sin, joint velocities,
# fingertip x-y) with the target x-y as the goal.
TIP = slice(6, 8)  # fingertip x-y in the reacher layout


def reacher_distance(state: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    return _norm(state[..., TIP] - goal)


def reacher_v5(state, action, next_state, goal):
    """Gymnasium Reacher-v5 (default weights 1, 1): distance after the step, control cost."""
    return -reacher_distance(next_state, goal) - _control_cost(action)


def reacher_v4(state, action, next_state, goal):
    """Gymnasium Reacher-v4 scores the distance before the step."""
    return -reacher_distance(state, goal) - _control_cost(action)


# The "observation" layout: the state is the env's observation.

def reacher_obs_v5(state, action, next_state, goal):
    """Reacher-v5 on observations: obs[8:10] is fingertip - target (x, y; the z's are equal), after the step."""
    return -_norm(next_state[..., 8:10]) - _control_cost(action)


def reacher_obs_v4(state, action, next_state, goal):
    """Reacher-v4 on observations: obs[8:11] is fingertip - target, scored before the step."""
    return -_norm(state[..., 8:11]) - _control_cost(action)


def _pusher(obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    # obs[14:17] the arm's tip, obs[17:20] the object, obs[20:23] the goal (centres of mass);
    # weights: near 0.5, distance 1, control 0.1 (v5's defaults, v4's constants)
    tip, obj, goal = obs[..., 14:17], obs[..., 17:20], obs[..., 20:23]
    return -0.5 * _norm(obj - tip) - _norm(obj - goal) - 0.1 * _control_cost(action)


def pusher_v5(state, action, next_state, goal):
    """Pusher-v5: after the step."""
    return _pusher(next_state, action)


def pusher_v4(state, action, next_state, goal):
    """Pusher-v4: before the step."""
    return _pusher(state, action)


def inverted_pendulum_termination(state, action, next_state, goal):
    """InvertedPendulum-v4/v5: the pole's angle obs[1] beyond 0.2 rad, or a non-finite observation."""
    return ~torch.isfinite(next_state).all(-1) | (next_state[..., 1].abs() > 0.2)


PENDULUM_RAIL_END = 0.5  # m: InvertedPendulum's cart runs on a rail of +-1 m (its slider's range)


def inverted_pendulum_rail_end(state, action, next_state, goal):
    """The planner's end for InvertedPendulum-v4/v5: the env's own (`inverted_pendulum_termination`)
    or the cart past 0.5 m of its +-1 m rail.

    Why: the env ends only on the pole's angle, but a cart that reaches the rail's end stops dead
    and the pole falls soon after. An alive reward gives the planner no reason to keep the cart
    centred, and a slow drift reaches the rail long after a 15-step horizon could see the fall,
    so plain planning (the oracle on the true simulator too) lets the cart drift into it.
    Why 0.5 m, half the rail: the planner must keep room to run under a pole leaning outward. With
    the end at 0.9 m the loop's carts (accurate models, seeds 1 and 2 at ~2,000 env steps) parked at
    ~0.87 m with the pole leaning out, where any catch crosses the end: 2 and 5 of 10 evaluation
    episodes fell there. On the same models, those 5 failed episodes of seed 2 all balanced for
    1,000 steps with the end at 0.7 m or 0.5 m (carts within 0.68 and 0.47 m)."""
    rail = next_state[..., 0].abs() > PENDULUM_RAIL_END
    return inverted_pendulum_termination(state, action, next_state, goal) | rail


def inverted_pendulum_v5(state, action, next_state, goal):
    """InvertedPendulum-v5: 1 per step the pole stays up, 0 on the terminating step."""
    return (~inverted_pendulum_termination(state, action, next_state, goal)).to(next_state.dtype)


def inverted_pendulum_v4(state, action, next_state, goal):
    """InvertedPendulum-v4: 1 per step, the terminating one included."""
    return next_state.new_ones(next_state.shape[:-1])


STANDUP_TIMESTEP = 0.003  # humanoidstandup.xml's timestep: the reward is the torso's height / timestep


def _standup(next_state: torch.Tensor, action: torch.Tensor, contact_forces: int) -> torch.Tensor:
    # obs[0] the torso's z after the step; the last `contact_forces` numbers are cfrc_ext
    # (v5 leaves out the world body's, which is zero); weights 0.1 and 0.5e-6, impact cost capped at 10
    impact = (0.5e-6 * next_state[..., -contact_forces:].square().sum(-1)).clamp(max=10.0)
    return next_state[..., 0] / STANDUP_TIMESTEP - 0.1 * _control_cost(action) - impact + 1


def humanoid_standup_v5(state, action, next_state, goal):
    """HumanoidStandup-v5: height gain, control and impact costs, all from the observation after the step."""
    return _standup(next_state, action, 13 * 6)


def humanoid_standup_v4(state, action, next_state, goal):
    """HumanoidStandup-v4: as v5; its observation holds all 14 bodies' contact forces."""
    return _standup(next_state, action, 14 * 6)


CARTPOLE_LENGTH = 0.6  # motorlab.envs.cartpole_swingup's pole, hinge to tip (m)


def cartpole_swingup(state, action, next_state, goal):
    """CartpoleSwingup-v0 (PETS' swing-up; motorlab.envs.cartpole_swingup.reward, the same arithmetic):
    exp(-|tip - (0, l)|^2 / l^2) - 0.01 |a|^2, the tip (x + l sin, l cos) from the observation after
    the step, obs = (x, sin theta, cos theta, x', theta'), theta 0 upright."""
    length = CARTPOLE_LENGTH
    dx = next_state[..., 0] + length * next_state[..., 1]
    dz = length * next_state[..., 2] - length
    return torch.exp(-(dx * dx + dz * dz) / (length * length)) - 0.01 * (action * action).sum(-1)


# Which env uses which of them (Reacher-v5: reacher_v5 and reacher_obs_v5, ...) is in the env
# catalogue (motorlab.envs.catalog), with why InvertedDoublePendulum has none.


class GoalDistance:
    """The goal reward: minus the distance from the achieved_goal entries of the state after the step
    to the goal (the desired_goal), for goal-conditioned envs with a Dict observation."""

    def __init__(self, achieved: slice):
        self.achieved = achieved

    def __call__(self, state, action, next_state, goal):
        return -_norm(next_state[..., self.achieved] - goal)

    def __repr__(self) -> str:
        return f"GoalDistance(achieved={self.achieved.start}:{self.achieved.stop})"


class NewestFrame:
    """A StateFn written for one observation, on a state of stacked ones (--history: gymnasium's
    FrameStackObservation, flattened, the newest last): it reads the newest, the last `size` entries."""

    def __init__(self, fn: StateFn, size: int):
        self.fn, self.size = fn, size

    def __call__(self, state, action, next_state, goal):
        return self.fn(state[..., -self.size:], action, next_state[..., -self.size:], goal)

    def __repr__(self) -> str:
        return f"NewestFrame({self.fn!r}, {self.size})"


# ---- one-line messages ------------------------------------------------------------------

def _one_line(text, limit: int | None = None) -> str:
    """`text` on one line (cut to `limit` characters: for what the user's code says)."""
    text = re.sub(r"\s+", " ", str(text)).strip()
    return text if limit is None or len(text) <= limit else text[:limit - 3] + "..."


def _ways(what: str, builtin: bool = True) -> str:
    """The ways to give the planner a reward (or a termination), for messages."""
    returns = "reward" if what == "reward" else "bool (episode over)"
    ways = [f"--{what} MODULE:FUNCTION (your torch function (obs, action, next_obs) -> {returns})",
            f"--{what} learned (fit the model with --learn-{what})"]
    if builtin:
        ways.insert(0, f"--{what} builtin (bundled for {', '.join(builtin_envs())})")
    if what == "termination":
        ways.append("--termination none")
    return ", ".join(ways[:-1]) + ", or " + ways[-1]


def _no_builtin_reason(env_id: str, layout: str, state_size: int | None) -> str:
    """Why env_id's bundled reward does not apply here ("" where it has none)."""
    planning = facts(env_id).planning
    entry = next((p for p in planning if p.layout == layout), None)
    if entry is not None and entry.state_size not in (None, state_size):
        return (f" (its bundled reward reads the {entry.state_size}-number {layout} state, this model's has "
                f"{state_size}: an env made with other observation options?)")
    others = [p.layout for p in planning if p.layout != layout]
    if not others:
        return ""
    return (f" with the {layout!r} state layout (its bundled reward is for the {' and '.join(others)} "
            f"layout{'s' if len(others) > 1 else ''})")


def _synergy_reward(env_id: str) -> str:
    """The one line for a bundled reward under synergy actions (--sar)."""
    return (f"--reward builtin: {env_id}'s bundled reward charges the env's own actions, and with --sar the planner "
            "acts in synergies; use --reward MODULE:FUNCTION (your torch function (obs, action, next_obs) -> reward) "
            "or --reward learned (fit the model with --learn-reward).")


def missing_reward_message(env_id: str, layout: str = "observation", state_size: int | None = None) -> str:
    """The one line for an env without a reward to plan with, listing the ways to give one."""
    reason = _no_builtin_reason(env_id, layout, state_size)
    return _one_line(f"no reward to plan with on {env_id}{reason}: use {_ways('reward', builtin=not reason)}.")


def reward_for(env_id: str, layout: str) -> StateFn:
    """The bundled reward of env_id under the layout (MotorlabError listing the three ways if none)."""
    entry = _entry(env_id, layout)
    if entry is None:
        raise MotorlabError(missing_reward_message(env_id, layout))
    return entry.reward


# ---- the user's functions ---------------------------------------------------------------

def load_function(spec: str, what: str = "reward") -> Callable:
    """The user's function named "module:function" (a dotted attribute path after the colon works too).

    The module is imported through `user_modules.import_modules`, so processes motorlab starts
    import it too. Raises MotorlabError (one line) for: no colon, a module that does not import,
    no such attribute (listing the module's functions), not callable, a signature that cannot take
    the 3 positional arguments (obs, action, next_obs).
    """
    flag = f"--{what} {spec}"
    module_name, sep, attr = spec.partition(":")
    module_name, attr = module_name.strip(), attr.strip()
    if not sep or not module_name or not attr:
        raise MotorlabError(f"{flag}: name a function as MODULE:FUNCTION (e.g. mypkg.tasks:{what}), a torch "
                            f"function (obs, action, next_obs) -> {_returns(what)} in an importable module.")
    try:
        import_modules([module_name], why=f"for {flag}")
    except MotorlabError as e:
        raise MotorlabError(_one_line(e)) from None
    module = importlib.import_module(module_name)
    fn = module
    for part in attr.split("."):
        if not hasattr(fn, part):
            raise MotorlabError(_one_line(f"{flag}: module {module_name!r} has no {attr!r}"
                                          f"{did_you_mean(attr, _public_callables(module, 100))}; "
                                          f"{_listing(module)}"))
        fn = getattr(fn, part)
    if not callable(fn):
        raise MotorlabError(_one_line(f"{flag}: {attr} is of type {type(fn).__name__}, not a function; give a "
                                      f"torch function (obs, action, next_obs) -> {_returns(what)}."))
    try:
        signature = inspect.signature(fn)
    except (TypeError, ValueError):  # some builtins and C callables have none: the probe call decides
        return fn
    try:
        signature.bind(None, None, None)
    except TypeError as e:
        raise MotorlabError(_one_line(f"{flag}: {attr}{signature} cannot be called with the 3 positional "
                                      f"arguments (obs, action, next_obs) ({e}); define it as "
                                      f"def {attr.rpartition('.')[2]}(obs, action, next_obs).")) from None
    return fn


def _returns(what: str) -> str:
    return "reward" if what == "reward" else "bool"


def _public_callables(module, n: int = 6) -> list[str]:
    own, other = [], []
    for name, value in vars(module).items():
        if name.startswith("_") or not callable(value):
            continue
        (own if getattr(value, "__module__", None) == module.__name__ else other).append(name)
    return (own or other)[:n]


def _listing(module) -> str:
    names = _public_callables(module)
    return f"its functions: {', '.join(names)}." if names else "it defines no functions."


class UserFunction:
    """A user's (obs, action, next_obs) function as a StateFn (the goal is not passed on).

    A reward comes back in the state's dtype, a termination as bool.
    """

    def __init__(self, fn: Callable, spec: str, what: str = "reward"):
        self.fn, self.spec, self.what = fn, spec, what

    def __call__(self, state, action, next_state, goal=None):
        out = self.fn(state, action, next_state)
        if self.what == "termination":
            return out if out.dtype == torch.bool else out != 0
        return out if out.dtype == state.dtype else out.to(state.dtype)

    def __repr__(self) -> str:
        return f"UserFunction({self.spec!r}, {self.what})"


def _describe(out) -> str:
    if isinstance(out, torch.Tensor):
        return f"a {str(out.dtype).removeprefix('torch.')} tensor of shape {tuple(out.shape)}"
    if hasattr(out, "shape") and hasattr(out, "dtype"):
        kind = f"{type(out).__module__.partition('.')[0]}.{type(out).__name__}"
        return f"a {kind} ({out.dtype}) of shape {tuple(out.shape)}, not a torch tensor"
    return f"a {type(out).__name__}"


def check_function(fn: Callable, spec: str, what: str, state_size: int, action_size: int) -> None:
    """Call `fn` on probe tensors with leading shapes (2, 3) and (5,); MotorlabError (one line)
    naming the function, what it returned and what is expected, if it raises or returns the wrong thing."""
    generator = torch.Generator().manual_seed(0)
    for lead in PROBE_SHAPES:
        obs, next_obs = (torch.rand(*lead, state_size, generator=generator) - 0.5 for _ in range(2))
        action = torch.rand(*lead, action_size, generator=generator) * 2 - 1
        shapes = f"obs {tuple(obs.shape)}, action {tuple(action.shape)}, next_obs {tuple(next_obs.shape)}"
        if what == "reward":
            expected = f"a float tensor of shape {lead} (one reward per row: reduce the last dim, e.g. .sum(-1))"
        else:
            expected = f"a bool (or 0/1) tensor of shape {lead} (one per row: reduce the last dim, e.g. .any(-1))"
        try:
            with torch.no_grad():
                out = fn(obs, action, next_obs)
        except Exception as e:  # the user's code may raise anything
            raise MotorlabError(_one_line(f"--{what} {spec} raised {type(e).__name__}: {_one_line(e, 160)} on "
                                          f"probe tensors {shapes}; it should take torch tensors (..., obs), "
                                          f"(..., action), (..., obs) and return {expected}.")) from None
        problem = None
        if not isinstance(out, torch.Tensor) or tuple(out.shape) != lead:
            problem = "wrong"
        elif what == "reward":
            if not out.dtype.is_floating_point:
                problem = "wrong"
            elif not torch.isfinite(out).all():
                problem = "non-finite values in"
        elif out.dtype != torch.bool and not ((out == 0) | (out == 1)).all():
            problem = "values other than 0/1 in"
        if problem:
            got = _describe(out) if problem == "wrong" else f"{problem} {_describe(out)}"
            raise MotorlabError(_one_line(f"--{what} {spec} returned {got} for {shapes}; expected {expected}."))


def _user_function(spec: str, what: str, state_size: int, action_size: int) -> UserFunction:
    fn = load_function(spec, what)
    check_function(fn, spec, what, state_size, action_size)
    return UserFunction(fn, spec, what)


# ---- picking the task -------------------------------------------------------------------

@dataclass(frozen=True)
class Task:
    """What the planner maximizes, and when a predicted episode ends."""

    reward: StateFn | None  # None means: use the model's learned reward head
    termination: StateFn | None  # None: no termination, or the learned head when termination_source == "learned"
    reward_source: str  # "builtin", "learned", or the "module:function" text
    termination_source: str  # "builtin", "learned", "none", or "module:function"


def _builtin(env_id: str, layout: str, state_size: int, action_size: int) -> _Builtin | None:
    """env_id's builtin task for a model of this state size; a user's functions declared in the
    catalogue are checked on probe tensors as --reward MODULE:FUNCTION is."""
    entry = _entry(env_id, layout)
    if entry is None or entry.state_size not in (None, state_size):
        return None
    for fn in entry[:2]:
        if isinstance(fn, UserFunction):
            check_function(fn.fn, fn.spec, fn.what, state_size, action_size)
    return entry


def _unknown(what: str, value: str, choices: tuple[str, ...]) -> MotorlabError:
    known, goal = choices, ""
    if what == "reward":  # named apart: it applies to goal-conditioned envs only
        known, goal = (*choices, "goal"), ", or goal on a goal-conditioned env (achieved_goal and desired_goal in " \
            "its Dict observation)"
    return MotorlabError(f"--{what} {value!r}{did_you_mean(value, known)}: choose {', '.join(choices)} or "
                         f"MODULE:FUNCTION (your torch function (obs, action, next_obs) -> {_returns(what)}){goal}.")


def _no_goal(env_id: str) -> MotorlabError:
    return MotorlabError(f"--reward goal: minus the distance from achieved_goal to desired_goal needs an env whose "
                         f"Dict observation holds both keys, of one size; {env_id}'s does not. Use --reward "
                         "MODULE:FUNCTION (your torch function (obs, action, next_obs) -> reward) or --reward learned "
                         "(fit the model with --learn-reward).")


def resolve_task(env_id: str, layout: str, state_size: int, action_size: int, goal_size: int = 0,
                 reward: str = "auto", termination: str = "auto",
                 learned: frozenset[str] = frozenset(), achieved: slice | None = None, frames: int = 1,
                 synergies: bool = False) -> Task:
    """The reward and termination to plan with on env_id.

    Args:
        layout: the model's state layout ("observation", "reacher").
        state_size, action_size, goal_size: the model's; a user function is checked on tensors of these sizes.
        reward: "auto" (builtin if bundled for env_id and layout, else learned if the model has a reward
            head, else goal where the env is goal-conditioned), "builtin", "learned", "goal" or
            "module:function".
        termination: "auto" (the bundled one with a bundled reward, else learned if the model has a
            termination head, else none), "builtin", "learned", "none" or "module:function".
        learned: the heads the model has ({"reward"}, {"reward", "termination"} or none).
        achieved: the state's achieved_goal entries, for a goal-conditioned env whose goal is the
            desired_goal (StateLayout.achieved): what makes the goal reward available.
        frames: observations stacked in the state (--history; StateLayout.frames): the bundled
            reward and termination, written for one observation, read the newest.
        synergies: the planner's actions are synergies (--sar), not the env's own: the bundled
            rewards, which charge the env's own actions, do not apply.

    Raises:
        MotorlabError: one line naming what is missing and the ways to give it.
    """
    learned = frozenset(learned)
    frame = state_size // frames if frames > 1 and state_size % frames == 0 else state_size  # one observation
    builtin = _builtin(env_id, layout, frame, action_size)
    if builtin is not None and frame != state_size:
        builtin = _Builtin(NewestFrame(builtin.reward, frame),
                           builtin.termination and NewestFrame(builtin.termination, frame), builtin.state_size)
    reward = reward.strip()
    if reward == "auto":
        if builtin is not None and not synergies:
            reward = "builtin"
        elif "reward" in learned:
            reward = "learned"
        elif achieved is not None:
            reward = "goal"
        elif builtin is not None:
            raise MotorlabError(_synergy_reward(env_id))
        else:
            raise MotorlabError(missing_reward_message(env_id, layout, frame))
    if reward == "builtin":
        if builtin is None:
            raise MotorlabError(_one_line(f"--reward builtin: no bundled reward for {env_id}"
                                          f"{_no_builtin_reason(env_id, layout, frame)}; bundled for "
                                          f"{', '.join(builtin_envs())}. Use --reward MODULE:FUNCTION (your torch "
                                          "function (obs, action, next_obs) -> reward) or --reward learned (fit "
                                          "the model with --learn-reward)."))
        if synergies:
            raise MotorlabError(_synergy_reward(env_id))
        reward_fn = builtin.reward
    elif reward == "learned":
        if "reward" not in learned:
            raise MotorlabError(f"--reward learned: this model of {env_id} has no reward head; refit it with "
                                "--learn-reward, or use --reward builtin or --reward MODULE:FUNCTION.")
        reward_fn = None
    elif reward == "goal":
        if achieved is None:
            raise _no_goal(env_id)
        reward_fn = GoalDistance(achieved)
    elif ":" in reward:
        reward_fn = _user_function(reward, "reward", state_size, action_size)
    else:
        raise _unknown("reward", reward, ("auto", "builtin", "learned"))

    termination = termination.strip()
    if termination == "auto":
        if reward == "builtin" and builtin.termination is not None:
            termination = "builtin"
        elif "termination" in learned:
            termination = "learned"
        else:
            termination = "none"
    if termination == "builtin":
        if builtin is None:
            raise MotorlabError(_one_line(f"--termination builtin: no bundled termination for {env_id}"
                                          f"{_no_builtin_reason(env_id, layout, frame)} (bundled for "
                                          f"{', '.join(_termination_envs())}); use "
                                          f"{_ways('termination', builtin=False)}."))
        termination_fn = builtin.termination
        if termination_fn is None:  # a bundled env whose episodes end only by the time limit
            termination = "none"
    elif termination == "learned":
        if "termination" not in learned:
            raise MotorlabError(f"--termination learned: this model of {env_id} has no termination head; refit "
                                "it with --learn-termination, or use --termination builtin, MODULE:FUNCTION or "
                                "none.")
        termination_fn = None
    elif termination == "none":
        termination_fn = None
    elif ":" in termination:
        termination_fn = _user_function(termination, "termination", state_size, action_size)
    else:
        raise _unknown("termination", termination, ("auto", "builtin", "learned", "none"))
    return Task(reward_fn, termination_fn, reward, termination)
