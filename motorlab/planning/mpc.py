"""Model-predictive control with the cross-entropy method (CEM) or MPPI, batched in torch.

Every control step, for every env at once: sample `population` action sequences of
`horizon` steps from a Gaussian per env, roll them through the model (one batched call
per step ahead, all envs and candidates together), score them with the task's reward in
torch, refit the Gaussian to the best `elites` (CEM, with iCEM's kept elites) or move it
to the return-weighted mean of all samples (MPPI), repeat `iterations` times, and apply
the first action of the final mean. The mean is shifted one step and kept for the next
control step (warm start). `EvoTorchCEM` plans the same problem with EvoTorch's CEM,
one env at a time, for users of the reference notebook.

A sequence's score is its return under the model: each of `particles` copies rolls out
(TS-inf: a copy keeps its ensemble member; a probabilistic member samples its next state),
rewards after a predicted termination count nothing, and the copies' returns are averaged.

Non-finite numbers: a candidate whose predicted states or rewards went NaN or Inf (a model off its
data, a reward that is NaN outside some range) is rejected: its score is -inf, so it is never an
elite nor weighted. An env whose every candidate was rejected keeps its previous plan (the warm
start's first action). `PlannerFaults` counts both, on the planner's device (counting never waits
for it; on the CPU the usual all-finite case is one check per scoring), for the run's summary.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
import torch

from motorlab.dynamics.model import stepwise_rollout
from motorlab.errors import MotorlabError

# (states (N, S), actions (N, H, A), goals (N, G)) -> returns (N,), -inf for a rejected candidate
Scorer = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class FaultCounts:
    """What a planner met of non-finite numbers over a run (see `PlannerFaults`)."""

    plans: int = 0  # plans made: one env at one control step
    faulty_plans: int = 0  # plans that met a non-finite prediction or reward among their candidates
    states: int = 0  # candidates rejected because a predicted state went NaN or Inf
    rewards: int = 0  # candidates rejected because their reward went NaN or Inf on finite states
    fallbacks: int = 0  # plans whose every candidate was rejected: the previous plan's action was taken

    def __add__(self, other: FaultCounts) -> FaultCounts:
        return FaultCounts(*(getattr(self, f.name) + getattr(other, f.name) for f in fields(self)))


class PlannerFaults:
    """The non-finite numbers a planner meets, counted in a tensor on its device: adding to it never
    waits for the device, `counts()` reads it once. The scorer counts rejected candidates, the
    planner the plans that met one and those that had to fall back."""

    _FAULTY, _STATES, _REWARDS, _FALLBACKS = range(4)

    def __init__(self):
        self.plans = 0
        self._tally: torch.Tensor | None = None

    def _add(self, index: int | slice, amount: torch.Tensor) -> None:
        if self._tally is None:
            self._tally = torch.zeros(4, dtype=torch.int64, device=amount.device)
        self._tally[index] += amount.to(self._tally.device)

    def candidates(self, finite: torch.Tensor, states_finite: torch.Tensor) -> None:
        """Count the rejected candidates of one scoring: `finite` (N,) whether a candidate's return is
        finite, `states_finite` (N,) whether its predicted states all are."""
        rejected = ~finite
        self._add(slice(self._STATES, self._REWARDS + 1),
                  torch.stack([(rejected & ~states_finite).sum(), (rejected & states_finite).sum()]))

    def plan(self, n: int, met: torch.Tensor | None = None, found: torch.Tensor | None = None) -> None:
        """Count a plan for n envs: `met` (n,) which met a rejected candidate, `found` (n,) which had a
        usable one in some iteration (None: all of them)."""
        self.plans += n
        if met is not None:
            self._add(self._FAULTY, met.sum())
        if found is not None:
            self._add(self._FALLBACKS, (~found).sum())

    def counts(self) -> FaultCounts:
        tally = [0] * 4 if self._tally is None else self._tally.tolist()
        return FaultCounts(self.plans, *tally)


def all_finite(values: torch.Tensor) -> bool:
    """Whether every value is finite, known for sure on the CPU (False on a GPU: knowing would wait for it).

    Their sum is finite only if every value is (or, in float overflow, says "not known": the careful
    path then runs): one reduction and one read, ~4x cheaper than isfinite().all() on a
    planner's few hundred returns, which matters on a path run every iteration of every plan.
    """
    return values.device.type == "cpu" and math.isfinite(float(values.sum()))


def _reject_non_finite(returns: torch.Tensor, path: torch.Tensor, particles: int,
                       faults: PlannerFaults | None) -> torch.Tensor:
    """`returns` with every non-finite one set to -inf (rejected), counted in `faults` as a fault of
    the model (a non-finite predicted state) or of the reward."""
    if all_finite(returns):  # the usual case
        return returns
    finite = torch.isfinite(returns)
    if faults is not None:
        states_finite = torch.isfinite(path).flatten(1).all(1)
        if particles > 1:
            states_finite = states_finite.reshape(-1, particles).all(1)
        faults.candidates(finite, states_finite)
    return returns.masked_fill(~finite, float("-inf"))


class EndProbability:
    """The probability that a predicted step ends the episode, for a termination written as a yes/no
    function of the state: the share of `draws` states around each predicted one, spread by the
    model's own measured open-loop error t steps ahead (model.json's "rollout_error", fit time), that
    the termination calls ended.

    Why: with a +1-per-step alive reward every candidate that survives the horizon on the predicted
    path scores the same, so CEM cannot tell a pole near its limit from one upright and picks among
    them at random. The probability grows as the predicted state nears the boundary, by as much as
    the model's predictions can be off there, so the planner keeps away from it. The draws are fixed
    (common random numbers): candidates are compared on the same noise, and a plan is repeatable.
    """

    def __init__(self, end_fn, drift, draws: int, seed: int = 0):
        self.end_fn = end_fn
        self.drift = torch.as_tensor(np.asarray(drift, dtype=np.float32))  # (T, S)
        self.noise = torch.randn((draws, *self.drift.shape), generator=torch.Generator().manual_seed(seed))

    def __call__(self, state, action, next_state, goal) -> torch.Tensor:
        """(N, H, ...) tensors -> (N, H) probabilities."""
        h = next_state.shape[1]
        steps = torch.arange(h).clamp(max=len(self.drift) - 1)
        spread = (self.drift[steps] * self.noise[:, steps]).to(next_state)  # (M, H, S)
        drawn = next_state[None] + spread[:, None]  # (M, N, H, S)
        ends = self.end_fn(state[None].expand_as(drawn), action[None].expand(len(drawn), *action.shape),
                           drawn, goal[None].expand(len(drawn), *goal.shape))
        return ends.to(next_state.dtype).mean(0)


def end_spread(model, drift, margin: float) -> np.ndarray:
    """The spread (T, S) of EndProbability's draws t steps ahead: the model's measured open-loop error
    `drift`, at least `margin` x its typical one-step change of each entry x sqrt(t + 1).

    Why a floor: an accurate model's error is tiny (InvertedPendulum's loop models: ~0.003 rad 15
    steps ahead), so the draws only penalize a plan that all but crosses the end, and the planner
    lets the pole lean to the edge of its 0.2 rad and parks the cart at the end of its range, where
    what lies beyond the horizon is already a fall. A spread like a random walk of half a typical
    step's change keeps plans in the middle of what the termination allows."""
    drift = np.asarray(drift, dtype=np.float64)
    if margin <= 0:
        return drift
    typical = getattr(getattr(model, "delta_norm", None), "std", None)
    if typical is None:  # not a ForwardModel (e.g. a bare predict function): no scale to take
        return drift
    typical = np.asarray(typical.detach().cpu(), dtype=np.float64)[:drift.shape[1]]
    floor = margin * typical[None] * np.sqrt(np.arange(1, len(drift) + 1))[:, None]
    return np.maximum(drift, floor)


def model_scorer(model, task, discount: float = 1.0, propagation: str = "mean", particles: int | None = None,
                 generator: torch.Generator | None = None, faults: PlannerFaults | None = None,
                 termination_draws: int = 0, termination_margin: float = 0.0) -> Scorer:
    """Return of each action sequence under the forward model and a task (reward, termination;
    see motorlab.dynamics.planner_rewards.Task; a None reward or a "learned" termination use the model's heads)
    or a bare torch reward (state, action, next_state, goal) -> (...,).

    Mean propagation predicts the whole path first (`fast_rollout`, a probabilistic member's Gaussian
    mean; with a learned reward, the reward head's predictions come with it from the same passes);
    then the reward scores all H steps in one call on (N, H, ...) tensors: a reward is elementwise
    over its leading dimensions, and one call instead of H saves ~10 torch calls per step ahead.
    TS propagation has its own whole path (`ts_rollout`); a learned termination (or a learned reward
    without a reward head) steps with `step_fn`, collecting the heads' outputs on the way.

    A candidate whose return is NaN or Inf scores -inf (rejected), and is counted in `faults`.

    `termination_draws` > 0 scores a yes/no termination as a probability of ending (`EndProbability`,
    where the model measured its open-loop error): each step's reward counts with the chance that
    the episode is still running. `termination_margin` > 0 widens the draws' spread t steps ahead to
    at least margin x the typical one-step change of each entry (the model's delta normalizer's std)
    x sqrt(t + 1) (`end_spread`).
    """
    if particles is None:  # one rollout per candidate, or under TS one particle per member
        particles = model.members if propagation == "ts" else 1
    if particles < 1:
        raise MotorlabError(f"--particles must be positive, got {particles}.")
    if propagation == "ts" and particles % model.members:
        raise MotorlabError(f"--particles {particles}: trajectory sampling gives each particle one of the "
                            f"{model.members} members, so use a multiple of {model.members}.")
    reward_fn = getattr(task, "reward", task)
    end_fn, end_source = getattr(task, "termination", None), getattr(task, "termination_source", "none")
    drift = getattr(model, "meta", {}).get("rollout_error")
    if end_fn is not None and termination_draws and drift is not None:
        end_fn = EndProbability(end_fn, end_spread(model, drift, termination_margin), termination_draws)
    learned_reward = reward_fn is None
    learned_end = end_fn is None and end_source == "learned"
    whole_path = not learned_end and (not learned_reward or "reward" in getattr(model, "heads", ()))
    fast_mean = whole_path and propagation == "mean"
    fast_ts = whole_path and propagation == "ts" and hasattr(model, "ts_rollout")  # step_fn's TS, ~20% faster
    fast = fast_mean or fast_ts
    if fast_ts:  # with a learned reward: (path, the reward head's predictions (N, H))
        rollout = model.ts_rollout(generator, reward=learned_reward)
    elif fast_mean and learned_reward:
        rollout = model.fast_rollout(reward=True)
    elif fast_mean:
        rollout = model.fast_rollout() if hasattr(model, "fast_rollout") else stepwise_rollout(model.predict)
    else:
        step = model.step_fn(propagation, generator)

    def score(states: torch.Tensor, actions: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        if particles > 1:
            states, actions, goals = (v.repeat_interleave(particles, 0) for v in (states, actions, goals))
        h = actions.shape[1]
        head_rewards, head_ends = [], []
        if fast:
            path = rollout(states, actions)
            if learned_reward:
                path, head_rewards = path
        else:
            path = [states]
            for t in range(h):
                next_states, r, end = step(path[-1], actions[:, t])
                path.append(next_states)
                head_rewards.append(r)
                head_ends.append(end)
            path = torch.stack(path, 1)
            if learned_reward:
                head_rewards = torch.stack(head_rewards, 1)
        goals_h = goals[:, None].expand(-1, h, -1)
        rewards = head_rewards if learned_reward else reward_fn(path[:, :-1], actions, path[:, 1:], goals_h)
        ends = (torch.stack(head_ends, 1) if learned_end
                else end_fn(path[:, :-1], actions, path[:, 1:], goals_h) if end_fn else None)
        if ends is not None and ends.dtype != torch.bool:  # a probability of ending at each step: a step's
            alive = torch.cumprod(1 - ends.clamp(0, 1), 1)  # reward counts as much as the chance it is reached
            rewards = rewards * torch.cat([alive.new_ones(alive.shape[:1] + (1,)), alive[:, :-1]], 1)
        elif ends is not None:  # the ending step is paid, the steps after it are not (the episode is over):
            ends = ends.bool()  # left out, not multiplied by 0, so that what a model predicts past it cannot be NaN
            rewards = rewards.masked_fill(ends.cumsum(1) > ends.to(torch.int64), 0.0)
        if discount != 1.0:
            rewards = rewards * discount ** torch.arange(h, dtype=rewards.dtype, device=rewards.device)
        returns = rewards.sum(1)
        if particles > 1:  # a particle's NaN makes its candidate's mean NaN: rejected whole
            returns = returns.reshape(-1, particles).mean(1)
        return _reject_non_finite(returns, path, particles, faults)

    return score


class MPCPolicy:
    """A planner as a motorlab Policy: act(observations) -> actions, through a state layout.

    With an ensemble `model`, it records the members' disagreement on the next state under each
    action it takes (`disagreements`, one array per control step: how far the planner trusted a
    model whose members disagree).

    `explore` > 0 adds Gaussian noise to each action it takes, its std that share of each action's
    half-range, clipped to the bounds (drawn from its own generator, seeded by `seed`): exploration
    while the model-based loop collects. The planner's warm start keeps its own plan."""

    def __init__(self, planner, layout, model=None, device: torch.device | str = "cpu", explore: float = 0.0,
                 seed: int = 0):
        self.planner, self.layout, self.model = planner, layout, model
        self.device = torch.device(device)
        self.disagreements: list[np.ndarray] = []
        self.task = None  # the reward and termination it plans with (build_policy sets it)
        if explore < 0:
            raise MotorlabError(f"exploration noise must be 0 or more, got {explore}.")
        self.explore = explore
        self._noise = np.random.default_rng(seed)
        # the planner's action bounds, as arrays once (the noise is drawn at every control step)
        self._low, self._high = (torch.as_tensor(b).cpu().numpy() for b in (planner.low, planner.high))

    @property
    def faults(self) -> PlannerFaults:
        """The non-finite predictions and rewards its planner met (rejected candidates, fallbacks)."""
        return self.planner.faults

    def disagreement_mean(self) -> float | None:
        """The ensemble's mean disagreement over the steps taken so far (None for one member)."""
        return float(np.concatenate(self.disagreements).mean()) if self.disagreements else None

    def reset(self, n: int) -> None:
        self.planner.reset(n)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        states = torch.as_tensor(self.layout.state(obs), dtype=torch.float32, device=self.device)
        goals = torch.as_tensor(self.layout.goal(obs), dtype=torch.float32, device=self.device)
        actions = self.planner.plan(states, goals)
        if self.model is not None and self.model.members > 1:
            self.disagreements.append(self.model.disagreement(states, actions).cpu().numpy())
        actions = actions.cpu().numpy()
        if not self.explore:
            return actions
        noise = self._noise.standard_normal(actions.shape) * self.explore * (self._high - self._low) / 2
        return np.clip(actions + noise, self._low, self._high).astype(actions.dtype)
