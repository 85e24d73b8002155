"""benchmarks/bodies.py: generated arms are valid MuJoCo models, the same for the same seed, within the
generator's declared ranges, step without NaN, carry a torch reward equal to the env's, and pose a task
random actions cannot solve and the oracle (MPC on the true simulator) can."""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import bodies  # noqa: E402  (benchmarks/ is a folder of scripts, not a package)

SEEDS = st.integers(0, 999)
FEW = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
REL = 1e-4  # the spec stores 5 significant digits of each derived number


def within(value: float, bounds: tuple[float, float], rel: float = 0.0) -> bool:
    lo, hi = bounds
    return lo * (1 - rel) <= value <= hi * (1 + rel)


@FEW
@given(seed=SEEDS, muscles=st.booleans())
def test_the_xml_compiles_into_the_body_the_spec_describes(seed, muscles):
    spec = bodies.generate(seed, muscles)
    model = mujoco.MjModel.from_xml_string(bodies.mjcf(spec))
    n = spec.n_links
    assert 2 <= n <= 4 and model.njnt == n and model.nv == n
    assert model.nu == (2 * n if muscles else n) and model.na == (2 * n if muscles else 0)
    assert np.allclose(model.body_mass[1:n + 1], spec.masses) and np.allclose(model.dof_damping, spec.damping)
    assert np.allclose(model.opt.gravity, [0, -bodies.GRAVITY, 0] if spec.vertical else [0, 0, 0])
    assert model.opt.timestep * spec.frame_skip == pytest.approx(bodies.CONTROL_DT)
    if muscles:  # an antagonist pair per joint: moment arms +r and -r, excitations in [0, 1]
        assert np.allclose(model.actuator_ctrlrange, [0, 1])
        assert np.allclose(model.actuator_gainprm[:, 2], np.repeat(spec.muscle_forces, 2))  # peak force
        assert np.all(model.jnt_limited == 1)
    else:
        assert np.allclose(model.actuator_gear[:, 0], spec.torques) and np.allclose(model.actuator_ctrlrange, [-1, 1])


@FEW
@given(seed=SEEDS, muscles=st.booleans())
def test_parameters_lie_in_their_declared_ranges(seed, muscles):
    spec, r = bodies.generate(seed, muscles), bodies.RANGES
    assert all(within(x, r.length) for x in spec.lengths) and all(within(x, r.mass) for x in spec.masses)
    inertia = bodies.joint_inertias(spec.lengths, spec.masses)
    hold = bodies.gravity_torques(spec.lengths, spec.masses)
    for torque, i, g, damping in zip(spec.torques, inertia, hold, spec.damping):
        assert within(i / damping, r.damping_time, REL)
        assert torque / i >= r.accel[0] * (1 - REL)  # every joint accelerates its arm at least this much
        if spec.vertical:  # ... and holds what lies beyond it against gravity
            assert torque / g >= r.strength[0] * (1 - REL)
            assert torque <= max(r.accel[1] * i, r.strength[1] * g) * (1 + REL)
        else:
            assert torque / i <= r.accel[1] * (1 + REL)
    assert all(within(x, r.moment_arm) for x in spec.moment_arms) and len(spec.moment_arms) == (spec.n_links if muscles
                                                                                               else 0)


@FEW
@given(seed=SEEDS, other=SEEDS, muscles=st.booleans())
def test_the_same_seed_gives_the_same_body_and_another_seed_another(seed, other, muscles):
    assert bodies.mjcf(bodies.generate(seed, muscles)) == bodies.mjcf(bodies.generate(seed, muscles))
    if other != seed:
        assert bodies.generate(seed, muscles).lengths != bodies.generate(other, muscles).lengths
    # the muscle variant is the same arm with other actuators
    plain, strung = bodies.generate(seed, False), bodies.generate(seed, True)
    assert (plain.lengths, plain.masses, plain.torques, plain.damping) == (strung.lengths, strung.masses,
                                                                           strung.torques, strung.damping)


def test_the_ids_are_registered_for_every_seed_and_vertical_and_horizontal_arms_both_occur():
    assert all(bodies.env_id(s, m) in gym.registry for s in (0, 517, 999) for m in (False, True))
    vertical = [bodies.generate(s).vertical for s in range(100)]
    assert 30 <= sum(vertical) <= 70
    assert {bodies.generate(s).n_links for s in range(100)} == {2, 3, 4}


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=SEEDS, muscles=st.booleans(), reset=st.integers(0, 2**31 - 1))
def test_random_actions_step_without_nan_and_the_torch_reward_is_the_envs(seed, muscles, reset):
    env = gym.make(bodies.env_id(seed, muscles))
    spec = env.unwrapped.body
    obs, _ = env.reset(seed=reset)
    env.action_space.seed(reset)
    target = env.unwrapped.data.mocap_pos[0, :2].copy()
    assert bodies.TARGET_MIN_REACH * spec.reach * (1 - 1e-9) <= np.hypot(*target) <= spec.reach  # reachable
    rows = []
    for _ in range(40):
        action = env.action_space.sample()
        nxt, r, terminated, truncated, _ = env.step(action)
        assert np.isfinite(nxt).all() and np.isfinite(r) and not terminated
        rows.append((obs, np.asarray(action, np.float64), nxt, r))
        obs = nxt
    tip = env.unwrapped.data.site("tip").xpos[:2]
    assert np.allclose(obs[-2:], tip - target) and np.allclose(tip, bodies.tip_position(spec, env.unwrapped.data.qpos))
    o, a, n, r = (np.array(x, dtype=np.float64) for x in zip(*rows))
    batched = bodies.reward(torch.as_tensor(o), torch.as_tensor(a), torch.as_tensor(n)).numpy()
    grid = bodies.reward(*(torch.as_tensor(x).reshape(4, 10, -1) for x in (o, a, n))).reshape(-1).numpy()
    assert np.array_equal(batched, r) and np.array_equal(grid, r) and np.array_equal(bodies.reward_np(o, a, n), r)
    fresh = gym.make(bodies.env_id(seed, muscles))
    assert np.array_equal(fresh.reset(seed=reset)[0], rows[0][0])  # a reset seed fixes the start and the target
    fresh.close()
    env.close()


def _random_distances(env_id: str, reset: int) -> np.ndarray:
    """The tip's distance to the target after every step of random actions (the space seeded by the reset)."""
    env = gym.make(env_id)
    env.reset(seed=reset)
    env.action_space.seed(reset)
    out = [np.hypot(*env.step(env.action_space.sample())[0][-2:]) for _ in range(bodies.EPISODE_STEPS)]
    env.close()
    return np.array(out)


def _oracle_distances(env_id: str, reset: int) -> np.ndarray:
    """The same for the oracle, as motorlab.planning.oracle.oracle_episodes plays it (CEM on the true
    simulator), on a small budget (horizon 10, population 50, 2 iterations), the distances recorded."""
    from motorlab.planning.oracle import SimulatorScorer, physics_state
    from motorlab.planning.planners.cem import CEMPlanner

    env, scorer = gym.make(env_id), SimulatorScorer(env_id)
    planner = CEMPlanner(scorer, env.action_space.low, env.action_space.high, horizon=10, population=50,
                         iterations=2, elites=5, seed=0)
    env.reset(seed=reset)
    scorer.reset(reset)
    planner.reset(1)
    out = []
    for _ in range(bodies.EPISODE_STEPS):
        action = planner.plan(torch.from_numpy(physics_state(env))[None], torch.zeros((1, 0)))[0].numpy()
        out.append(np.hypot(*env.step(action)[0][-2:]))
    env.close()
    scorer.close()
    return np.array(out)


@pytest.mark.parametrize("seed,muscles,reset", [(5, False, 31), (6, True, 32)])
def test_random_actions_cannot_solve_a_body_and_the_oracle_can(seed, muscles, reset):
    torch.set_num_threads(1)
    env_id = f"bodies:{bodies.env_id(seed, muscles)}"
    reach = bodies.generate(seed, muscles).reach
    oracle, random = _oracle_distances(env_id, reset), _random_distances(env_id, reset)
    # the oracle ends at the target and holds it (the last 20 steps, 0.4 s); random actions end far from it
    assert oracle[-20:].max() < 0.05 * reach, oracle[-20:]
    assert random[-20:].min() > 0.25 * reach, random[-20:]
    # and over the whole episode (the return is minus the summed distance, and a small effort cost)
    assert random.mean() > 3 * oracle.mean(), (random.mean(), oracle.mean())
