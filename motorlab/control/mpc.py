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

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
import torch

from motorlab.dynamics.model import stepwise_rollout
from motorlab.errors import MotorlabError
from motorlab.extras import require

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
    see motorlab.dynamics.rewards.Task; a None reward or a "learned" termination use the model's heads)
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


OPTIMIZERS = {"cem": CEMPlanner, "mppi": MPPIPlanner, "evotorch": EvoTorchCEM}


def make_planner(optimizer: str, score: Scorer, low, high, **settings):
    if optimizer not in OPTIMIZERS:
        raise MotorlabError(f"--optimizer {optimizer!r}: choose {', '.join(OPTIMIZERS)}.")
    return OPTIMIZERS[optimizer](score, low, high, **settings)


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
