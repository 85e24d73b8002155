"""What each synergy does: a SAR policy evaluated intact and with each synergy's command zeroed.

A policy trained with `--sar sar.npz` emits synergy commands z (N coordinates in [-1, 1]; with
phi < 1 the raw muscle or motor commands follow them, [z, raw]), and the env's
`SynergyActionWrapper` decodes them. Ablating synergy k sets z_k = 0 in every action the policy
emits, before the wrapper decodes it (`ZeroedSynergy`, a policy wrapper: the policy acts in this
process while the envs may step in worker processes, so zeroing there needs no env change). The raw
part of a phi < 1 action is left as the policy emits it.

What zero means, in the synergy coordinates the policy emits: every SAR method ends in a
MinMaxScaler to [-1, 1] fitted on the recorded data, so z_k = 0 is the MIDDLE of the range the
synergy's coefficient took in the data the SAR was fitted on, not "no activation":

- pca-ica (and sklearn-import, the same chain): the middle of the fitted range of the k-th ICA
  source; a source's own zero (its mean, after ICA's centring) is generally elsewhere;
- pca: the middle of the range of the k-th principal-component score (its mean is 0 before
  scaling, so again generally elsewhere);
- nmf: the middle of the k-th NMF coefficient's fitted range, (min + max) / 2; the synergy's
  "off" (coefficient 0) is z_k = -1 only where the fitted minimum was 0.

So the ablation holds synergy k at its typical mid-range level and asks what the policy loses when
it can no longer modulate it.

Every condition runs the same episodes (episode i from reset seed seed + i, deterministic policy),
so the per-episode differences intact - ablated are paired; their mean is the return (or success)
lost, with a 95% percentile-bootstrap interval over episodes (`mean_interval`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.progress import Progress

from motorlab.envs import EnvConfig
from motorlab.errors import MotorlabError
from motorlab.evaluation.rollouts import Rollouts, open_evaluator, trained_env_settings
from motorlab.intervals import CONFIDENCE, MIN_SEEDS_FOR_INTERVAL, wilson
from motorlab.policies import Policy, load_run_policy
from motorlab.runs import require_run_dir
from motorlab.synergies.sar import load_sar

# The intervals module's rule for seeds holds for episodes too: a percentile bootstrap of fewer than
# 5 values mostly returns their extremes, which is their range, not a 95% interval.
MIN_EPISODES = MIN_SEEDS_FOR_INTERVAL
RESAMPLES = 9999  # scipy's default; the statistic is a mean of at most a few thousand numbers
BATCH = 50  # envs stepped side by side, as `motorlab.evaluation.evaluate` does
INTERVAL_METHOD = (f"{CONFIDENCE:.0%} percentile bootstrap over episodes of the paired per-episode differences "
                   f"(scipy.stats.bootstrap, {RESAMPLES} resamples, fixed rng seed 0)")


@dataclass(frozen=True)
class MeanInterval:
    """The mean of per-episode values with its 95% percentile-bootstrap interval over the `n` episodes."""

    mean: float
    low: float
    high: float
    n: int


def mean_interval(values: np.ndarray | list[float]) -> MeanInterval:
    """The mean of `values` (per-episode numbers, e.g. paired differences intact - ablated) and
    its 95% percentile-bootstrap interval (scipy.stats.bootstrap, `RESAMPLES` resamples, rng seed
    0: the same values give the same interval). Percentile rather than BCa: BCa's jackknife is
    undefined (NaN) when every value is the same, the usual case for a synergy the policy does
    not use, where the percentile interval is that one value.

    Raises:
        MotorlabError: fewer than MIN_EPISODES values, or a value that is not finite.
    """
    from scipy.stats import bootstrap

    x = np.asarray(values, dtype=np.float64).ravel()
    if len(x) < MIN_EPISODES:
        raise MotorlabError(f"{len(x)} episodes are too few for a 95% interval over episodes, which needs "
                            f"{MIN_EPISODES}; give --episodes {MIN_EPISODES} or more.")
    if not np.isfinite(x).all():
        raise MotorlabError("per-episode values must be finite to average them; leave out the faulted episodes.")
    ci = bootstrap((x,), np.mean, n_resamples=RESAMPLES, confidence_level=CONFIDENCE, method="percentile",
                   rng=np.random.default_rng(0)).confidence_interval
    return MeanInterval(float(np.mean(x)), float(ci.low), float(ci.high), len(x))


def paired_difference(before: np.ndarray, after: np.ndarray, keep: np.ndarray | None = None) -> MeanInterval | None:
    """before - after, episode by episode (the same reset seeds), averaged with its interval
    (`mean_interval`) over the episodes `keep` marks (default: all); None where fewer than
    MIN_EPISODES are kept (faulted episodes, or success undefined)."""
    before, after = np.asarray(before, dtype=np.float64), np.asarray(after, dtype=np.float64)
    keep = np.ones(len(before), bool) if keep is None else np.asarray(keep, bool)
    if keep.sum() < MIN_EPISODES:
        return None
    return mean_interval(before[keep] - after[keep])


class ZeroedSynergy:
    """`policy` with synergy coordinate `index` (0-based) of every action set to 0: what the SAR
    then decodes is the policy's command with that synergy held at the middle of its fitted range."""

    def __init__(self, policy: Policy, index: int):
        self.policy, self.index = policy, index

    def reset(self, n: int) -> None:
        self.policy.reset(n)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = np.array(self.policy.act(obs), copy=True)  # the policy's array may be its own buffer
        actions[:, self.index] = 0
        return actions

    def __getattr__(self, name: str):
        # Evaluation asks `hasattr(policy, "reset_row")` to restart rows one at a time: answer as the policy would
        if name != "reset_row":
            raise AttributeError(name)
        return getattr(self.policy, name)


@dataclass(frozen=True)
class SynergyLoss:
    """What zeroing one synergy cost, against the intact policy on the same episodes."""

    synergy: int  # 1-based: synergy k is coordinate k - 1 of the policy's action
    return_mean: float | None  # ablated
    success_rate: float | None  # ablated; None where the env defines no success
    return_lost: MeanInterval | None  # intact - ablated, per episode
    success_lost: MeanInterval | None


@dataclass(frozen=True)
class Ablation:
    """The intact policy and each synergy zeroed in turn, on the same `episodes` episodes."""

    run: Path
    env_id: str
    sar: str
    sar_method: str
    phi: float
    episodes: int
    seed: int
    baseline: Rollouts
    baseline_return: MeanInterval | None
    baseline_success: tuple[float, float] | None  # 95% Wilson interval of the intact success rate
    losses: list[SynergyLoss]
    fault_log: list[str]

    @property
    def n_synergies(self) -> int:
        return len(self.losses)

    def top(self) -> SynergyLoss | None:
        """The synergy whose loss costs the most return (None: no return difference could be measured)."""
        known = [s for s in self.losses if s.return_lost is not None]
        return max(known, key=lambda s: s.return_lost.mean) if known else None  # type: ignore[union-attr]


def sar_env(run_dir: Path) -> EnvConfig:
    """The env a run's policy acted in, which must put on a SAR.

    Raises:
        MotorlabError: a run trained without --sar (its policy emits the env's own actions).
    """
    cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    if not cfg.sar:
        raise MotorlabError(f"{run_dir} was trained without --sar: its policy emits {cfg.id}'s own actions, so there "
                            "is no synergy command to zero; give a run trained with --sar sar.npz.")
    return cfg


def ablate(run_dir: Path, episodes: int = 50, seed: int = 0, workers: int | None = None, progress: bool = False,
           before_work: Callable[[], None] | None = None) -> Ablation:
    """Evaluate a SAR run's deterministic policy intact and with each synergy zeroed in turn.

    Args:
        run_dir: a finished training run whose policy acts through a SAR (`train --sar`).
        episodes: episodes per condition; episode i starts from reset seed seed + i in every one.
        seed: the first episode's reset seed.
        workers: processes stepping the envs (None: every core when it pays, as `evaluate` decides);
            the results are the same for any number.
        progress: show a progress bar over the conditions.
        before_work: called once the run is checked, before the first episode (the step kind
            refuses a finished --out there).

    Raises:
        MotorlabError: not a finished run, a run without a SAR, fewer than MIN_EPISODES episodes.
    """
    run_dir = require_run_dir(Path(run_dir))
    cfg = sar_env(run_dir)
    if episodes < MIN_EPISODES:
        raise MotorlabError(f"--episodes {episodes} is too few for a 95% interval over episodes, which needs "
                            f"{MIN_EPISODES}; give --episodes {MIN_EPISODES} or more.")
    sar = load_sar(Path(cfg.sar))
    policy = load_run_policy(run_dir)
    if before_work is not None:
        before_work()
    conditions: list[tuple[str, Policy]] = [("intact", policy)]
    conditions += [(f"synergy {k + 1} zeroed", ZeroedSynergy(policy, k)) for k in range(sar.n_synergies)]
    results = _evaluate_all(cfg, conditions, episodes, seed, workers, progress)

    base = results[0]
    finite = np.isfinite(base.returns)
    judged = _judged(base)
    losses = []
    for k, r in enumerate(results[1:]):
        both_judged = judged & _judged(r)
        losses.append(SynergyLoss(
            synergy=k + 1, return_mean=r.summary()["return_mean"], success_rate=r.success_rate,
            return_lost=paired_difference(base.returns, r.returns, finite & np.isfinite(r.returns)),
            success_lost=paired_difference(base.success, r.success, both_judged)))
    faults = [f"{name}: {line}" for (name, _), r in zip(conditions, results) for line in r.fault_log]
    k = int(base.success[judged].sum())
    return Ablation(run=run_dir, env_id=cfg.id, sar=str(cfg.sar), sar_method=sar.method, phi=cfg.phi,
                    episodes=episodes, seed=seed, baseline=base,
                    baseline_return=mean_interval(base.returns[finite]) if finite.sum() >= MIN_EPISODES else None,
                    baseline_success=wilson(k, int(judged.sum())) if judged.any() else None,
                    losses=losses, fault_log=faults)


def _judged(r: Rollouts) -> np.ndarray:
    """Episodes whose success is known (a flag, or a maximum return to reach)."""
    return np.ones(len(r.success), bool) if r.judged is None else np.asarray(r.judged, bool)


def _evaluate_all(cfg: EnvConfig, conditions: list[tuple[str, Policy]], episodes: int, seed: int,
                  workers: int | None, progress: bool) -> list[Rollouts]:
    """Each policy on the same episodes, in one set of envs built once (`Evaluator.run` resets them
    from the same seeds every time), as `motorlab.evaluation.evaluate` runs one policy."""
    ev = open_evaluator(cfg, episodes, seed, workers, BATCH, work=episodes * len(conditions))
    with ev, Progress(disable=not progress, transient=True) as bar:
        task = bar.add_task("conditions", total=len(conditions))
        results = []
        for name, policy in conditions:
            bar.update(task, description=name)
            results.append(ev.run(policy, first_seed=seed, count=episodes))
            bar.advance(task)
    return results


def ablation_plot(a: Ablation, path: Path) -> Path | None:
    """Return lost (and success lost, where the env defines success) per synergy, with their 95%
    intervals over episodes as error bars."""
    from motorlab.report.plots import STYLE, plt, save_figure

    panels = [("return lost", [s.return_lost for s in a.losses], False)]
    if any(s.success_lost is not None for s in a.losses):
        panels.append(("success lost", [s.success_lost for s in a.losses], True))
    xs = np.arange(1, a.n_synergies + 1)
    with plt.rc_context(STYLE):
        width = max(4.5, 0.4 * len(xs) + 2)  # per panel: room for every synergy's bar
        fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), 3.8), squeeze=False)
        for ax, (label, values, percent) in zip(axes[0], panels):
            known = [(x, v) for x, v in zip(xs, values) if v is not None]
            if known:
                x, v = zip(*known)
                means = np.array([m.mean for m in v])
                errors = np.array([[m.mean - m.low for m in v], [m.high - m.mean for m in v]])
                scale = 100.0 if percent else 1.0
                ax.bar(x, scale * means, yerr=scale * np.maximum(errors, 0), capsize=3, color="tab:red", alpha=0.8)
            ax.axhline(0, color="gray", lw=0.8)
            ax.set_xticks(xs)
            ax.set_xlabel("synergy zeroed")
            ax.set_ylabel(f"{label} (percentage points)" if percent else label)
        fig.suptitle(f"{a.env_id}: what each synergy does ({a.episodes} episodes per condition)", fontsize=10)
        return save_figure(fig, path, f"Return and success lost when each synergy's command is zeroed (the middle of "
                           f"its fitted range), intact - ablated on the same {a.episodes} episodes; error bars: "
                           f"{INTERVAL_METHOD}.")
