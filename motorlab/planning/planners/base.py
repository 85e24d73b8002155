"""What the batched planners share: the settings check, iCEM's coloured noise, a Gaussian over action
sequences per env (warm-started), and the record of a plan's rejected candidates."""

from __future__ import annotations

import math

import numpy as np
import torch

from motorlab.errors import MotorlabError
from motorlab.planning.mpc import PlannerFaults, Scorer, all_finite


def check_plan_settings(horizon: int, population: int, iterations: int, elites: int) -> None:
    for name, v in (("horizon", horizon), ("population", population), ("iterations", iterations),
                    ("elites", elites)):
        if v <= 0:
            raise MotorlabError(f"--{name} must be positive, got {v}.")
    if elites > population:
        raise MotorlabError(f"--elites ({elites}) cannot exceed --population ({population}).")


def colored_noise(shape: tuple[int, ...], beta: float, generator: torch.Generator,
                  device: torch.device | str = "cpu") -> torch.Tensor:
    """Gaussian noise of unit variance whose power falls as 1/f^beta along the second-to-last axis
    (time): beta 0 is white, 2 is red (Brownian-like: slow, smooth action sequences), as iCEM samples
    (Pinneri et al. 2020). A port of the `colorednoise` package's powerlaw_psd_gaussian (Timmer &
    Koenig 1995) to torch, so it draws with the planner's seeded generator on its device."""
    *lead, h, a = shape
    if beta == 0 or h < 2:
        return torch.randn(shape, generator=generator, device=device)
    f = torch.fft.rfftfreq(h, device=device)
    scale = f.clamp(min=1.0 / h) ** (-beta / 2)
    w = scale[1:].clone()
    w[-1] *= (1 + h % 2) / 2  # the Nyquist bin of an even length is real: half the weight
    sigma = 2 * torch.sqrt((w ** 2).sum()) / h
    size = (*lead, a, len(f))
    real = torch.randn(size, generator=generator, device=device) * scale
    imag = torch.randn(size, generator=generator, device=device) * scale
    if h % 2 == 0:  # the Nyquist bin is real
        imag[..., -1] = 0
        real[..., -1] *= math.sqrt(2)
    imag[..., 0] = 0  # and so is the mean's
    real[..., 0] *= math.sqrt(2)
    return (torch.fft.irfft(torch.complex(real, imag), n=h) / sigma).transpose(-1, -2)


class GaussianPlanner:
    """What CEM and MPPI share: a Gaussian over action sequences per env, in the action bounds,
    sampled with a seeded generator on the planner's device, its mean warm-started from the last plan."""

    def __init__(self, score: Scorer, low: np.ndarray, high: np.ndarray, horizon: int, population: int,
                 iterations: int, init_std: float, seed: int, device: torch.device | str,
                 faults: PlannerFaults | None = None, noise_beta: float = 0.0):
        self.score = score
        self.noise_beta = noise_beta
        self.faults = faults or PlannerFaults()
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
        noise = colored_noise((n, p, h, mean.shape[-1]), self.noise_beta, self.generator, self.device)
        samples = torch.maximum(torch.minimum(mean[:, None] + std[:, None] * noise, self.high), self.low)
        samples[:, 0] = mean  # the current mean always competes
        return samples

    def screen(self, returns: torch.Tensor) -> tuple[bool, torch.Tensor | None]:
        """(whether every candidate's return is finite, known without waiting for the device, and
        which are finite, (n, p), or None when all are). On a GPU the answer is always "not known":
        the guarded update costs a few small kernels, a check would cost a sync per iteration."""
        return (True, None) if all_finite(returns) else (False, torch.isfinite(returns))


class _PlanRecord:
    """One plan's record, per env, of rejected candidates: whether it met one, whether some
    iteration had a usable candidate (else the plan falls back to the previous one)."""

    def __init__(self):
        self.met: torch.Tensor | None = None
        self.found: torch.Tensor | None = None
        self.clean = False  # some iteration had only finite candidates, for every env

    def guarded(self, finite: torch.Tensor, usable: torch.Tensor) -> None:
        """An iteration with rejected candidates: `finite` (n, p), `usable` (n,) an env had one not rejected."""
        met = ~finite.all(1)
        self.met = met if self.met is None else self.met | met
        self.found = usable if self.found is None else self.found | usable

    def count(self, faults: PlannerFaults, n: int) -> None:
        faults.plan(n, self.met, None if self.clean or self.found is None else self.found)
