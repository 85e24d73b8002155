"""`--optimizer evotorch`: EvoTorch's CEM, one env at a time (the reference notebook's planner)."""

from __future__ import annotations

import logging

import numpy as np
import torch

from motorlab.extras import require
from motorlab.planning.mpc import PlannerFaults, Scorer
from motorlab.planning.planners.base import check_plan_settings


class EvoTorchCEM:
    """The same problem planned with EvoTorch's CEM (one env at a time, as the reference notebook does)."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int = 10,
                 population: int = 200, iterations: int = 5, elites: int = 20, init_std: float = 0.5,
                 seed: int = 0, device: torch.device | str = "cpu", faults: PlannerFaults | None = None, **_):
        check_plan_settings(horizon, population, iterations, elites)
        require("evotorch", "evotorch", "--optimizer evotorch needs EvoTorch")  # fail here, not at the first plan
        self.score = score
        self.faults = faults or PlannerFaults()
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
        met, found = [], []
        for i in range(states.shape[0]):
            s, g = states[i:i + 1], goals[i:i + 1]
            seen = {"rejected": False, "usable": False}

            def objective(x: torch.Tensor, s=s, g=g, seen=seen) -> torch.Tensor:
                # EvoTorch's CEM searches an unbounded space: the env would clip, so the model sees clipped actions
                seqs = torch.maximum(torch.minimum(x.reshape(len(x), self.horizon, a_dim), high), low)
                returns = self.score(s.expand(len(x), -1), seqs, g.expand(len(x), -1))
                finite = torch.isfinite(returns)
                seen["rejected"] |= not bool(finite.all())
                seen["usable"] |= bool(finite.any())
                return returns.clamp(min=-1e30)  # a rejected candidate ranks last; EvoTorch takes no -inf

            problem = Problem("max", objective, solution_length=self.horizon * a_dim, vectorized=True,
                              dtype=torch.float32, seed=self.seed, device=self.device)
            searcher = CEM(problem, popsize=self.population, parenthood_ratio=self.elites / self.population,
                           stdev_init=self.init_std, center_init=self.centers[i])
            for _ in range(self.iterations):
                searcher.step()
            center = np.clip(searcher.status["center"].cpu().numpy(), np.tile(self.low, self.horizon),
                             np.tile(self.high, self.horizon))
            if not seen["usable"]:  # every candidate rejected: the last plan's next action, its centre kept
                center = self.centers[i]
            plan = center.reshape(self.horizon, a_dim)
            self.centers[i] = np.concatenate([plan[1:], plan[-1:]]).ravel()
            actions.append(plan[0])
            met.append(seen["rejected"])
            found.append(seen["usable"])
        self.faults.plan(len(met), torch.tensor(met), torch.tensor(found))
        return torch.as_tensor(np.array(actions))


# the plan settings (MpcSettings.plan) this planner takes
SETTINGS = ("horizon", "population", "iterations", "elites")
PLANNER = EvoTorchCEM
