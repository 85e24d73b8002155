"""`--optimizer cem`: the cross-entropy method, batched over envs, with iCEM's kept elites."""

from __future__ import annotations

import numpy as np
import torch

from motorlab.planning.mpc import PlannerFaults, Scorer
from motorlab.planning.planners.base import GaussianPlanner, _PlanRecord, check_plan_settings


class CEMPlanner(GaussianPlanner):
    """Batched CEM over action sequences; `plan(states, goals)` gives one action per env."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 15,
                 population: int = 100, iterations: int = 5, elites: int = 10, init_std: float = 0.5,
                 min_std: float = 0.05, momentum: float = 0.1, keep: float = 0.3, execute: str = "mean",
                 seed: int = 0, device: torch.device | str = "cpu", faults: PlannerFaults | None = None,
                 noise_beta: float = 0.0):
        check_plan_settings(horizon, population, iterations, elites)
        super().__init__(score, low, high, horizon, population, iterations, init_std, seed, device, faults,
                         noise_beta)
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
        record = _PlanRecord()
        usable = None
        for _ in range(self.iterations):
            samples = self.sample(mean, std)
            if kept is not None:  # iCEM (Pinneri et al. 2020): the best few of the last round compete again
                samples[:, 1:1 + kept.shape[1]] = kept
            returns = self.score(flat_states, samples.reshape(n * p, h, -1), flat_goals).reshape(n, p)
            clean, finite = self.screen(returns)
            if clean:
                record.clean = True
                elite = samples[rows, returns.topk(self.elites, dim=1).indices]  # (n, elites, h, A), best first
            else:  # a rejected elite gives way to the best one; an env without a usable candidate keeps its Gaussian
                top = returns.masked_fill(~finite, float("-inf")).topk(self.elites, dim=1)  # rejected ones last
                ok = torch.isfinite(top.values)
                elite = samples[rows, torch.where(ok, top.indices, top.indices[:, :1])]
                usable = ok[:, 0]
                record.guarded(finite, usable)
            kept = elite[:, :self.keep]
            new_mean = self.momentum * mean + (1 - self.momentum) * elite.mean(1)
            new_std = torch.maximum(self.momentum * std + (1 - self.momentum) * elite.std(1), self.min_std)
            if clean:
                mean, std = new_mean, new_std
            else:
                mean = torch.where(usable[:, None, None], new_mean, mean)
                std = torch.where(usable[:, None, None], new_std, std)
        record.count(self.faults, n)
        # warm start: shift the mean and the kept elites by one step for the next control step
        self.mean = torch.cat([mean[:, 1:], mean[:, -1:]], dim=1)
        self.kept = torch.cat([kept[:, :, 1:], kept[:, :, -1:]], dim=2) if self.keep else None
        if self.execute != "best":
            return mean[:, 0]
        return elite[:, 0, 0] if clean else torch.where(usable[:, None], elite[:, 0, 0], mean[:, 0])


# the plan settings (MpcSettings.plan) this planner takes
SETTINGS = ("horizon", "population", "iterations", "elites", "noise_beta")
PLANNER = CEMPlanner
