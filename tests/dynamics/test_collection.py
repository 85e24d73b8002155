"""Reacher rollouts (the arm's closed form, MuJoCo's C rollout) vs Gymnasium's env, and the reacher state layout."""

from __future__ import annotations

import copy

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from motorlab.dynamics.layouts import layout_for
from motorlab.dynamics.planar_arm import PlanarArm
from motorlab.dynamics.reacher_sim import arm_models, closed_form_arm, rollout_reacher, sample_initial_states
from motorlab.errors import MotorlabError

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def gym_rollout(env, qpos0, qvel0, actions):
    obs, rewards = [], []
    env.reset(seed=0)
    env.unwrapped.set_state(qpos0, qvel0)
    obs.append(env.unwrapped._get_obs())
    for a in actions:
        o, r, *_ = env.step(a)
        obs.append(o)
        rewards.append(r)
    return np.array(obs), np.array(rewards), env.unwrapped.data.qpos[1]


def limit_pressing_episodes(env, n=12, seed=3):
    """n initial states and actions, a third of them at full torque: the elbow reaches its +-3 rad limit."""
    rng = np.random.default_rng(seed)
    qpos, qvel = sample_initial_states(env, n, rng)
    actions = rng.uniform(-1, 1, size=(n, 50, 2))
    actions[: n // 3] = np.sign(actions[: n // 3])
    return qpos, qvel, actions


@pytest.mark.parametrize("env_id", ["Reacher-v5", "Reacher-v4"])
def test_mujoco_rollout_matches_gymnasium(env_id):
    """MuJoCo's rollout: joints bit for bit, the fingertip (RK4's last stage, see reacher_sim)
    and rewards to rounding, at the elbow's limit too."""
    env = gym.make(env_id)
    qpos, qvel, actions = limit_pressing_episodes(env)
    obs, rewards = rollout_reacher(env, qpos, qvel, actions, threads=2, simulator="mujoco")
    assert obs.shape == (12, 51, env.observation_space.shape[0]) and rewards.shape == (12, 50)
    joint = np.r_[0:8]  # cos, sin, target, joint velocities: from qpos/qvel, bit-identical
    at_limit = 0
    for e in range(12):
        g_obs, g_rew, _ = gym_rollout(env, qpos[e], qvel[e], actions[e])
        np.testing.assert_array_equal(obs[e][:, joint], g_obs[:, joint])
        np.testing.assert_allclose(obs[e][:, 8:], g_obs[:, 8:], rtol=0, atol=1e-12)
        np.testing.assert_allclose(rewards[e], g_rew, rtol=0, atol=1e-12)
        at_limit += int((np.abs(np.arctan2(g_obs[:, 3], g_obs[:, 1])) > 2.9).sum())
    assert at_limit > 20  # the case where the fingertip of the reached state would be mm off


@pytest.mark.parametrize("env_id", ["Reacher-v5", "Reacher-v4"])
def test_closed_form_rollout_matches_gymnasium(env_id):
    """The arm's closed form: Gymnasium's observations and rewards to rounding where MuJoCo's
    solver converges (tolerance 0), and to that solver's own tolerance with the env's default
    (1e-8 on the scaled cost, which MuJoCo stops at while the elbow presses on its limit)."""
    env = gym.make(env_id)
    qpos, qvel, actions = limit_pressing_episodes(env)
    obs, rewards = rollout_reacher(env, qpos, qvel, actions, threads=2)
    assert obs.shape == (12, 51, env.observation_space.shape[0]) and rewards.shape == (12, 50)
    default = [gym_rollout(env, qpos[e], qvel[e], actions[e]) for e in range(12)]
    env.unwrapped.model.opt.tolerance = 0.0  # MuJoCo's Newton solver iterates to convergence
    converged = [gym_rollout(env, qpos[e], qvel[e], actions[e]) for e in range(12)]
    loose = 0.0
    for e in range(12):
        np.testing.assert_allclose(obs[e], converged[e][0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(rewards[e], converged[e][1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(obs[e], default[e][0], rtol=0, atol=1e-5)
        np.testing.assert_allclose(rewards[e], default[e][1], rtol=0, atol=1e-5)
        loose = max(loose, np.abs(obs[e] - default[e][0]).max())
    at_limit = sum(int((np.abs(np.arctan2(g[0][:, 3], g[0][:, 1])) > 2.9).sum()) for g in converged)
    assert at_limit > 20 and loose > 1e-12  # the solver's tolerance shows where the elbow meets its limit


def test_closed_form_equals_mujoco_forward_dynamics():
    """The closed form's accelerations are MuJoCo's (mj_forward) at random states, past the limit
    too; a model it cannot reproduce (gravity in the arm's plane) gets None, and rollouts fall back
    to MuJoCo's."""
    env = gym.make("Reacher-v5")
    arm = closed_form_arm(env)
    assert arm is not None and arm.limit is not None and arm.limit.dof == 1
    model = arm_models(env)[0]
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    q = rng.uniform(-3.3, 3.3, size=(400, 2))
    v, u = rng.normal(0, 20, size=(400, 2)), rng.uniform(-1.5, 1.5, size=(400, 2))
    want = np.empty((400, 2))
    for i in range(400):
        data.qpos[:], data.qvel[:], data.ctrl[:] = q[i], v[i], u[i]
        mujoco.mj_forward(model, data)
        want[i] = data.qacc
    got = np.stack(arm.qacc(q[:, 0], q[:, 1], v[:, 0], v[:, 1], *arm.actuator_torque(u)), axis=1)
    assert (np.abs(q[:, 1]) > 3).sum() > 10
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)

    tilted = copy.copy(model)
    tilted.opt.gravity[:] = (0.0, -9.81, 0.0)  # now gravity pulls the links round their hinges
    assert PlanarArm.from_model(tilted) is None
    both_limited = copy.copy(model)
    both_limited.jnt_limited[0] = 1  # two soft limits at once: a coupled problem the closed form leaves to MuJoCo
    assert PlanarArm.from_model(both_limited) is None and PlanarArm.from_model(model) == arm


def test_rollouts_simulate_the_arm_alone_for_stock_and_user_xml(tmp_path):
    """Reacher is rolled out without its target body and world geoms, for the stock XML and a
    user's; a model edited at run time, or a moving target, is refused with the way out."""
    rng = np.random.default_rng(7)
    heavy = tmp_path / "heavy.xml"  # a user's XML: a denser forearm
    stock = gym.make("Reacher-v5").unwrapped.fullpath
    heavy.write_text(open(stock).read().replace('name="link1" rgba', 'name="link1" density="3000" rgba'))
    env = gym.make("Reacher-v5", xml_file=str(heavy))
    rollout, stage = arm_models(env)
    assert rollout.nq == 2 and rollout.ngeom == 3 and stage.nq == 2
    qpos, qvel = sample_initial_states(env, 6, rng)
    actions = rng.uniform(-1, 1, size=(6, 50, 2))
    heavy_obs, heavy_rew = rollout_reacher(env, qpos, qvel, actions, simulator="mujoco")
    closed_obs, closed_rew = rollout_reacher(env, qpos, qvel, actions)  # the closed form of the user's arm
    for e in range(6):
        g_obs, g_rew, _ = gym_rollout(env, qpos[e], qvel[e], actions[e])
        np.testing.assert_array_equal(heavy_obs[e][:, :8], g_obs[:, :8])
        np.testing.assert_allclose(heavy_rew[e], g_rew, rtol=0, atol=1e-12)
        np.testing.assert_allclose(closed_obs[e], g_obs, rtol=0, atol=1e-5)
        np.testing.assert_allclose(closed_rew[e], g_rew, rtol=0, atol=1e-5)
    stock_obs = rollout_reacher(gym.make("Reacher-v5"), qpos, qvel, actions)[0]
    assert not np.array_equal(heavy_obs, stock_obs)  # the user's arm is the one simulated

    renamed = tmp_path / "renamed.xml"  # a user's arm with other body names
    renamed.write_text(open(stock).read().replace('"body1"', '"forearm"'))
    with pytest.raises(MotorlabError, match="--simulator gymnasium"):
        rollout_reacher(gym.make("Reacher-v5", xml_file=str(renamed)), qpos, qvel, actions)
    for edit in (lambda m: setattr(m.opt, "timestep", 0.005), lambda m: m.body_mass.__setitem__(2, 1.0),
                 lambda m: m.dof_damping.__setitem__(1, 0.0)):
        edited = gym.make("Reacher-v5")
        edit(edited.unwrapped.model)
        with pytest.raises(MotorlabError, match="--simulator gymnasium"):
            rollout_reacher(edited, qpos, qvel, actions)
    qvel[:, 2:] = 0.01  # the env's reset never moves the target
    with pytest.raises(MotorlabError, match="target starts at rest"):
        rollout_reacher(env, qpos, qvel, actions)


def test_initial_states_follow_the_env_reset():
    env = gym.make("Reacher-v5")
    qpos, qvel = sample_initial_states(env, 5000, np.random.default_rng(0))
    goal = qpos[:, 2:]
    assert (np.linalg.norm(goal, axis=1) < 0.2).all() and np.abs(goal).max() > 0.18
    assert np.abs(qpos[:, :2]).max() <= 0.1 and (qvel[:, 2:] == 0).all() and np.abs(qvel).max() <= 0.005
    g = np.array([env.reset(seed=s)[0][4:6] for s in range(300)])
    assert abs(np.linalg.norm(g, axis=1).mean() - np.linalg.norm(goal, axis=1).mean()) < 0.01


def test_reacher_layout():
    env = gym.make("Reacher-v5")
    obs, _ = env.reset(seed=1)
    layout = layout_for("Reacher-v5", 10)
    state = layout.state(obs[None])[0]
    assert layout.size == 8 and state.shape == (8,)
    np.testing.assert_allclose(state[6:], env.unwrapped.get_body_com("fingertip")[:2], atol=1e-12)
    np.testing.assert_array_equal(layout.goal(obs), obs[4:6])
    assert layout_for("Pendulum-v1", 3).size == 3 and layout_for("Pendulum-v1", 3).goal(np.zeros(3)).shape == (0,)
    with pytest.raises(MotorlabError, match="--state observation"):
        layout_for("Pendulum-v1", 3, "reacher")
