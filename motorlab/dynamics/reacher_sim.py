"""Reacher rollouts in batches: the arm's closed-form dynamics in NumPy, or `mujoco.rollout`.

Gymnasium's Reacher steps MuJoCo `frame_skip` times per action in Python. Two faster ways
give Gymnasium's observations and rewards for the same initial states and actions:

- `simulator="closed-form"` (the default): the arm's equations of motion, taken from the
  compiled model and checked against MuJoCo (`planar_arm.PlanarArm`), integrated with
  MuJoCo's RK4 over all episodes at once in NumPy, ~1.5M transitions/s per core. It solves
  the elbow's soft limit exactly, where MuJoCo's Newton solver stops at its tolerance
  (1e-8 on the scaled cost): the two agree to ~1e-14 away from the limit and to MuJoCo's
  convergence (a few 1e-7 rad/s) while the elbow presses on it; with MuJoCo's tolerance set
  to 0 they agree to ~1e-14 everywhere (tests/dynamics/test_collection.py). Its RK4 stages give
  Gymnasium's fingertip (below) directly.
- `simulator="mujoco"`: MuJoCo's own C step through `mujoco.rollout` on all cores, bit for
  bit Gymnasium's joint angles and velocities, ~90k transitions/s per core.

The MuJoCo rollout is set up so:

- Only the arm is simulated. The target is a separate body on undamped slide joints that
  starts at rest and is never pushed, so it never moves, and the world's geoms are only
  drawn; without them each RK4 substep runs ~20% fewer instructions (callgrind: 47k vs
  58k), and the joint angles and velocities come out bit-identical to the env's.
- The fingertip is the one Gymnasium reports. It reads `data.xpos` after `mj_step`, which
  with RK4 holds the kinematics of RK4's last intermediate stage, q0 + h*v2 with
  v2 = v0 + h/2*a1, not of the state reached (the two differ by millimetres while the
  elbow presses on its limit). Its observation and its reward both use it. The rollout
  records each substep's joint accelerations (two angular-acceleration sensors, evaluated
  at the substep's start), rebuilds RK4's first stage of each env step's last substep,
  evaluates its acceleration a1 with one more batched forward pass (a one-step rollout
  from that stage, read through the same sensors) and takes the fingertip of the last
  stage: equal to Gymnasium's to ~1e-16 m. This costs about one forward pass per env step
  on top of the eight that RK4 makes over the two substeps.
"""

from __future__ import annotations

import copy
import functools
import os

import mujoco
import mujoco.rollout
import numpy as np

from motorlab.dynamics.planar_arm import PlanarArm
from motorlab.errors import MotorlabError

ARM_BODIES = ("world", "body0", "body1", "fingertip")
_FULLPHYSICS = mujoco.mjtState.mjSTATE_FULLPHYSICS  # = [time, qpos, qvel, act, ...]


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


@functools.lru_cache(maxsize=4)
def _arm_models(path: str) -> tuple[mujoco.MjModel, mujoco.MjModel, mujoco.MjModel] | None:
    """From Reacher's XML: the arm as compiled, the arm for rollouts (with joint-acceleration
    sensors, collision off) and the same for evaluating one RK4 stage (Euler: one forward pass
    per step, without Euler's implicit damping, which would change nothing the sensors read)."""
    spec = mujoco.MjSpec.from_file(path)
    target = spec.body("target")
    if target is None:
        return None
    spec.delete(target)
    for geom in list(spec.worldbody.geoms):  # floor, arena walls, base: drawn, never touched
        spec.delete(geom)
    arm = spec.compile()
    for body in ARM_BODIES[1:3]:  # world-frame angular acceleration of each link: z gives the joints' qacc
        spec.add_sensor(type=mujoco.mjtSensor.mjSENS_FRAMEANGACC, objtype=mujoco.mjtObj.mjOBJ_BODY, objname=body)
    rollout = _without_collision(spec.compile())
    stage = copy.copy(rollout)
    stage.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    stage.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    return arm, rollout, stage


@functools.lru_cache(maxsize=4)
def _closed_form(path: str) -> PlanarArm | None:
    return PlanarArm.from_model(_arm_models(path)[0])


def closed_form_arm(env) -> PlanarArm | None:
    """The closed-form arm of a Reacher env, or None where it does not reproduce MuJoCo's dynamics.

    Raises:
        MotorlabError: as `arm_models`.
    """
    arm_models(env)
    return _closed_form(str(env.unwrapped.fullpath))


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


def arm_models(env) -> tuple[mujoco.MjModel, mujoco.MjModel]:
    """Reacher's arm alone, with joint-acceleration sensors: the model for rollouts and the one
    for evaluating an RK4 stage.

    Raises:
        MotorlabError: the env's model is not Reacher's layout (its XML lacks the target or the
            arm's bodies), or differs from its XML (edited after loading).
    """
    u = env.unwrapped
    path = getattr(u, "fullpath", None)
    try:
        models = _arm_models(str(path)) if path and u.model.nq == 4 else None
    except (ValueError, KeyError, TypeError):  # the XML lacks the arm's bodies
        models = None
    if models is None or not _same_arm(u.model, models[0]):
        raise MotorlabError("this Reacher model is not Reacher's arm as its XML file compiles it (bodies body0, "
                            "body1, fingertip and target; joints, actuators or options edited after loading); "
                            "collect it with --simulator gymnasium.")
    return models[1], models[2]


def _states(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """Full-physics initial states (N, nstate) with the given joint positions and velocities."""
    template = np.empty(mujoco.mj_stateSize(model, _FULLPHYSICS))
    mujoco.mj_getState(model, mujoco.MjData(model), template, _FULLPHYSICS)
    states = np.tile(template, (len(qpos), 1))
    states[:, 1:1 + model.nq] = qpos
    states[:, 1 + model.nq:1 + model.nq + model.nv] = qvel
    return states


def _joint_acc(sensors: np.ndarray) -> np.ndarray:
    """Joint accelerations (..., 2) from the two links' world angular accelerations (..., 6)."""
    return np.stack([sensors[..., 2], sensors[..., 5] - sensors[..., 2]], axis=-1)


def rollout_reacher(env, qpos0: np.ndarray, qvel0: np.ndarray, actions: np.ndarray,
                    threads: int | None = None, simulator: str = "closed-form") -> tuple[np.ndarray, np.ndarray]:
    """Observations (E, T+1, obs_dim) and rewards (E, T) of Gymnasium's Reacher-v4/v5 for
    E episodes from the given initial qpos/qvel under actions (E, T, 2).

    Args:
        threads: MuJoCo rollout threads (default: all cores); the closed form runs in one.
        simulator: "closed-form" (where it reproduces the model; else MuJoCo) or "mujoco".

    Raises:
        MotorlabError: a target with a velocity (the env's reset sets it to zero), or a model
            that is not Reacher's layout (see `arm_models`).
    """
    u = env.unwrapped
    if np.any(qvel0[:, 2:]):
        raise MotorlabError("Reacher's target starts at rest (the env's reset sets its velocity to 0); "
                            "rollouts simulate the arm alone.")
    model, stage = arm_models(env)
    frame_skip, steps = u.frame_skip, actions.shape[1]
    threads = threads or os.cpu_count() or 1
    qpos = np.repeat(qpos0[:, None], steps + 1, axis=1)  # the target's entries stay as they began
    qvel = np.repeat(qvel0[:, None], steps + 1, axis=1)
    arm = closed_form_arm(env) if simulator == "closed-form" else None
    if arm is not None:
        # one thread: NumPy's short array operations gain nothing from a second (measured slower)
        q, v, last_stage = arm.rollout(qpos0[:, :2], qvel0[:, :2], actions, frame_skip)
        qpos[:, 1:, :2], qvel[:, 1:, :2] = q[:, 1:], v[:, 1:]
        tip = np.concatenate([fingertip_xyz(model, qpos0[:, None]), fingertip_xyz(model, last_stage)], axis=1)
    else:
        tip = _mujoco_rollout(model, stage, qpos0, qvel0, actions, frame_skip, threads, qpos, qvel)
    return _observe(env, qpos, qvel, tip, actions)


def _mujoco_rollout(model, stage, qpos0, qvel0, actions, frame_skip, threads, qpos, qvel) -> np.ndarray:
    """mujoco.rollout of the arm: fills qpos/qvel (E, T+1, 4) in place, returns Gymnasium's fingertip (E, T+1, 3)."""
    h = model.opt.timestep
    n, steps = actions.shape[:2]
    datas = [mujoco.MjData(model) for _ in range(threads)]
    control = np.repeat(actions, frame_skip, axis=1)  # the env holds each action for frame_skip substeps
    state, accel = mujoco.rollout.rollout(model, datas, _states(model, qpos0[:, :2], qvel0[:, :2]), control)
    # joint angles and velocities at the start of every substep, and after the last
    q = np.concatenate([qpos0[:, None, :2], state[..., 1:3]], axis=1)
    v = np.concatenate([qvel0[:, None, :2], state[..., 3:5]], axis=1)
    ends = np.arange(1, steps + 1) * frame_skip  # each env step's end; its last substep starts at ends - 1
    qpos[:, 1:, :2], qvel[:, 1:, :2] = q[:, ends], v[:, ends]

    # Gymnasium's fingertip: RK4's last stage of each step's last substep, computed as MuJoCo's
    # mj_RungeKutta does (stage 1 at X0 + h/2 F0, stage 2 at X0 + h/2 F1, stage 3 at X0 + h F2)
    q0, v0, a0 = q[:, ends - 1], v[:, ends - 1], _joint_acc(accel[:, ends - 1])
    q1, v1 = q0 + (0.5 * v0) * h, v0 + (0.5 * a0) * h
    _, accel1 = mujoco.rollout.rollout(stage, [mujoco.MjData(stage) for _ in datas],
                                       _states(stage, q1.reshape(-1, 2), v1.reshape(-1, 2)),
                                       actions.reshape(-1, 1, actions.shape[-1]))
    v2 = v0 + (0.5 * _joint_acc(accel1[:, 0]).reshape(n, steps, 2)) * h
    return np.concatenate([fingertip_xyz(model, qpos0[:, None]), fingertip_xyz(model, q0 + v2 * h)], axis=1)


def _observe(env, qpos: np.ndarray, qvel: np.ndarray, tip: np.ndarray, actions: np.ndarray):
    """Gymnasium's observations and rewards from joint states (E, T+1, 4) and fingertips (E, T+1, 3)."""
    u = env.unwrapped
    vec = tip - target_xyz(u.model, qpos)
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
