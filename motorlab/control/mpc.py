"""Model-predictive control with the cross-entropy method (CEM), batched in torch.

Every control step, for every env at once: sample `population` action sequences of
`horizon` steps from a Gaussian per env, roll them through the model (one batched call
per step ahead, all envs and candidates together), score them with the env's reward in
torch, refit the Gaussian to the best `elites`, repeat `iterations` times, and apply the
first action of the final mean. The mean is shifted one step and kept for the next
control step (warm start). `EvoTorchCEM` plans the same problem with EvoTorch's CEM,
one env at a time, for users of the reference notebook.
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


def model_scorer(model, reward_fn, discount: float = 1.0) -> Scorer:
    """Return of each action sequence under the forward model and a torch reward.

    The model predicts the whole path first (`fast_rollout` where the model has one), then the
    reward scores all H steps in one call on (N, H, ...) tensors: a reward is elementwise over
    its leading dimensions, and one call instead of H saves ~10 torch calls per step ahead.
    """
    rollout = model.fast_rollout() if hasattr(model, "fast_rollout") else stepwise_rollout(model.predict)

    def score(states: torch.Tensor, actions: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        h = actions.shape[1]
        path = rollout(states, actions)
        rewards = reward_fn(path[:, :-1], actions, path[:, 1:], goals[:, None].expand(-1, h, -1))
        if discount != 1.0:
            rewards = rewards * discount ** torch.arange(h, dtype=rewards.dtype)
        return rewards.sum(1)

    return score


def check_plan_settings(horizon: int, population: int, iterations: int, elites: int) -> None:
    for name, v in (("horizon", horizon), ("population", population), ("iterations", iterations),
                    ("elites", elites)):
        if v <= 0:
            raise MotorlabError(f"--{name} must be positive, got {v}.")
    if elites > population:
        raise MotorlabError(f"--elites ({elites}) cannot exceed --population ({population}).")


class CEMPlanner:
    """Batched CEM over action sequences; `plan(states, goals)` gives one action per env."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 15,
                 population: int = 100, iterations: int = 5, elites: int = 10, init_std: float = 0.5,
                 min_std: float = 0.05, momentum: float = 0.1, keep: float = 0.3, execute: str = "mean",
                 seed: int = 0):
        check_plan_settings(horizon, population, iterations, elites)
        self.score = score
        self.low = torch.as_tensor(low, dtype=torch.float32)
        self.high = torch.as_tensor(high, dtype=torch.float32)
        self.horizon, self.population, self.iterations, self.elites = horizon, population, iterations, elites
        half_range = (self.high - self.low) / 2
        self.init_std, self.min_std = init_std * half_range, min_std * half_range
        self.momentum = momentum
        self.keep = min(int(keep * elites), population - 1)  # elites carried into the next round
        self.execute = execute
        self.kept: torch.Tensor | None = None
        self.generator = torch.Generator().manual_seed(seed)
        self.mean: torch.Tensor | None = None

    def reset(self, n: int) -> None:
        """Forget the warm start; the next plan starts from the middle of the action range."""
        self.mean = ((self.low + self.high) / 2).expand(n, self.horizon, -1).clone()
        self.kept = None

    @torch.no_grad()
    def plan(self, states: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        n, p, h = states.shape[0], self.population, self.horizon
        if self.mean is None or self.mean.shape[0] != n:
            self.reset(n)
        mean = self.mean
        std = self.init_std.expand_as(mean).clone()
        flat_states = states.repeat_interleave(p, 0)
        flat_goals = goals.repeat_interleave(p, 0)
        rows = torch.arange(n)[:, None]
        kept = self.kept
        for _ in range(self.iterations):
            noise = torch.randn((n, p, h, mean.shape[-1]), generator=self.generator)
            samples = torch.maximum(torch.minimum(mean[:, None] + std[:, None] * noise, self.high), self.low)
            samples[:, 0] = mean  # the current mean always competes
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


class EvoTorchCEM:
    """The same problem planned with EvoTorch's CEM (one env at a time, as the reference notebook does)."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 10,
                 population: int = 200, iterations: int = 5, elites: int = 20, init_std: float = 0.5,
                 seed: int = 0, **_):
        check_plan_settings(horizon, population, iterations, elites)
        require("evotorch", "evotorch", "--optimizer evotorch needs EvoTorch")  # fail here, not at the first plan
        self.score = score
        self.low, self.high = np.asarray(low, dtype=np.float32), np.asarray(high, dtype=np.float32)
        self.horizon, self.population, self.iterations, self.elites = horizon, population, iterations, elites
        self.init_std = float(init_std * np.max((self.high - self.low) / 2))
        self.seed = seed
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
        low, high = torch.as_tensor(self.low), torch.as_tensor(self.high)
        actions = []
        for i in range(states.shape[0]):
            s, g = states[i:i + 1], goals[i:i + 1]

            def objective(x: torch.Tensor, s=s, g=g) -> torch.Tensor:
                # EvoTorch's CEM searches an unbounded space: the env would clip, so the model sees clipped actions
                seqs = torch.maximum(torch.minimum(x.reshape(len(x), self.horizon, a_dim), high), low)
                return self.score(s.expand(len(x), -1), seqs, g.expand(len(x), -1))

            problem = Problem("max", objective, solution_length=self.horizon * a_dim, vectorized=True,
                              dtype=torch.float32, seed=self.seed)
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


OPTIMIZERS = {"cem": CEMPlanner, "evotorch": EvoTorchCEM}


def make_planner(optimizer: str, score: Scorer, low, high, **settings):
    if optimizer not in OPTIMIZERS:
        raise MotorlabError(f"--optimizer {optimizer!r}: choose {' or '.join(OPTIMIZERS)}.")
    return OPTIMIZERS[optimizer](score, low, high, **settings)


class MPCPolicy:
    """A planner as a motorlab Policy: act(observations) -> actions, through a state layout."""

    def __init__(self, planner, layout):
        self.planner, self.layout = planner, layout

    def reset(self, n: int) -> None:
        self.planner.reset(n)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        states = torch.as_tensor(self.layout.state(obs), dtype=torch.float32)
        goals = torch.as_tensor(self.layout.goal(obs), dtype=torch.float32)
        return self.planner.plan(states, goals).numpy()
