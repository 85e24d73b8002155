"""`motorlab synergies ablate`: a SAR policy evaluated intact and with each synergy's command zeroed,
on the same episodes. Ground truth by construction: a policy on the user's arm (tests/userpkg) whose
command for one synergy is exactly 0 loses nothing when that synergy is ablated, and loses (or gains)
something when a synergy it uses is. The paired interval's properties on generated data (Hypothesis)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from safetensors.numpy import load_file, save_file

from motorlab.errors import MotorlabError
from motorlab.evaluation.rollouts import Rollouts
from motorlab.kinds.ablate import ABLATE
from motorlab.synergies import fit_sar, save_sar
from motorlab.synergy_runs.ablation import (
    MIN_EPISODES,
    Ablation,
    MeanInterval,
    SynergyLoss,
    ZeroedSynergy,
    ablation_plot,
    mean_interval,
    paired_difference,
)
from tests.helpers import (
    TINY_PPO,
    assert_ok,
    assert_one_line_error,
    assert_png,
    read_summary,
    run_cli,
    run_here,
    run_kind,
    user_packages_importable,
)

ARM = "userpkg.arm:ArmReach-v0"  # three motors, ctrlrange [-1, 1]
UNUSED = 1  # the synergy coordinate (0-based) whose command the policy never moves: synergy 2
GENERATED = settings(max_examples=40, deadline=None, derandomize=True, database=None)


@pytest.fixture(scope="module", autouse=True)
def user_package_on_path():
    """Every process motorlab starts imports the arm's package as an installed one: once a run of it
    is read in this process, motorlab passes `userpkg.arm` on to them all (even to train the pendulum)."""
    with user_packages_importable():
        yield


@pytest.fixture(scope="module")
def sar_run(tmp_path_factory) -> Path:
    """A tiny PPO run on the arm through a 3-synergy SAR of its motor commands, whose output layer
    then has synergy 2's row and bias zeroed: its deterministic command for synergy 2 is exactly 0
    (the mean action, clipped into [-1, 1]) on every observation."""
    folder = tmp_path_factory.mktemp("ablate")
    rng = np.random.default_rng(0)
    commands = np.tanh(rng.normal(size=(500, 3)) @ rng.normal(size=(3, 3)))  # 3 sources mixed, inside [-1, 1]
    save_sar(fit_sar(commands, n_synergies=3, method="pca-ica", seed=0, source_env=ARM, signal="ctrl",
                     bounds=(-np.ones(3), np.ones(3))), folder / "sar.npz")
    run = folder / "sar-rl"
    assert_ok(run_cli("train", ARM, "--sar", folder / "sar.npz", *TINY_PPO, "--seed", "0", "--no-progress",
                      "--out", run))
    weights = load_file(str(run / "policy.safetensors"))
    weights["policy.action_net.weight"][UNUSED] = 0.0
    weights["policy.action_net.bias"][UNUSED] = 0.0
    save_file(weights, str(run / "policy.safetensors"))
    return run


def test_a_synergy_the_policy_never_commands_loses_nothing(sar_run, tmp_path):
    out = tmp_path / "ablate"
    proc = run_cli("synergies", "ablate", sar_run, "--episodes", "8", "--workers", "1", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["n_synergies"] == 3 and s["synergy"] == [1, 2, 3] and s["episodes"] == 8 and s["sar_method"] == "pca-ica"
    # by construction: the same actions on the same episodes, so every paired difference is exactly 0
    assert (s["return_lost"][UNUSED], s["return_lost_low"][UNUSED], s["return_lost_high"][UNUSED]) == (0.0, 0.0, 0.0)
    assert s["return_mean"][UNUSED] == s["baseline_return_mean"]
    # the synergies it does command change what happens: some episode's return differs
    used = [k for k in range(3) if k != UNUSED]
    assert all(s["return_lost"][k] != 0 or s["return_lost_low"][k] < s["return_lost_high"][k] for k in used)
    for k in used:
        assert s["return_lost_low"][k] <= s["return_lost"][k] <= s["return_lost_high"][k]
        assert s["return_lost"][k] == pytest.approx(s["baseline_return_mean"] - s["return_mean"][k], abs=1e-9)
    # the arm defines no success: none is reported, rather than a 0% nobody measured
    assert s["baseline_success_rate"] is None and s["success_lost"] == [None] * 3
    assert "percentile bootstrap" in s["interval"] and "paired" in s["interval"]
    assert "synergy zeroed" in proc.stdout and "ablation.png" in proc.stdout
    assert_png(out / "ablation.png")


def test_the_result_does_not_depend_on_the_workers(sar_run, tmp_path):
    one = run_kind(ABLATE, tmp_path / "one", run=str(sar_run), episodes=6, workers=1)
    two = run_kind(ABLATE, tmp_path / "two", run=str(sar_run), episodes=6, workers=2)
    keys = ("baseline_return_mean", "return_mean", "return_lost", "return_lost_low", "return_lost_high")
    assert {k: one[k] for k in keys} == {k: two[k] for k in keys}
    numbers = {n["key"]: n for n in json.loads((tmp_path / "one" / "results.json").read_text())["numbers"]}
    assert numbers["top_return_lost"]["label"].startswith(f"return lost without synergy {one['top_synergy']} ")
    assert numbers["baseline_return_mean"]["text"].count("[") == 1  # with its 95% interval


def test_a_run_without_a_sar_is_refused_in_one_line(ppo_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_cli("synergies", "ablate", ppo_run, "--out", out), "trained without --sar",
                          "--sar sar.npz")
    assert not out.exists()


def test_too_few_episodes_for_an_interval_is_refused_in_one_line(sar_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_here("synergies", "ablate", sar_run, "--episodes", str(MIN_EPISODES - 1),
                                   "--out", out), f"--episodes {MIN_EPISODES - 1}", f"needs {MIN_EPISODES}")
    assert not out.exists()


# ---- the pieces -----------------------------------------------------------------------------

class Recorder:
    """A stateless policy that acts with fixed synergy commands (and, optionally, restarts rows)."""

    def __init__(self, action: list[float]):
        self.action = np.array(action, dtype=np.float32)

    def reset(self, n: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.repeat(self.action[None], len(obs), axis=0)


def test_zeroing_sets_one_coordinate_and_leaves_the_policy_alone():
    inner = Recorder([0.5, -0.25, 1.0, 0.25])  # with phi < 1: 2 synergies, then 2 raw commands
    zeroed = ZeroedSynergy(inner, 1)
    np.testing.assert_array_equal(zeroed.act(np.zeros((3, 5))), [[0.5, 0.0, 1.0, 0.25]] * 3)
    np.testing.assert_array_equal(inner.act(np.zeros((1, 5))), [[0.5, -0.25, 1.0, 0.25]])  # not written into
    assert not hasattr(zeroed, "reset_row")  # evaluation then runs episodes a batch at a time, as for the policy
    inner.reset_row = lambda i: None
    assert zeroed.reset_row is inner.reset_row


def test_the_plot_shows_success_where_the_env_defines_it(tmp_path):
    def m(mean: float) -> MeanInterval:
        return MeanInterval(mean, mean - 0.1, mean + 0.2, 10)

    losses = [SynergyLoss(k, -5.0, 0.5, m(1.0 * k), m(0.1 * k)) for k in (1, 2, 3, 4)]
    base = Rollouts(np.zeros(10), np.full(10, 50), np.ones(10, bool))
    a = Ablation(Path("run"), "myoHandReorient8-v0", "sar.npz", "pca-ica", 1.0, 10, 0, base, m(0.0), (0.7, 1.0),
                 losses, [])
    assert a.top() is losses[-1]
    assert_png(ablation_plot(a, tmp_path / "ablation.png"))


# ---- the paired interval, on generated per-episode values --------------------------------------

returns = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
episodes = st.integers(MIN_EPISODES, 60)


@GENERATED
@given(episodes.flatmap(lambda n: st.lists(returns, min_size=n, max_size=n)))
def test_the_same_returns_lose_exactly_nothing(values):
    d = paired_difference(np.array(values), np.array(values))
    assert (d.mean, d.low, d.high, d.n) == (0.0, 0.0, 0.0, len(values))


@GENERATED
@given(episodes.flatmap(lambda n: st.tuples(st.lists(returns, min_size=n, max_size=n),
                                            st.lists(returns, min_size=n, max_size=n))))
def test_the_interval_holds_the_mean_and_swapping_flips_it(pair):
    a, b = (np.array(v) for v in pair)
    d, flipped = paired_difference(a, b), paired_difference(b, a)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(a - b))))
    assert d.low - tol <= d.mean <= d.high + tol
    assert d.mean == pytest.approx(float(np.mean(a) - np.mean(b)), abs=tol)
    assert (flipped.mean, flipped.low, flipped.high) == pytest.approx((-d.mean, -d.high, -d.low), abs=tol)


@GENERATED
@given(st.lists(st.sampled_from([-1.0, 0.0, 1.0]), min_size=MIN_EPISODES, max_size=60))
def test_success_lost_stays_within_what_success_can_lose(differences):
    d = mean_interval(differences)
    assert -1.0 <= d.low <= d.mean <= d.high <= 1.0


def test_paired_difference_leaves_out_what_it_cannot_pair():
    before, after = np.arange(8.0), np.arange(8.0) - 1.0
    keep = np.array([True] * 6 + [False] * 2)
    assert paired_difference(before, after, keep).n == 6
    assert paired_difference(before, after, np.arange(8) < MIN_EPISODES - 1) is None
    with pytest.raises(MotorlabError, match=f"needs {MIN_EPISODES}"):
        mean_interval([1.0] * (MIN_EPISODES - 1))
