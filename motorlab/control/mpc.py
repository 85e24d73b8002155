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
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch

from motorlab.dynamics.model import stepwise_rollout
from motorlab.errors import MotorlabError
from motorlab.extras import require

# (states (N, S), actions (N, H, A), goals (N, G)) -> returns (N,)
Scorer = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def model_scorer(model, task, discount: float = 1.0, propagation: str = "mean", particles: int | None = None,
                 generator: torch.Generator | None = None) -> Scorer:
    """Return of each action sequence under the forward model and a task (reward, termination;
    see motorlab.dynamics.rewards.Task; a None reward or a "learned" termination use the model's heads)
    or a bare torch reward (state, action, next_state, goal) -> (...,).

    A deterministic state-only model with mean propagation predicts the whole path first
    (`fast_rollout`); then the reward scores all H steps in one call on (N, H, ...) tensors: a reward
    is elementwise over its leading dimensions, and one call instead of H saves ~10 torch calls per
    step ahead. Other models step with `step_fn`, collecting their heads' outputs on the way.
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
    learned_reward = reward_fn is None
    learned_end = end_fn is None and end_source == "learned"
    fast = (getattr(model, "plain", True) and propagation == "mean" and not learned_reward and not learned_end)
    if fast:
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
        else:
            path = [states]
            for t in range(h):
                next_states, r, end = step(path[-1], actions[:, t])
                path.append(next_states)
                head_rewards.append(r)
                head_ends.append(end)
            path = torch.stack(path, 1)
        goals_h = goals[:, None].expand(-1, h, -1)
        rewards = (torch.stack(head_rewards, 1) if learned_reward
                   else reward_fn(path[:, :-1], actions, path[:, 1:], goals_h))
        ends = (torch.stack(head_ends, 1) if learned_end
                else end_fn(path[:, :-1], actions, path[:, 1:], goals_h) if end_fn else None)
        if ends is not None:  # the ending step is paid, the steps after it are not (the episode is over)
            alive = torch.cumprod((~ends.bool()).to(rewards.dtype), 1)
            rewards = rewards * torch.cat([torch.ones_like(alive[:, :1]), alive[:, :-1]], 1)
        if discount != 1.0:
            rewards = rewards * discount ** torch.arange(h, dtype=rewards.dtype, device=rewards.device)
        returns = rewards.sum(1).nan_to_num(nan=-1e30, posinf=1e30, neginf=-1e30)  # a diverged rollout loses
        return returns.reshape(-1, particles).mean(1) if particles > 1 else returns

    return score


def check_plan_settings(horizon: int, population: int, iterations: int, elites: int) -> None:
    for name, v in (("horizon", horizon), ("population", population), ("iterations", iterations),
                    ("elites", elites)):
        if v <= 0:
            raise MotorlabError(f"--{name} must be positive, got {v}.")
    if elites > population:
        raise MotorlabError(f"--elites ({elites}) cannot exceed --population ({population}).")


class GaussianPlanner:
    """What CEM and MPPI share: a Gaussian over action sequences per env, in the action bounds,
    sampled with a seeded generator on the planner's device, its mean warm-started from the last plan."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int, population: int,
                 iterations: int, init_std: float, seed: int, device: torch.device | str):
        self.score = score
        self.device = torch.device(device)
        self.low = torch.as_tensor(low, dtype=torch.float32, device=self.device)
        self.high = torch.as_tensor(high, dtype=torch.float32, device=self.device)
        self.horizon, self.population, self.iterations = horizon, population, iterations
        self.init_std = init_std * (self.high - self.low) / 2
        self.generator = torch.Generator(self.device).manual_seed(seed)
        self.mean: torch.Tensor | None = None

    def reset(self, n: int) -> None:
        """Forget the warm start; the next plan starts from the middle of the action range."""
        self.mean = ((self.low + self.high) / 2).expand(n, self.horizon, -1).clone()

    def start(self, states: torch.Tensor, goals: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The warm-started mean (n, H, A) for n envs (a fresh one when n changed), and the states and
        goals repeated for each of the population's candidates."""
        n, p = states.shape[0], self.population
        if self.mean is None or self.mean.shape[0] != n:
            self.reset(n)
        return self.mean, states.repeat_interleave(p, 0), goals.repeat_interleave(p, 0)

    def sample(self, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
        """`population` sequences (n, p, H, A) around each env's mean, clipped to the bounds; the first is the mean."""
        n, p, h = mean.shape[0], self.population, self.horizon
        noise = torch.randn((n, p, h, mean.shape[-1]), generator=self.generator, device=self.device)
        samples = torch.maximum(torch.minimum(mean[:, None] + std[:, None] * noise, self.high), self.low)
        samples[:, 0] = mean  # the current mean always competes
        return samples


class CEMPlanner(GaussianPlanner):
    """Batched CEM over action sequences; `plan(states, goals)` gives one action per env."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 15,
                 population: int = 100, iterations: int = 5, elites: int = 10, init_std: float = 0.5,
                 min_std: float = 0.05, momentum: float = 0.1, keep: float = 0.3, execute: str = "mean",
                 seed: int = 0, device: torch.device | str = "cpu"):
        check_plan_settings(horizon, population, iterations, elites)
        super().__init__(score, low, high, horizon, population, iterations, init_std, seed, device)
        self.elites = elites
        self.min_std = min_std * (self.high - self.low) / 2
        self.momentum = momentum
        self.keep = min(int(keep * elites), population - 1)  # elites carried into the next round
        self.execute = execute
        self.kept: torch.Tensor | None = None

    def reset(self, n: int) -> None:
        super().reset(n)
        self.kept = None

    @torch.no_grad()
    def plan(self, states: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        n, p, h = states.shape[0], self.population, self.horizon
        mean, flat_states, flat_goals = self.start(states, goals)
        std = self.init_std.expand_as(mean).clone()
        rows = torch.arange(n, device=self.device)[:, None]
        kept = self.kept
        for _ in range(self.iterations):
            samples = self.sample(mean, std)
            if kept is not None:  # iCEM (Pinneri et al. 2020): the best few of the last round compete again
                samples[:, 1:1 + kept.shape[1]] = kept
            returns = self.score(flat_states, samples.reshape(n * p, h, -1), flat_goals).reshape(n, p)
            elite = samples[rows, returns.topk(self.elites, dim=1).indices]  # (n, elites, h, A), best first
            kept = elite[:, :self.keep]
            mean = self.momentum * mean + (1 - self.momentum) * elite.mean(1)
            std = torch.maximum(self.momentum * std + (1 - self.momentum) * elite.std(1), self.min_std)
        # warm start: shift the mean and the kept elites by one step for the next control step
        self.mean = torch.cat([mean[:, 1:], mean[:, -1:]], dim=1)
        self.kept = torch.cat([kept[:, :, 1:], kept[:, :, -1:]], dim=2) if self.keep else None
        return elite[:, 0, 0] if self.execute == "best" else mean[:, 0]


class MPPIPlanner(GaussianPlanner):
    """Batched MPPI (Williams et al. 2017) over action sequences: each iteration moves the mean to the
    average of all samples weighted by exp(standardized return / temperature).

    The returns are standardized per env before weighting, so one `temperature` works across envs
    whose rewards differ in scale (the raw-return form needs a temperature per env and reward).
    """

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 15,
                 population: int = 100, iterations: int = 1, init_std: float = 0.5, temperature: float = 0.5,
                 seed: int = 0, device: torch.device | str = "cpu", **_):
        check_plan_settings(horizon, population, iterations, 1)
        if temperature <= 0:
            raise MotorlabError(f"--temperature must be positive, got {temperature}.")
        super().__init__(score, low, high, horizon, population, iterations, init_std, seed, device)
        self.temperature = temperature

    @torch.no_grad()
    def plan(self, states: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        n, p, h = states.shape[0], self.population, self.horizon
        mean, flat_states, flat_goals = self.start(states, goals)
        std = self.init_std.expand_as(mean)
        for _ in range(self.iterations):
            samples = self.sample(mean, std)
            returns = self.score(flat_states, samples.reshape(n * p, h, -1), flat_goals).reshape(n, p)
            z = (returns - returns.mean(1, keepdim=True)) / (returns.std(1, keepdim=True) + 1e-8)
            weights = torch.softmax(z / self.temperature, dim=1)
            mean = (weights[:, :, None, None] * samples).sum(1)
        self.mean = torch.cat([mean[:, 1:], mean[:, -1:]], dim=1)
        return mean[:, 0]


class EvoTorchCEM:
    """The same problem planned with EvoTorch's CEM (one env at a time, as the reference notebook does)."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 10,
                 population: int = 200, iterations: int = 5, elites: int = 20, init_std: float = 0.5,
                 seed: int = 0, device: torch.device | str = "cpu", **_):
        check_plan_settings(horizon, population, iterations, elites)
        require("evotorch", "evotorch", "--optimizer evotorch needs EvoTorch")  # fail here, not at the first plan
        self.score = score
        self.low, self.high = np.asarray(low, dtype=np.float32), np.asarray(high, dtype=np.float32)
        self.horizon, self.population, self.iterations, self.elites = horizon, population, iterations, elites
        self.init_std = float(init_std * np.max((self.high - self.low) / 2))
        self.seed = seed
        self.device = torch.device(device)
        self.centers: list[np.ndarray] = []

    def reset(self, n: int) -> None:
        self.centers = [np.tile((self.low + self.high) / 2, self.horizon) for _ in range(n)]

    @torch.no_grad()
    def plan(self, states: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        from evotorch import Problem
        from evotorch.algorithms import CEM

        logging.getLogger("evotorch").setLevel(logging.WARNING)  # one INFO line per Problem otherwise

        if len(self.centers) != states.shape[0]:
            self.reset(states.shape[0])
        a_dim = len(self.low)
        low, high = torch.as_tensor(self.low, device=self.device), torch.as_tensor(self.high, device=self.device)
        actions = []
        for i in range(states.shape[0]):
            s, g = states[i:i + 1], goals[i:i + 1]

            def objective(x: torch.Tensor, s=s, g=g) -> torch.Tensor:
                # EvoTorch's CEM searches an unbounded space: the env would clip, so the model sees clipped actions
                seqs = torch.maximum(torch.minimum(x.reshape(len(x), self.horizon, a_dim), high), low)
                return self.score(s.expand(len(x), -1), seqs, g.expand(len(x), -1))

            problem = Problem("max", objective, solution_length=self.horizon * a_dim, vectorized=True,
                              dtype=torch.float32, seed=self.seed, device=self.device)
            searcher = CEM(problem, popsize=self.population, parenthood_ratio=self.elites / self.population,
                           stdev_init=self.init_std, center_init=self.centers[i])
            for _ in range(self.iterations):
                searcher.step()
            center = np.clip(searcher.status["center"].cpu().numpy(), np.tile(self.low, self.horizon),
                             np.tile(self.high, self.horizon))
            plan = center.reshape(self.horizon, a_dim)
            self.centers[i] = np.concatenate([plan[1:], plan[-1:]]).ravel()
            actions.append(plan[0])
        return torch.as_tensor(np.array(actions))


OPTIMIZERS = {"cem": CEMPlanner, "mppi": MPPIPlanner, "evotorch": EvoTorchCEM}


def make_planner(optimizer: str, score: Scorer, low, high, **settings):
    if optimizer not in OPTIMIZERS:
        raise MotorlabError(f"--optimizer {optimizer!r}: choose {', '.join(OPTIMIZERS)}.")
    return OPTIMIZERS[optimizer](score, low, high, **settings)


class MPCPolicy:
    """A planner as a motorlab Policy: act(observations) -> actions, through a state layout.

    With an ensemble `model`, it records the members' disagreement on the next state under each
    action it takes (`disagreements`, one array per control step: how far the planner trusted a
    model whose members disagree)."""

    def __init__(self, planner, layout, model=None, device: torch.device | str = "cpu"):
        self.planner, self.layout, self.model = planner, layout, model
        self.device = torch.device(device)
        self.disagreements: list[np.ndarray] = []
        self.task = None  # the reward and termination it plans with (build_policy sets it)

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
        return actions.cpu().numpy()
