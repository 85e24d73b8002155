"""Rewards and terminations the planner scores predicted paths with (motorlab/dynamics/planner_rewards.py):
the bundled ones equal the Gymnasium envs' own on real transitions, a user's torch function from
their package reproduces their env's reward, and every wrong input gets one line naming the fix."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motorlab import user_modules
from motorlab.dynamics import planner_rewards as rewards
from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.planner_rewards import (
    PENDULUM_RAIL_END,
    Task,
    UserFunction,
    builtin_envs,
    load_function,
    resolve_task,
    reward_for,
)
from motorlab.errors import MotorlabError

ARM = "userpkg.arm:ArmReach-v0"  # tests/ is on sys.path under pytest, as in test_user_env.py
ARM_REWARD = "userpkg.arm_reward"


@pytest.fixture(autouse=True)
def imports_passed_on(monkeypatch):
    """Loading a user function passes its module on in $MOTORLAB_IMPORTS: keep that to each test."""
    monkeypatch.setenv(user_modules.ENV_VAR, "")


def collect(env_id: str, episodes: int):
    return collect_transitions(env_id, episodes, workers=1, seed=0, state="observation", simulator="gymnasium",
                               progress=False)


def tensors(data, dtype):
    return [torch.as_tensor(x, dtype=dtype) for x in (data.states, data.actions, data.next_states)]


def assert_matches(task: Task, data) -> None:
    """The task's reward and termination equal the env's, in float64 and float32, on any leading shape."""
    for dtype, tol in ((torch.float64, 1e-9), (torch.float32, 1e-5)):
        s, a, n = tensors(data, dtype)
        goal = torch.zeros(len(s), 0, dtype=dtype)
        reward = task.reward(s, a, n, goal)
        assert reward.shape == (len(s),) and reward.dtype == dtype
        np.testing.assert_allclose(reward.numpy(), data.rewards, rtol=tol, atol=tol)
        batched = task.reward(s[None], a[None], n[None], goal[None])  # (1, N, ...): any leading dims
        np.testing.assert_allclose(batched[0].numpy(), reward.numpy(), rtol=1e-6, atol=1e-6)
        if task.termination is not None:
            done = task.termination(s, a, n, goal)
            assert done.dtype == torch.bool and done.shape == (len(s),)
            ends = data.terminated
            if data.env_id.startswith("InvertedPendulum"):  # the planner also ends at the rail's end
                ends = ends | (np.abs(data.next_states[:, 0]) > PENDULUM_RAIL_END)
            np.testing.assert_array_equal(done.numpy(), ends)


@pytest.mark.parametrize("env_id, episodes, terminates", [
    ("Reacher-v5", 2, False), ("Reacher-v4", 2, False), ("Pusher-v5", 2, False),
    ("InvertedPendulum-v5", 6, True), ("InvertedPendulum-v4", 6, True),
    ("HumanoidStandup-v5", 1, False), ("HumanoidStandup-v4", 1, False),
])
def test_builtins_are_the_envs_own_rewards_and_terminations(env_id, episodes, terminates):
    data = collect(env_id, episodes)
    task = resolve_task(env_id, "observation", data.states.shape[1], data.actions.shape[1])
    assert task.reward_source == "builtin"
    assert task.termination_source == ("builtin" if terminates else "none")
    assert (task.termination is not None) == terminates
    assert data.terminated.any() == terminates  # random actions topple the pendulum within a few steps
    assert_matches(task, data)
    # an explicit --termination builtin on an env that never terminates is no termination
    assert resolve_task(env_id, "observation", data.states.shape[1], data.actions.shape[1], reward="builtin",
                        termination="builtin").termination_source == ("builtin" if terminates else "none")


def test_the_pendulums_planner_ends_where_the_env_does_and_at_the_end_of_the_rail():
    task = resolve_task("InvertedPendulum-v5", "observation", 4, 1)
    #           upright, centred | pole past 0.2 rad | cart past 0.5 m, upright | NaN
    nxt = torch.tensor([[0.0, 0.05, 0, 0], [0.0, -0.25, 0, 0], [-0.55, 0.0, 0, 0], [float("nan"), 0, 0, 0]])
    ends = task.termination(torch.zeros(4, 4), torch.zeros(4, 1), nxt, torch.zeros(4, 0))
    assert ends.tolist() == [False, True, True, True]
    assert task.reward(torch.zeros(4, 4), torch.zeros(4, 1), nxt, torch.zeros(4, 0))[2] == 1  # the env's reward


def test_pusher_v4_scores_the_state_before_the_step():
    """Pusher-v4 needs mujoco<3 (not installed): its reward is v5's, on the observation before the step."""
    data = collect("Pusher-v5", 1)
    s, a, n = tensors(data, torch.float64)
    goal = torch.zeros(len(s), 0)
    np.testing.assert_allclose(rewards.pusher_v4(n, a, s, goal).numpy(), data.rewards, rtol=1e-12)


def test_reacher_layout_keeps_its_rewards_and_builtin_envs_lists_them():
    for env_id in ("Reacher-v5", "Reacher-v4"):
        task = resolve_task(env_id, "reacher", 8, 2, goal_size=2)
        assert task.reward is reward_for(env_id, "reacher") and task.termination_source == "none"
    assert builtin_envs()[:6] == ["Reacher-v5", "Reacher-v4", "Pusher-v5", "Pusher-v4", "InvertedPendulum-v5",
                                  "InvertedPendulum-v4"]
    assert builtin_envs("reacher") == ["Reacher-v5", "Reacher-v4"]
    assert "InvertedDoublePendulum-v5" not in builtin_envs()  # see docs/model-based-rewards.md


def test_user_reward_and_termination_from_the_users_package():
    user_modules._registered.pop(ARM_REWARD, None)  # imported by an earlier test: import (and pass on) again
    data = collect(ARM, 2)
    task = resolve_task(ARM, "observation", 8, 3, reward=f"{ARM_REWARD}:reward",
                        termination=f"{ARM_REWARD}:reached")
    assert (task.reward_source, task.termination_source) == (f"{ARM_REWARD}:reward", f"{ARM_REWARD}:reached")
    assert isinstance(task.reward, UserFunction) and ARM_REWARD in user_modules.imported_names()
    s, a, n = tensors(data, torch.float32)
    goal = torch.zeros(len(s), 0)
    np.testing.assert_allclose(task.reward(s, a, n, goal).numpy(), data.rewards, rtol=1e-5, atol=1e-5)
    near = torch.linalg.vector_norm(n[:, 6:8], dim=-1) < 0.02
    assert torch.equal(task.termination(s, a, n, goal), near)
    # 0/1 floats are a termination too, handed on as bool; auto with a user reward: no termination
    floats = resolve_task(ARM, "observation", 8, 3, reward=f"{ARM_REWARD}:reward",
                          termination=f"{ARM_REWARD}:reached_float")
    assert torch.equal(floats.termination(s, a, n, goal), near)
    assert resolve_task(ARM, "observation", 8, 3, reward=f"{ARM_REWARD}:reward").termination_source == "none"


def test_learned_heads():
    task = resolve_task(ARM, "observation", 8, 3, learned=frozenset({"reward"}))
    assert task == Task(None, None, "learned", "none")
    task = resolve_task(ARM, "observation", 8, 3, learned=frozenset({"reward", "termination"}))
    assert task == Task(None, None, "learned", "learned")
    # a bundled reward comes first; the bundled termination goes with it, a learned one otherwise
    task = resolve_task("InvertedPendulum-v5", "observation", 4, 1, learned=frozenset({"reward", "termination"}))
    assert (task.reward_source, task.termination_source) == ("builtin", "builtin")
    task = resolve_task("InvertedPendulum-v5", "observation", 4, 1, reward="learned",
                        learned=frozenset({"reward", "termination"}))
    assert (task.reward, task.reward_source, task.termination_source) == (None, "learned", "learned")


def one_line_error(fn, *args, **kwargs) -> str:
    with pytest.raises(MotorlabError) as info:
        fn(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message and message.endswith(".")
    return message


def test_an_env_without_a_reward_lists_the_three_ways():
    message = one_line_error(resolve_task, ARM, "observation", 8, 3)
    assert message.startswith(f"no reward to plan with on {ARM}: use --reward builtin (bundled for Reacher-v5, ")
    for fragment in ("InvertedPendulum-v5", "--reward MODULE:FUNCTION (your torch function (obs, action, "
                     "next_obs) -> reward)", "--reward learned (fit the model with --learn-reward)"):
        assert fragment in message
    # reward_for (MPC before learned rewards) says the same
    assert one_line_error(reward_for, ARM, "observation") == message


@pytest.mark.parametrize("kwargs, fragments", [
    (dict(reward="builtin"), ["--reward builtin: no bundled reward for", "bundled for Reacher-v5",
                              "--reward MODULE:FUNCTION", "--reward learned"]),
    (dict(reward="learned"), ["has no reward head", "refit it with --learn-reward"]),
    (dict(reward="buitin"), ["'buitin' (did you mean builtin?)", "MODULE:FUNCTION"]),
    (dict(reward=f"{ARM_REWARD}:reward", termination="builtin"),
     ["no bundled termination", "(bundled for InvertedPendulum-v5, InvertedPendulum-v4); use --termination "
      "MODULE:FUNCTION", "--termination learned", "or --termination none"]),
    (dict(reward=f"{ARM_REWARD}:reward", termination="learned"), ["no termination head", "--learn-termination"]),
    (dict(reward=f"{ARM_REWARD}:reward", termination="never"), ["'never'", "none"]),
])
def test_missing_or_unknown_sources(kwargs, fragments):
    message = one_line_error(resolve_task, ARM, "observation", 8, 3, **kwargs)
    for fragment in fragments:
        assert fragment in message, message


def test_a_builtin_for_another_observation_is_refused():
    """Pusher's bundled reward indexes its 23 observations: a model of 20 (other env options) gets none."""
    message = one_line_error(resolve_task, "Pusher-v5", "observation", 20, 7)
    assert "its bundled reward reads the 23-number observation state, this model's has 20" in message
    assert "--reward builtin" not in message and "--reward learned" in message
    assert resolve_task("Pusher-v5", "observation", 20, 7, learned=frozenset({"reward"})).reward_source == "learned"
    message = one_line_error(resolve_task, "Reacher-v5", "other", 10, 2, reward="builtin")
    assert "with the 'other' state layout (its bundled reward is for the reacher and observation layouts)" in message


@pytest.mark.parametrize("name, what, fragments", [
    ("userpkg.arm_reward", "reward", ["choose auto, builtin, learned or MODULE:FUNCTION"]),
    ("no_such_package_xyz:reward", "reward", ["cannot import module 'no_such_package_xyz'", "PYTHONPATH"]),
    ("userpkg.needs_missing:reward", "reward", ["cannot import module 'userpkg.needs_missing'",
                                                "motorlab_no_such_dependency"]),
    ("userpkg.arm_reward:rewrd", "reward", ["has no 'rewrd' (did you mean reward", "its functions: reward, reached"]),
    ("userpkg.arm_reward:NOT_A_FUNCTION", "reward", ["is of type float, not a function"]),
    ("userpkg.arm_reward:two_arguments", "reward", ["two_arguments(obs, action) cannot be called with the 3 "
                                                    "positional arguments (obs, action, next_obs)"]),
    ("userpkg.arm_reward:keepdim_reward", "reward", ["returned a float32 tensor of shape (2, 3, 1)",
                                                     "expected a float tensor of shape (2, 3)", ".sum(-1)"]),
    ("userpkg.arm_reward:flat_reward", "reward", ["returned a float32 tensor of shape (6,)"]),
    ("userpkg.arm_reward:numpy_reward", "reward", ["returned a numpy.ndarray (float32) of shape (2, 3), not a torch"]),
    ("userpkg.arm_reward:raises", "reward", ["raised IndexError", "probe tensors obs (2, 3, 8), action (2, 3, 3)"]),
    ("userpkg.arm_reward:log_reward", "reward", ["returned non-finite values in a float32 tensor"]),
    ("userpkg.arm_reward:distance_termination", "termination", ["returned values other than 0/1",
                                                                "expected a bool (or 0/1) tensor of shape (2, 3)"]),
    ("userpkg.arm_reward:keepdim_reward", "termination", ["shape (2, 3, 1)", "expected a bool"]),
])
def test_bad_user_functions(name, what, fragments):
    kwargs = dict(reward=name) if what == "reward" else dict(reward=f"{ARM_REWARD}:reward", termination=name)
    message = one_line_error(resolve_task, ARM, "observation", 8, 3, **kwargs)
    assert name in message or "cannot import" in message, message
    for fragment in fragments:
        assert fragment in message, message


def test_load_function_passes_the_module_on():
    assert load_function(f"{ARM_REWARD}:reward").__name__ == "reward"
    user_modules._registered.pop(ARM_REWARD, None)
    load_function(f"{ARM_REWARD}:reached", what="termination")
    assert ARM_REWARD in user_modules.imported_names()
    assert "--termination userpkg.arm_reward: name a function as MODULE:FUNCTION" in one_line_error(
        load_function, ARM_REWARD, what="termination")


def test_the_old_module_name_still_works_and_says_where_it_moved():
    import motorlab.dynamics.rewards as old

    with pytest.warns(DeprecationWarning, match="moved to motorlab.dynamics.planner_rewards.register"):
        assert old.register is rewards.register
    with pytest.raises(AttributeError, match="planner_rewards"):
        old.no_such_name  # noqa: B018
