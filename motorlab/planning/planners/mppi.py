"""`--optimizer mppi`: the return-weighted average of all samples (MPPI), batched over envs."""

from __future__ import annotations

import numpy as np
import torch

from motorlab.errors import MotorlabError
from motorlab.planning.mpc import PlannerFaults, Scorer
from motorlab.planning.planners.base import GaussianPlanner, _PlanRecord, check_plan_settings


class MPPIPlanner(GaussianPlanner):
    """Batched MPPI (Williams et al. 2017) over action sequences: each iteration moves the mean to the
    average of all samples weighted by exp(standardized return / temperature).

    The returns are standardized per env before weighting, so one `temperature` works across envs
    whose rewards differ in scale (the raw-return form needs a temperature per env and reward).
    """

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 15,
                 population: int = 100, iterations: int = 1, init_std: float = 0.5, temperature: float = 0.5,
                 seed: int = 0, device: torch.device | str = "cpu", faults: PlannerFaults | None = None,
                 noise_beta: float = 0.0, **_):
        check_plan_settings(horizon, population, iterations, 1)
        if temperature <= 0:
            raise MotorlabError(f"--temperature must be positive, got {temperature}.")
        super().__init__(score, low, high, horizon, population, iterations, init_std, seed, device, faults,
                         noise_beta)
        self.temperature = temperature

    @torch.no_grad()
    def plan(self, states: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        n, p, h = states.shape[0], self.population, self.horizon
        mean, flat_states, flat_goals = self.start(states, goals)
        std = self.init_std.expand_as(mean)
        record = _PlanRecord()
        for _ in range(self.iterations):
            samples = self.sample(mean, std)
            returns = self.score(flat_states, samples.reshape(n * p, h, -1), flat_goals).reshape(n, p)
            clean, finite = self.screen(returns)
            if clean:
                record.clean = True
                z = (returns - returns.mean(1, keepdim=True)) / (returns.std(1, keepdim=True) + 1e-8)
                mean = (torch.softmax(z / self.temperature, dim=1)[:, :, None, None] * samples).sum(1)
            else:  # standardized over the usable candidates only; the rejected ones weigh nothing
                usable = finite.any(1)
                record.guarded(finite, usable)
                z = _standardized(returns, finite)
                moved = (torch.softmax(z / self.temperature, dim=1)[:, :, None, None] * samples).sum(1)
                mean = torch.where(usable[:, None, None], moved, mean)  # none usable: NaN weights, not taken
        record.count(self.faults, n)
        self.mean = torch.cat([mean[:, 1:], mean[:, -1:]], dim=1)
        return mean[:, 0]


def _standardized(returns: torch.Tensor, finite: torch.Tensor) -> torch.Tensor:
    """Returns (n, p) standardized per row over its finite entries (as Tensor.std: unbiased); -inf
    for the others."""
    count = finite.sum(1, keepdim=True)
    kept = torch.where(finite, returns, 0.0)
    mu = kept.sum(1, keepdim=True) / count.clamp(min=1)
    var = torch.where(finite, (kept - mu) ** 2, 0.0).sum(1, keepdim=True) / (count - 1).clamp(min=1)
    return torch.where(finite, (kept - mu) / (var.sqrt() + 1e-8), float("-inf"))


# the plan settings (MpcSettings.plan) this planner takes
SETTINGS = ("horizon", "population", "iterations", "temperature", "noise_beta")
PLANNER = MPPIPlanner
