"""Spaces beyond one Box in the model-based kinds: a Dict observation (Gymnasium-Robotics' point maze)
collected, fitted, checked and planned on flat, each key's slice recorded and read back; synergies
collected on it; discrete actions refused before any work; and the planner's NaN/Inf: rejected,
counted, warned about once, never an action the env gets."""

from __future__ import annotations

import contextlib
import io
import json
import os
import textwrap

import gymnasium as gym
import numpy as np
import pytest
import torch

from motorlab.controllers.lqr import LQRSettings, learn_lqr
from motorlab.controllers.pid import pid_for_env
from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.model import ForwardModel, load_model
from motorlab.dynamics.planner_rewards import Task, resolve_task
from motorlab.dynamics.transitions import load_transitions
from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.kinds.dynamics import DYNAMICS_CHECK, DYNAMICS_COLLECT, DYNAMICS_FIT
from motorlab.kinds.planning import MPC
from motorlab.kinds.synergies import COLLECT
from motorlab.kinds.train import TRAIN
from motorlab.planning.mpc import PlannerFaults, model_scorer
from motorlab.planning.mpc_episodes import build_policy, run_episodes
from motorlab.planning.planners.cem import CEMPlanner
from motorlab.planning.planners.mppi import MPPIPlanner
from tests.helpers import assert_ok, read_summary, run_cli, run_kind

with contextlib.redirect_stderr(io.StringIO()):  # its import prints a notice about other envs, once
    import gymnasium_robotics  # noqa: F401  (registers PointMaze_UMaze-v3 in this process)

MAZE = "gymnasium_robotics:PointMaze_UMaze-v3"
# gymnasium.spaces.flatten's order: the Dict's keys sorted
MAZE_LAYOUT = [{"key": "achieved_goal", "start": 0, "stop": 2, "shape": [2]},
               {"key": "desired_goal", "start": 2, "stop": 4, "shape": [2]},
               {"key": "observation", "start": 4, "stop": 8, "shape": [4]}]
TINY_PLAN = dict(horizon=10, population=60, iterations=2, elites=6)
NAN_REWARD = '''
import torch


def reward(obs, action, next_obs):
    """Minus the distance to the goal, NaN once the point is more than 0.6 from the maze's x = 0
    (the probes, in [-0.5, 0.5], never see it)."""
    r = -torch.linalg.vector_norm(next_obs[..., 0:2] - next_obs[..., 2:4], dim=-1)
    return torch.where(next_obs[..., 0].abs() < 0.6, r, torch.nan)
'''


@pytest.fixture(scope="module")
def maze(tmp_path_factory):
    """10 random episodes of the point maze (3000 transitions) and a model fit on them."""
    root = tmp_path_factory.mktemp("maze")
    collect = run_kind(DYNAMICS_COLLECT, root / "data", env=MAZE, episodes=10, workers=1)
    fit = run_kind(DYNAMICS_FIT, root / "model", transitions=str(root / "data"), epochs=50)  # the default: SiLU
    # layers need ~100 gradient steps (2 a epoch here); at 15 epochs the held-out MSE was 0.65, at 50 0.10
    return root, collect, fit


# ---- a Dict observation, end to end -----------------------------------------------------------


def test_a_dict_observation_is_collected_flat_with_its_keys_recorded(maze):
    root, collect, _ = maze
    assert collect["state_size"] == 8 and collect["action_size"] == 2 and collect["transitions"] == 10 * 300
    data = load_transitions(root / "data")
    assert data.meta["obs_layout"] == MAZE_LAYOUT
    assert data.meta["state_labels"][:3] == ["achieved_goal[0]", "achieved_goal[1]", "desired_goal[0]"]
    assert data.meta["goal_labels"] == ["desired_goal[0]", "desired_goal[1]"]
    assert data.meta["action_space"]["type"] == "Box"
    np.testing.assert_array_equal(data.goals, data.states[:, 2:4])  # the planner's goal: the desired_goal
    # the flat state is Gymnasium's own flattening of the env's Dict: episode 0 reset with seed 0
    raw = gym.make("PointMaze_UMaze-v3")
    first, _ = raw.reset(seed=0)
    np.testing.assert_array_equal(data.states[0], gym.spaces.flatten(raw.observation_space, first))
    raw.close()


def test_the_model_records_the_layout_and_dynamics_check_names_the_keys(maze, tmp_path):
    root, _, fit = maze
    assert fit["valid_mse"] < 0.5
    model_json = json.loads((root / "model" / "model.json").read_text())
    assert model_json["obs_layout"] == MAZE_LAYOUT and model_json["action_space"]["type"] == "Box"
    assert load_model(root / "model").meta["obs_layout"] == MAZE_LAYOUT  # read back as written
    check = run_kind(DYNAMICS_CHECK, tmp_path, model=str(root / "model"), episodes=2, steps=20)
    assert check["worst_dimension"].split("[")[0] in ("achieved_goal", "desired_goal", "observation")
    header = (tmp_path / "error_by_dimension.csv").read_text().splitlines()[0]
    assert '"achieved_goal[0]"' in header and '"observation[3]"' in header
    assert np.isfinite(check["state_nrmse_h1"]) and check["state_nrmse_h1"] < check["state_nrmse_h10"]


def test_mpc_reaches_the_maze_goal_with_the_goal_reward(maze, tmp_path):
    root, _, _ = maze
    s = run_kind(MPC, tmp_path, env=MAZE, model=str(root / "model"), episodes=1, **TINY_PLAN)
    assert s["reward_source"] == "goal" and s["termination_source"] == "none"
    distances = np.load(tmp_path / "episodes.npz")["distances"]
    # from the start to within the maze's success radius (0.45) of the desired goal, and kept there:
    # the env's own sparse reward pays 1 per step within it
    assert distances[0, 0] > 0.45 and s["final_distance_mean"] < 0.45 and s["return_mean"] > 100
    assert s["numerical_faults"] == s["planner_faults"] == 0


def test_the_goal_reward_needs_both_goal_keys():
    with pytest.raises(MotorlabError, match="--reward goal: .* needs an env whose Dict observation holds both keys"):
        resolve_task("Pendulum-v1", "observation", 3, 1, reward="goal")
    # a goal-conditioned env without a bundled reward or a learned head plans with it by default
    assert resolve_task(MAZE, "observation", 8, 2, 2, achieved=slice(0, 2)).reward_source == "goal"
    # a learned head, where the model has one, comes first
    assert resolve_task(MAZE, "observation", 8, 2, 2, learned=frozenset({"reward"}),
                        achieved=slice(0, 2)).reward_source == "learned"


def test_synergies_collect_on_a_dict_observation_env(tmp_path):
    run_kind(TRAIN, tmp_path / "lqr", env=MAZE, algo="lqr", timesteps=300)
    s = run_kind(COLLECT, tmp_path / "collect", run=str(tmp_path / "lqr"), episodes=2, preview=2, percentile=0,
                 workers=1)
    assert s["signal"] == "ctrl" and s["n_signals"] == 2 and s["samples"] == 2 * 300  # the point's two motors
    activations = np.load(tmp_path / "collect" / "activations.npz")["activations"]
    assert activations.shape == (600, 2) and np.isfinite(activations).all() and np.abs(activations).max() <= 1


# ---- discrete actions: one line, before any work ----------------------------------------------


def test_discrete_actions_are_refused_by_each_part_that_needs_a_box():
    with pytest.raises(MotorlabError, match=r"^dynamics collect needs continuous \(Box\) actions, and CartPole-v1's "
                                            r"actions are Discrete\(2\); learn it model-free"):
        collect_transitions("CartPole-v1", 2, workers=1, progress=False)
    env = make_env(EnvConfig(id="CartPole-v1"), shaped=False)
    with pytest.raises(MotorlabError, match=r"^MPC needs continuous \(Box\) actions.*Discrete\(2\)"):
        build_policy(env, "CartPole-v1", "no-model-is-read-first")
    with pytest.raises(MotorlabError, match=r"^the PID controller needs continuous \(Box\) actions.*Discrete\(2\)"):
        pid_for_env("pid:kp=1", env, "CartPole-v1")
    env.close()
    with pytest.raises(MotorlabError, match=r"^the LQR learner \(--algo lqr\) needs continuous \(Box\) actions"):
        learn_lqr(EnvConfig(id="CartPole-v1"), LQRSettings(), 100, 0, on_update=lambda *a: True)


def test_collect_closes_its_env_whatever_ends_it(monkeypatch, tmp_path):
    """dynamics collect's env is closed when a check refuses the collection (a policy folder that is not
    there, a finished --out through before_work), not only after its episodes."""
    from motorlab.dynamics import collection

    closed = []
    made = collection.make_env

    def watched(*args, **kwargs):
        env = made(*args, **kwargs)
        close = env.close
        env.close = lambda: (closed.append(True), close())[1]
        return env

    def refuse():
        raise MotorlabError("refused before the episodes")

    monkeypatch.setattr(collection, "make_env", watched)
    with pytest.raises(MotorlabError, match="neither 'random' nor a run folder"):
        collect_transitions("Pendulum-v1", 1, policy=str(tmp_path / "missing"), workers=1, progress=False)
    assert closed == [True]
    with pytest.raises(MotorlabError, match="refused before the episodes"):
        collect_transitions("Pendulum-v1", 1, workers=1, progress=False, before_work=refuse)
    assert closed == [True, True]
    assert len(collect_transitions("Pendulum-v1", 1, workers=1, progress=False)) == 200 and closed == [True] * 3


# ---- the planner's NaN and Inf --------------------------------------------------------------------


class _Rows:
    """A model whose next state is the state plus the action (S = A = 1): a planner test bed."""

    members, plain = 1, True

    def fast_rollout(self):
        return lambda states, actions: torch.cat([states[:, None], states[:, None] + actions.cumsum(1)], 1)


def _planner(kind, score, faults, **kw):
    low, high = np.array([-1.0], dtype=np.float32), np.array([1.0], dtype=np.float32)
    settings = dict(horizon=4, population=40, iterations=3, seed=0, faults=faults)
    return kind(score, low, high, **settings, **({"elites": 5} if kind is CEMPlanner else {}), **kw)


@pytest.mark.parametrize("kind", [CEMPlanner, MPPIPlanner])
def test_non_finite_candidates_are_rejected_and_counted(kind):
    """The reward is +inf (what nan_to_num used to make the best) for a first action above 0.2, NaN
    below -0.2, else minus its distance from 0.1: the plan is never one of the rejected ones."""
    def reward(state, action, next_state, goal):
        a = action[..., 0]
        return torch.where(a > 0.2, torch.inf, torch.where(a < -0.2, torch.nan, -(a - 0.1).abs()))

    faults = PlannerFaults()
    planner = _planner(kind, model_scorer(_Rows(), reward, faults=faults), faults)
    actions = [planner.plan(torch.zeros(3, 1), torch.zeros(3, 0)) for _ in range(4)]
    assert all(torch.isfinite(a).all() and (a.abs() <= 0.2).all() for a in actions)
    counts = faults.counts()
    assert counts.plans == 12 and counts.faulty_plans == 12 and counts.rewards > 0
    assert counts.states == 0 and counts.fallbacks == 0


@pytest.mark.parametrize("kind", [CEMPlanner, MPPIPlanner])
def test_a_plan_with_no_finite_candidate_falls_back_to_the_previous_one(kind):
    calls = {"n": 0}

    def reward(state, action, next_state, goal):  # finite for the first plan's 3 scorings, NaN after
        return -action[..., 0].abs() if calls["n"] <= 3 else torch.full(action.shape[:-1], torch.nan)

    def score(states, actions, goals):
        calls["n"] += 1
        return scorer(states, actions, goals)

    faults = PlannerFaults()
    scorer = model_scorer(_Rows(), reward, faults=faults)
    planner = _planner(kind, score, faults)
    planner.plan(torch.zeros(2, 1), torch.zeros(2, 0))
    warm = planner.mean.clone()  # the first plan, shifted: what the next one starts from
    action = planner.plan(torch.zeros(2, 1), torch.zeros(2, 0))
    torch.testing.assert_close(action, warm[:, 0])
    counts = faults.counts()
    assert counts.fallbacks == 2 and counts.faulty_plans == 2 and counts.rewards == 2 * 40 * 3


@pytest.mark.parametrize("kind", [CEMPlanner, MPPIPlanner])
def test_the_guarded_update_plans_as_the_fast_one_when_all_is_finite(kind, monkeypatch):
    """On a GPU every iteration takes the guarded update (checking for NaN would wait for the device):
    with finite returns it must plan exactly as the CPU's fast path, and count nothing."""
    def reward(state, action, next_state, goal):
        return -(next_state[..., 0] - 0.3).square() - 0.1 * action[..., 0].square()

    def plans(guarded: bool):
        if guarded:
            monkeypatch.setattr("motorlab.planning.mpc.all_finite", lambda values: False)
        faults = PlannerFaults()
        planner = _planner(kind, model_scorer(_Rows(), reward, faults=faults), faults)
        actions = [planner.plan(torch.zeros(3, 1), torch.zeros(3, 0)) for _ in range(3)]
        monkeypatch.undo()
        return torch.stack(actions), faults.counts()

    fast, fast_counts = plans(False)
    guarded, guarded_counts = plans(True)
    torch.testing.assert_close(guarded, fast)
    assert fast_counts == guarded_counts and guarded_counts.plans == 9 and guarded_counts.faulty_plans == 0


def test_a_model_that_diverges_is_counted_as_such():
    model = ForwardModel(2, 1, hidden=(8,))
    with torch.no_grad():
        model.net.weights[-1][0, 0, 0] = torch.nan  # a model gone bad: its predicted states are NaN
    faults = PlannerFaults()
    score = model_scorer(model, Task(lambda s, a, s2, g: -s2.square().sum(-1), None, "builtin", "none"),
                         faults=faults)
    returns = score(torch.zeros(6, 2), torch.zeros(6, 3, 1), torch.zeros(6, 0))
    assert (returns == -torch.inf).all()
    assert faults.counts().states == 6 and faults.counts().rewards == 0


def test_a_nan_reward_is_warned_about_once_and_no_nan_action_reaches_the_env(maze, tmp_path, monkeypatch):
    root, _, _ = maze
    (tmp_path / "nanmod.py").write_text(textwrap.dedent(NAN_REWARD))
    out = tmp_path / "mpc"
    proc = run_cli("mpc", MAZE, "--model", root / "model", "--episodes", "2", "--horizon", "10", "--population",
                   "60", "--iterations", "2", "--elites", "6", "--reward", "nanmod:reward", "--out", out,
                   env={"PYTHONPATH": str(tmp_path)})
    assert_ok(proc)
    s = read_summary(out)
    assert s["planner_faults"] > 0 and s["planner_nonfinite_rewards"] > 0 and s["planner_nonfinite_states"] == 0
    assert s["episode_faults"] == 0 and s["numerical_faults"] == s["planner_faults"]
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning: planner:")]
    assert len(warnings) == 1, proc.stderr
    assert f"{s['planner_faults']} of " in warnings[0] and "reward nanmod:reward" in warnings[0]
    assert "faults.log" in warnings[0] and "Traceback" not in proc.stderr
    log = (out / "faults.log").read_text().splitlines()
    assert len(log) == 1 and log[0].startswith(f"planner: {s['planner_faults']} of ")

    # the same planner in this process: every action it sent the env was finite and in its bounds
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("MOTORLAB_IMPORTS", os.environ.get("MOTORLAB_IMPORTS", ""))  # nanmod: not for later tests
    env = make_env(EnvConfig(id=MAZE), shaped=False)
    policy = build_policy(env, MAZE, root / "model", reward="nanmod:reward", device="cpu", **TINY_PLAN)
    env.close()
    result = run_episodes(MAZE, policy, 1, 0, 1, progress=False, record=True)
    actions = result.paths[0].actions
    assert result.planner.faulty_plans > 0 and np.isfinite(actions).all() and np.abs(actions).max() <= 1
    assert np.isfinite(result.paths[0].observations).all()
