"""Reacher rollouts straight in MuJoCo, batched and multithreaded (`mujoco.rollout`).

Gymnasium's Reacher steps MuJoCo `frame_skip` times per action (Python-level, ~25k
steps/s); `mujoco.rollout` runs the same substeps in C on all cores, so joint angles and
velocities come out bit-identical to the env's. Only the arm is simulated (`_arm_model`):
the target never moves, so its position is carried over from the initial state. The fingertip position is the planar
two-link forward kinematics of the final joint angles. Gymnasium reads it from
`data.xpos` after `mj_step`, which with Reacher's RK4 integrator holds the kinematics of
RK4's last intermediate stage, not of the final state: the two agree to ~1e-5 m, but
while the elbow presses on its +-3 rad limit they can differ by a few millimetres.
Reproducing that stage would cost a full forward pass per transition in Python; the
forward model is better served by the fingertip of the state it actually reached.
"""

from __future__ import annotations

import copy
import functools
import os

import mujoco
import mujoco.rollout
import numpy as np


def fingertip_xyz(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """Fingertip position (..., 3) for Reacher joint angles qpos[..., :2] (both hinges about z)."""
    base, link1, link2 = (model.body(b).pos for b in ("body0", "body1", "fingertip"))
    a1 = qpos[..., 0]
    a2 = a1 + qpos[..., 1]
    x = base[0] + link1[0] * np.cos(a1) + link2[0] * np.cos(a2)
    y = base[1] + link1[0] * np.sin(a1) + link2[0] * np.sin(a2)
    return np.stack([x, y, np.full_like(x, base[2] + link1[2] + link2[2])], axis=-1)


def target_xyz(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """Target position (..., 3): its two slide joints measure from the world origin (qpos0 = body pos)."""
    z = np.full(qpos.shape[:-1] + (1,), model.body("target").pos[2])
    return np.concatenate([qpos[..., 2:4], z], axis=-1)


def sample_initial_states(env, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Reacher's reset distribution (gymnasium reacher_v5.reset_model), vectorized."""
    u = env.unwrapped
    nq, nv = u.model.nq, u.model.nv
    qpos = rng.uniform(-0.1, 0.1, size=(n, nq)) + u.init_qpos
    goal = rng.uniform(-0.2, 0.2, size=(n, 2))
    bad = np.linalg.norm(goal, axis=1) >= 0.2
    while bad.any():  # rejection sampling inside the disc, as the env does
        goal[bad] = rng.uniform(-0.2, 0.2, size=(int(bad.sum()), 2))
        bad = np.linalg.norm(goal, axis=1) >= 0.2
    qpos[:, -2:] = goal
    qvel = u.init_qvel + rng.uniform(-0.005, 0.005, size=(n, nv))
    qvel[:, -2:] = 0.0
    return qpos, qvel


def _without_collision(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of `model` with collision detection off, when no two geoms can ever touch.

    MuJoCo only pairs geoms whose contype and conaffinity bits meet; in Reacher every
    contype is 0, so collision detection finds nothing, and skipping it changes no number
    (the test checks bit-identity) while saving ~20% of each step.
    """
    can_touch = (model.geom_contype[:, None] & model.geom_conaffinity[None, :]).any() or model.npair > 0
    if can_touch:
        return model
    fast = copy.copy(model)
    fast.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return fast


ARM_BODIES = ("world", "body0", "body1", "fingertip")


@functools.lru_cache(maxsize=4)
def _arm_spec_model(path: str) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(path)
    spec.delete(spec.body("target"))
    for geom in list(spec.worldbody.geoms):  # floor, arena walls, base: drawn, never touched
        spec.delete(geom)
    return spec.compile()


def _same_arm(full: mujoco.MjModel, arm: mujoco.MjModel) -> bool:
    """Whether `arm` has exactly `full`'s arm: bodies, joints, actuators and options."""
    if [arm.body(i).name for i in range(arm.nbody)] != list(ARM_BODIES) or arm.nv != 2 or arm.nu != full.nu:
        return False
    nb, nj = arm.nbody, arm.njnt
    pairs = [(f"body_{k}", nb) for k in ("pos", "quat", "ipos", "iquat", "mass", "inertia")]
    pairs += [(f"dof_{k}", nj) for k in ("armature", "damping", "frictionloss")]
    pairs += [(f"jnt_{k}", nj) for k in ("range", "limited", "stiffness", "solref", "solimp", "margin")]
    pairs += [(f"actuator_{k}", full.nu) for k in ("gear", "ctrlrange", "ctrllimited", "trnid", "gainprm", "biasprm")]
    same = all(np.array_equal(getattr(full, k)[:n], getattr(arm, k)[:n]) for k, n in pairs)
    opts = ("timestep", "integrator", "gravity", "disableflags", "enableflags", "solver", "iterations", "tolerance")
    return same and all(np.array_equal(getattr(full.opt, k), getattr(arm.opt, k)) for k in opts)


def _arm_model(env) -> mujoco.MjModel | None:
    """Reacher's arm alone, for rollouts: the model without the target and the world's geoms.

    The target is a separate kinematic tree on two frictionless, undamped slide joints with
    zero velocity and no force along them, so it never moves and nothing it does reaches
    the arm; the world's geoms are drawn but can never touch. Without them each RK4
    substep runs ~20% fewer instructions (callgrind: 47k vs 58k) and the arm's joint
    angles and velocities come out bit-identical (tests/test_dynamics_collect.py).
    None when the env's model is not the stock layout (a custom XML, edited options):
    the full model is used then.
    """
    full = env.unwrapped.model
    path = getattr(env.unwrapped, "fullpath", None)
    if full.nq != 4 or full.nv != 4 or not path:
        return None
    try:
        arm = _arm_spec_model(str(path))
    except (ValueError, KeyError, TypeError):  # not the stock file's bodies
        return None
    return _without_collision(arm) if _same_arm(full, arm) else None


def rollout_reacher(env, qpos0: np.ndarray, qvel0: np.ndarray, actions: np.ndarray,
                    threads: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Observations (E, T+1, obs_dim) and rewards (E, T) of Gymnasium's Reacher-v4/v5 for
    E episodes from the given initial qpos/qvel under actions (E, T, 2)."""
    u = env.unwrapped
    # the target stays put only when it starts at rest; else simulate it too
    arm = _arm_model(env) if not np.any(qvel0[:, 2:]) else None
    model = arm or _without_collision(u.model)
    k = model.nq  # simulated joints: the arm's two, or all four with the (motionless) target's
    frame_skip = u.frame_skip
    n, steps = actions.shape[:2]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    template = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, mujoco.MjData(model), template, spec)
    # FULLPHYSICS = [time, qpos, qvel, act, ...]
    iq, iv = 1, 1 + k
    init = np.tile(template, (n, 1))
    init[:, iq:iq + k] = qpos0[:, :k]
    init[:, iv:iv + k] = qvel0[:, :k]
    control = np.repeat(actions, frame_skip, axis=1)  # the env holds each action for frame_skip substeps
    datas = [mujoco.MjData(model) for _ in range(threads or os.cpu_count() or 1)]
    state, _ = mujoco.rollout.rollout(model, datas, init, control)
    last = np.arange(1, steps + 1) * frame_skip - 1  # each env step's final substep
    qpos = np.repeat(qpos0[:, None], steps + 1, axis=1)
    qvel = np.repeat(qvel0[:, None], steps + 1, axis=1)
    qpos[:, 1:, :k] = state[:, last, iq:iq + k]
    qvel[:, 1:, :k] = state[:, last, iv:iv + k]
    vec = fingertip_xyz(model, qpos) - target_xyz(u.model, qpos)
    theta = qpos[..., :2]
    v4 = env.observation_space.shape[0] == 11  # v4 keeps the z of the vector, v5 drops it
    width = 3 if v4 else 2
    obs = np.concatenate([np.cos(theta), np.sin(theta), qpos[..., 2:], qvel[..., :2], vec[..., :width]], axis=-1)
    dist = np.linalg.norm(vec, axis=-1)
    ctrl_cost = np.square(actions).sum(-1)
    if v4:
        reward = -dist[:, :-1] - ctrl_cost  # v4 scores the state before the step
    else:
        w_dist = getattr(u, "_reward_dist_weight", 1.0)
        w_ctrl = getattr(u, "_reward_control_weight", 1.0)
        reward = -w_dist * dist[:, 1:] - w_ctrl * ctrl_cost  # v5 scores the state after it
    return obs, reward
