"""Numerical faults end an episode instead of a run, and are counted; success is
"solved at any step" (manipulation) or "solved at the last step" (MyoSuite's walking tasks);
the training success rate is over the last 100 episodes."""

from __future__ import annotations

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from click.testing import CliRunner

from motorlab.cli import app
from motorlab.envs import EnvConfig, make_env
from motorlab.evaluation import EpisodeSuccess, Evaluator, evaluate, success_mode
from motorlab.kinds.dynamics import DYNAMICS_COLLECT
from motorlab.kinds.train import TRAIN
from motorlab.policies import ZeroPolicy
from motorlab.rl.config import TrainConfig
from motorlab.rl.monitor import TrainingMonitor
from tests.helpers import (
    assert_one_line_error,
    episode_rows,
    read_metrics_rows,
    read_summary,
    run_cli,
    run_here,
    run_kind,
)

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

FAULTY_ID = "MotorlabTestFaulty-v0"
SOLVED_ONCE_ID = "MotorlabTestSolvedOnce-v0"
EPISODE_STEPS = 8
FAULT_STEP = 4  # a faulty episode's observation is NaN at this step
SOLVED_STEP = 3  # a solvable episode reports solved=True at this step only


class FaultyEnv(gym.Env):
    """Reward 1 per step; in about half of the episodes (decided at reset from the env's
    seeded RNG, or always / never with options={"faulty": ...}) the observation of step
    FAULT_STEP holds a NaN (or, with options={"what": "reward"}, its reward is NaN)."""

    def __init__(self, render_mode=None):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.t = 0
        self.faulty = False
        self.what = "observation"
        self.data = SimpleNamespace(act=np.zeros(2))  # stands in for MuJoCo's muscle activations

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.faulty = bool(self.np_random.integers(2))
        options = options or {}
        self.faulty = bool(options.get("faulty", self.faulty))
        self.what = options.get("what", "observation")
        return np.zeros(3, np.float32), {}

    def step(self, action):
        self.t += 1
        self.data.act[:] = self.t / EPISODE_STEPS
        obs, reward = np.full(3, self.t / EPISODE_STEPS, np.float32), 1.0
        if self.faulty and self.t == FAULT_STEP:
            if self.what == "reward":
                reward = float("nan")
            else:
                obs[1] = np.nan
        return obs, reward, False, False, {}


class SolvedOnceEnv(gym.Env):
    """info["solved"] is True at step SOLVED_STEP only, in episodes reset with an even seed."""

    def __init__(self, render_mode=None):
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)
        self.t = 0
        self.solvable = False

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.solvable = seed is not None and seed % 2 == 0
        return np.zeros(2, np.float32), {"solved": False}

    def step(self, action):
        self.t += 1
        return np.zeros(2, np.float32), 0.0, False, False, {"solved": self.solvable and self.t == SOLVED_STEP}


for _id, _cls in ((FAULTY_ID, FaultyEnv), (SOLVED_ONCE_ID, SolvedOnceEnv)):
    if _id not in gym.registry:
        gym.register(_id, entry_point=_cls, max_episode_steps=EPISODE_STEPS, disable_env_checker=True)


# ---- NumericalGuard --------------------------------------------------------------------

def test_guard_ends_a_nan_episode_with_zero_reward():
    env = make_env(EnvConfig(id=FAULTY_ID))
    env.reset(seed=0, options={"faulty": True})
    for _t in range(1, FAULT_STEP):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert reward == 1.0 and not terminated and "numerical_fault" not in info
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert terminated and reward == 0.0
    assert "non-finite observation" in info["numerical_fault"]
    assert np.all(np.isfinite(obs)) and obs[1] == 0.0  # the NaN is zeroed, the rest kept
    assert obs[0] == pytest.approx(FAULT_STEP / EPISODE_STEPS)
    assert obs.dtype == np.float32


def test_guard_ends_an_episode_with_a_nan_reward():
    env = make_env(EnvConfig(id=FAULTY_ID))
    env.reset(seed=0, options={"faulty": True, "what": "reward"})
    rewards = []
    for _t in range(1, FAULT_STEP + 1):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        rewards.append(reward)
    assert terminated and "non-finite reward" in info["numerical_fault"]
    assert rewards == [1.0] * (FAULT_STEP - 1) + [0.0]
    assert obs[1] == pytest.approx(FAULT_STEP / EPISODE_STEPS)  # a finite observation is kept as it is


def test_guard_leaves_healthy_episodes_alone():
    env = make_env(EnvConfig(id=FAULTY_ID))
    env.reset(seed=0, options={"faulty": False})
    for _t in range(1, EPISODE_STEPS + 1):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert reward == 1.0 and not terminated and "numerical_fault" not in info
    assert truncated


def expected_faults(seeds) -> list[bool]:
    """Which reset seeds give a faulty episode, read from the env itself."""
    env = FaultyEnv()
    return [env.reset(seed=s) is not None and env.faulty for s in seeds]


def test_evaluate_counts_faulted_episodes():
    episodes = 12
    faulty = np.array(expected_faults(range(episodes)))
    assert 0 < faulty.sum() < episodes  # the seeds give both kinds
    env = make_env(EnvConfig(id=FAULTY_ID))
    result = evaluate(ZeroPolicy(env.action_space), EnvConfig(id=FAULTY_ID), episodes, seed=0, batch=5)
    assert result.faults == int(faulty.sum())
    np.testing.assert_array_equal(result.lengths, np.where(faulty, FAULT_STEP, EPISODE_STEPS))
    np.testing.assert_array_equal(result.returns, np.where(faulty, FAULT_STEP - 1, EPISODE_STEPS))
    assert result.summary()["numerical_faults"] == int(faulty.sum())


def test_evaluator_counts_faults_per_run():
    ev = Evaluator(EnvConfig(id=FAULTY_ID), episodes=6, seed=100)
    try:
        result = ev.run(ZeroPolicy(ev.action_space))
    finally:
        ev.close()
    assert result.faults == sum(expected_faults(range(100, 106)))


def test_evaluate_command_logs_faulted_episodes(tmp_path):
    """`motorlab evaluate` (in this process, where the faulty env is registered): faults.log names
    each faulted episode's seed and reason, summary.json counts them, stderr says so in one line."""
    episodes = 12
    faulty = np.array(expected_faults(range(episodes)))
    result = CliRunner().invoke(app, ["evaluate", "zero", "--env", FAULTY_ID, "--episodes", str(episodes),
                                      "--out", str(tmp_path / "eval")])
    assert result.exit_code == 0, result.output
    assert read_summary(tmp_path / "eval")["numerical_faults"] == faulty.sum()
    log = (tmp_path / "eval" / "faults.log").read_text().splitlines()
    assert [int(line.split()[0].removeprefix("seed=")) for line in log] == list(np.flatnonzero(faulty))
    assert all(f"length={FAULT_STEP}: non-finite observation" in line for line in log)
    warning = [line for line in result.stderr.splitlines() if "numerical fault" in line]
    assert len(warning) == 1 and f"{faulty.sum()} episodes" in warning[0] and "faults.log" in warning[0]


def test_evaluate_without_faults_writes_no_faults_log(tmp_path):
    result = CliRunner().invoke(app, ["evaluate", "zero", "--env", SOLVED_ONCE_ID, "--episodes", "3",
                                      "--out", str(tmp_path / "eval")])
    assert result.exit_code == 0, result.output
    assert read_summary(tmp_path / "eval")["numerical_faults"] == 0
    assert not (tmp_path / "eval" / "faults.log").exists() and "numerical fault" not in result.stderr


def test_dynamics_collect_leaves_a_faulted_episode_out_whole(tmp_path):
    """A faulty episode gives no transition at all, not its steps before the fault (the run-up to a
    diverging simulation is no physics either: tests/dynamics/test_diverging_episodes.py); every kept
    episode is whole and finite, and the faults are logged."""
    from motorlab.dynamics.transitions import load_transitions

    episodes = 10
    faulty = np.array(expected_faults(range(episodes)))
    assert 0 < faulty.sum() < episodes
    summary = run_kind(DYNAMICS_COLLECT, tmp_path / "data", env=FAULTY_ID, episodes=episodes, workers=1)
    data = load_transitions(tmp_path / "data")
    lengths = np.bincount(data.episode, minlength=episodes)
    np.testing.assert_array_equal(lengths, np.where(faulty, 0, EPISODE_STEPS))
    assert np.isfinite(data.states).all() and np.isfinite(data.next_states).all()
    ends = np.flatnonzero(np.diff(data.episode, append=episodes))  # the last row of each episode
    assert data.dones[ends].all() and data.dones.sum() == episodes - faulty.sum()
    assert summary["numerical_faults"] == data.meta["numerical_faults"] == faulty.sum()
    assert len((tmp_path / "data" / "faults.log").read_text().splitlines()) == faulty.sum()


@pytest.fixture(scope="module")
def faulty_run(tmp_path_factory):
    cfg = TrainConfig(env=EnvConfig(id=FAULTY_ID), algo="ppo", timesteps=256, seed=0, progress=False,
                      solve_episodes=2, hyperparams={"n_steps": 64, "batch_size": 32})
    run = tmp_path_factory.mktemp("faulty") / "run"
    return run, TRAIN.perform(cfg, run).keys()


def test_synergy_collect_never_keeps_a_faulted_episode(faulty_run, tmp_path):
    from motorlab.kinds.synergies import COLLECT

    run, _ = faulty_run
    summary = run_kind(COLLECT, tmp_path / "c", run=str(run), episodes=4, percentile=0.0, preview=6, workers=1)
    with np.load(tmp_path / "c" / "activations.npz", allow_pickle=False) as f:
        seeds, episode, acts = f["seeds"], f["episode"], f["activations"]
    preview_faulty = expected_faults(range(6))
    tried = expected_faults(range(6, 6 + summary["episodes_tried"]))
    assert not any(expected_faults(seeds.tolist()))  # kept episodes are the healthy ones
    assert np.bincount(episode).tolist() == [EPISODE_STEPS] * 4 and np.isfinite(acts).all()
    assert summary["numerical_faults"] == sum(preview_faulty) + sum(tried) > 0
    log = (tmp_path / "c" / "faults.log").read_text().splitlines()
    assert len(log) == summary["numerical_faults"] and sum(line.startswith("preview") for line in log) == sum(
        preview_faulty)


def test_training_survives_numerical_faults(faulty_run):
    run, summary = faulty_run
    assert read_summary(run)["numerical_faults"] == summary["numerical_faults"] > 0
    header, rows = read_metrics_rows(run)
    assert "numerical_fault" in header
    eps = episode_rows(rows)
    faulted = [r for r in eps if r["numerical_fault"] == "1"]
    healthy = [r for r in eps if r["numerical_fault"] == ""]
    assert len(faulted) + len(healthy) == len(eps) == summary["train_episodes"]
    assert len(faulted) == summary["numerical_faults"] and healthy
    for r in faulted:  # ended at the faulty step, which paid 0
        assert int(r["episode_length"]) == FAULT_STEP
        assert float(r["episode_return"]) == FAULT_STEP - 1
    for r in healthy:
        assert (int(r["episode_length"]), float(r["episode_return"])) == (EPISODE_STEPS, EPISODE_STEPS)
    log = (run / "faults.log").read_text().splitlines()
    assert len(log) == len(faulted)
    for line, r in zip(log, faulted):
        assert f"timesteps={r['timesteps']} " in line and "non-finite observation" in line
    assert (run / "policy.safetensors").is_file()


# ---- success: solved at any step -------------------------------------------------------

def test_episode_success_is_solved_at_any_step():
    outcome = EpisodeSuccess(2, target=None)
    for flag in (False, True, False, False):  # row 0: solved once, mid-episode
        outcome.step(0, {"solved": flag})
    for _ in range(4):
        outcome.step(1, {"solved": False})
    assert outcome.end(0, ret=0.0) is True
    assert outcome.end(1, ret=0.0) is False
    # a row restarts with its next episode
    outcome.step(0, {"solved": False})
    assert outcome.end(0, ret=0.0) is False
    # no flag from the env: the return decides where the task has a maximum, else unknowable
    assert EpisodeSuccess(1, target=10.0).end(0, ret=10.0) is True
    assert EpisodeSuccess(1, target=10.0).end(0, ret=9.0) is False
    assert EpisodeSuccess(1, target=None).end(0, ret=1e9) is None


def test_final_success_is_solved_at_the_last_step():
    outcome = EpisodeSuccess(3, target=None, mode="final")
    for flags in ((False, True, False), (True, True, True), (False, False, True)):
        for i, flag in enumerate(flags):  # row 0 solved mid-episode only, row 1 throughout, row 2 at the end
            outcome.step(i, {"solved": flag})
    for i, flag in enumerate((True, True, False)):
        outcome.step(i, {"solved": flag})  # last step of every row
    assert [outcome.end(i, ret=0.0) for i in range(3)] == [True, True, False]
    assert EpisodeSuccess(1, target=10.0, mode="final").end(0, ret=10.0) is True  # no flag: the return decides
    with pytest.raises(ValueError, match="any or final"):
        EpisodeSuccess(1, target=None, mode="sometimes")


@pytest.mark.parametrize("env_id, setting, mode", [
    ("myoLegWalk-v0", "auto", "final"), ("myoLegRoughTerrainWalk-v0", "auto", "final"),
    ("myoLegStairTerrainWalk-v0", "auto", "final"), ("myoHandReorient100-v0", "auto", "any"),
    ("InvertedPendulum-v5", "auto", "any"), ("myoLegWalk-v0", "any", "any"), ("myoHandReorient8-v0", "final", "final")])
def test_success_mode_is_final_for_walking_unless_set(env_id, setting, mode):
    assert success_mode(EnvConfig(id=env_id, success=setting)) == mode


def test_evaluate_final_success_ignores_a_mid_episode_solve():
    cfg = EnvConfig(id=SOLVED_ONCE_ID, success="final")
    result = evaluate(ZeroPolicy(make_env(cfg).action_space), cfg, 4, seed=0)
    assert result.summary()["success_rate"] == 0.0  # solved at step 3 of 8 only


def test_falling_forward_is_not_walking(tmp_path):
    """MyoSuite's walking "solved" means upright within 0.5 m/s of the commanded speed; a
    body falling forward meets it for a moment. Counted at any step, a policy that falls in
    every episode scores 100%; counted at the last step (the default for walking), 0%."""
    runs = {}
    for mode in ("auto", "any"):
        proc = run_cli("evaluate", "zero", "--env", "myoLegWalk-v0", "--episodes", "3", "--success", mode,
                       "--out", tmp_path / mode)
        assert proc.returncode == 0, proc.stderr
        runs[mode] = read_summary(tmp_path / mode)
    assert runs["auto"]["falls"] == runs["any"]["falls"] == 3
    assert runs["auto"]["success_mode"] == "final" and runs["auto"]["success_rate"] == 0.0
    assert runs["any"]["success_mode"] == "any" and runs["any"]["success_rate"] == 1.0


def test_bad_success_setting_is_one_line(tmp_path):
    proc = run_here("evaluate", "zero", "--env", "InvertedPendulum-v5", "--success", "sometimes",
                    "--out", tmp_path / "out")
    assert_one_line_error(proc, "--success")
    assert not (tmp_path / "out").exists()


def test_evaluate_success_counts_a_mid_episode_solve():
    env = make_env(EnvConfig(id=SOLVED_ONCE_ID))
    result = evaluate(ZeroPolicy(env.action_space), EnvConfig(id=SOLVED_ONCE_ID), 6, seed=0)
    assert np.all(result.lengths == EPISODE_STEPS)  # solved=False at the last step of every episode
    np.testing.assert_array_equal(result.success, [s % 2 == 0 for s in range(6)])
    assert result.summary()["success_rate"] == pytest.approx(0.5)


def test_tracker_success_rate_is_over_the_last_100_episodes(tmp_path):
    cfg = TrainConfig(env=EnvConfig(id=SOLVED_ONCE_ID), algo="ppo", solve_episodes=1, progress=False)
    monitor = TrainingMonitor(cfg, tmp_path, solve_return=None)
    outcomes = np.random.default_rng(0).random(150) < np.linspace(0.1, 0.9, 150)
    try:
        assert monitor.success_rate() is None  # nothing reported yet
        for i, ok in enumerate(outcomes):
            monitor.episode(steps=10 * (i + 1), ret=float(i), length=10, success=bool(ok))
            assert monitor.success_rate() == pytest.approx(outcomes[max(0, i - 99): i + 1].mean())
        monitor.episode(steps=1510, ret=0.0, length=10, success=None)  # an episode the env did not judge
        assert monitor.success_rate() == pytest.approx(outcomes[-100:].mean())
    finally:
        monitor.close()
    assert outcomes[-100:].mean() != pytest.approx(outcomes.mean())  # the window matters here
    _, rows = read_metrics_rows(tmp_path)
    assert len(rows) == 151
    for i, r in enumerate(rows[:150]):
        assert int(r["episode_success"]) == outcomes[i]
        assert float(r["success_rate_100"]) == pytest.approx(outcomes[max(0, i - 99): i + 1].mean())
    assert rows[150]["episode_success"] == "" and rows[150]["success_rate_100"] == ""


def test_myosuite_run_logs_training_success(hand_play_run):
    header, rows = read_metrics_rows(hand_play_run)
    assert {"episode_success", "success_rate_100"} <= set(header)
    eps = episode_rows(rows)
    assert eps
    success = np.array([int(r["episode_success"]) for r in eps])
    assert set(success) <= {0, 1}
    for i, r in enumerate(eps):
        assert float(r["success_rate_100"]) == pytest.approx(success[max(0, i - 99): i + 1].mean())
    s = read_summary(hand_play_run)
    assert 0.0 <= s["train_success_rate_last100"] <= 1.0
    assert s["train_success_rate_last100"] == pytest.approx(success[-100:].mean())
    assert s["train_episodes"] == len(eps)


def test_tables_show_training_success_only_where_the_env_judges_episodes(ppo_run, hand_play_run):
    """The pendulum has no success flag: its table has no training-success row (a return target
    would judge stochastic exploration episodes: 0% beside a solved policy), and its success is
    said to be the maximum return; the hand's flag ("solved") keeps the row, and is named."""
    from motorlab.report.results import read_run_results

    labels = {run: {n.key: n.label for n in read_run_results(run).numbers} for run in (ppo_run, hand_play_run)}
    assert "train_success_rate_last100" not in labels[ppo_run]
    assert labels[ppo_run]["success_rate"] == "success (return ≥ 1000)"
    assert read_summary(ppo_run)["train_success_rate_last100"] is None
    assert labels[hand_play_run]["train_success_rate_last100"] == \
        'training success (last 100 episodes, "solved" at any step)'
    assert labels[hand_play_run]["success_rate"] == 'success ("solved" at any step)'
    header, rows = read_metrics_rows(ppo_run)
    assert not any(r["episode_success"] for r in episode_rows(rows))  # nor in its metrics.csv
