"""Generated bodies: planar arms no one tuned motorlab's defaults on, for benchmarks/mbrl_bodies.py.

`generate(seed, muscles)` draws a `BodySpec` with numpy's default_rng(seed); `mjcf(spec)` writes its
MuJoCo XML; `GeneratedArm` is the Gymnasium env (a MujocoEnv loading that XML from a temp file,
`xml_file`). Importing this module registers, for every seed 0-999 (metadata only: the model is built when the env is made),

    GeneratedArm-s{seed}-v0         motors, one per joint, actions in [-1, 1] (x gear = torque, N m)
    GeneratedMuscleArm-s{seed}-v0   MuJoCo muscles, an antagonist pair per joint, actions in [0, 1]

usable as "bodies:GeneratedArm-s17-v0" on motorlab's command line (benchmarks/ on sys.path or
PYTHONPATH), with the torch reward "bodies:reward" (the env's own reward exactly, for every body).

The body (all draws from default_rng(seed), in a fixed order; see RANGES):
- 2-4 links (capsules, no contacts), each with its length and mass; hinge joints about z.
- The plane: half the bodies are horizontal (no gravity), half vertical (gravity -9.81 along -y, in
  the arm's plane): a researcher's bodies vary. Every arm starts hanging along -y (joint angles 0,
  +-0.1 rad of noise, at rest): for a vertical arm that is where gravity holds it.
- Each joint's peak torque is drawn as an acceleration: torque = accel x the inertia the joint moves
  (the arm straight), so a light arm gets a weak motor and a heavy one a strong motor, and every arm
  turns 1 rad in ~0.2-0.4 s from rest. A vertical arm's joints get at least `strength` x the gravity
  torque they hold with the arm horizontal, so each can lift and hold what lies beyond it.
- Each joint's damping is drawn as a time constant: damping = inertia / tau (s).
- Muscles: each joint has a flexor and an extensor, MuJoCo <muscle> actuators on fixed tendons with
  moment arm +r and -r; joints are limited (shoulder +-2.8 rad, others +-2.5) so the tendons' lengths
  have a range (given as the actuators' lengthrange). A muscle's peak force is 1.5 x torque / r: its
  active force falls to half at the short end of its range (MuJoCo's force-length curve), so the joint
  keeps at least ~0.75 x the motor arm's torque everywhere (isometric). Activation dynamics: MuJoCo's
  default time constants (10 ms up, 40 ms down), integrated with a 5 ms step: activation's fastest time
  constant (10 ms x 0.5, at zero activation) is 5 ms, which a 10 ms Euler step would overshoot.
  Action = the muscles' excitations in [0, 1] (MuJoCo's ctrl, unscaled: zero is a relaxed arm, and
  the action cost is effort, co-contraction included), ordered joint by joint, flexor then extensor.

The task: reach a target drawn at every reset from the env's np_random (so a reset seed fixes it):
the tip of the arm at random joint angles (shoulder +-2.8 rad, others +-2.5: inside every arm's
reach, the muscle arms' limits included), redrawn while it lies within 0.25 x the arm's length of
the shoulder (kept after 100 draws). A mocap body holds it, so MuJoCo's state carries it (the oracle
copies it).

Observation: cos and sin of the joint angles, the joint speeds, (muscles: the muscles' activations,
MuJoCo's act, the state the excitations drive), then tip - target (x, y) as the LAST TWO entries, so
one reward serves every body. The tip is computed after the step (mj_kinematics: mj_step leaves body
positions one substep behind the joints), so the observation is a function of the state.
Reward: -|tip - target| - 0.01 |action|^2 (`reward`, torch, batched; `reward_np`, numpy; equal to the
last bit). 100 control steps of 0.02 s (2 s: a reach takes ~0.5 s, the rest is holding); never terminates.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import torch
from gymnasium.envs.mujoco import MujocoEnv

SEEDS = range(1000)  # the generator seeds registered as env ids
EPISODE_STEPS = 100
CONTROL_DT = 0.02
ACTION_COST = 0.01
GRAVITY = 9.81
REST_NOISE = 0.1  # rad: the initial joint angles' uniform noise around 0 (hanging)
SHOULDER_LIMIT, JOINT_LIMIT = 2.8, 2.5  # rad: muscle arms' joint ranges, and the targets' joint angles
TARGET_MIN_REACH = 0.25  # x the arm's length: a target nearer the shoulder is redrawn
MUSCLE_FORCE_MARGIN = 1.5  # a muscle's peak force over torque / r: force-length halves it at the short end


@dataclass(frozen=True)
class Ranges:
    """What the generator draws from (uniform, inclusive bounds), and the share of vertical arms."""

    links: tuple[int, int] = (2, 4)
    length: tuple[float, float] = (0.12, 0.30)  # m, each link
    mass: tuple[float, float] = (0.1, 1.0)  # kg, each link
    accel: tuple[float, float] = (15.0, 60.0)  # rad/s^2: a joint's peak torque / the inertia it moves
    strength: tuple[float, float] = (1.5, 3.0)  # vertical arms: a joint's peak torque / the gravity torque it holds
    damping_time: tuple[float, float] = (0.2, 1.0)  # s: a joint's inertia / its damping
    moment_arm: tuple[float, float] = (0.015, 0.04)  # m, muscles
    vertical_share: float = 0.5


RANGES = Ranges()


@dataclass(frozen=True)
class BodySpec:
    """One generated arm. Per-joint tuples are ordered shoulder first; joint k moves links k.."""

    seed: int
    muscles: bool
    vertical: bool  # gravity in the arm's plane (else a horizontal arm, no gravity)
    lengths: tuple[float, ...]  # m
    masses: tuple[float, ...]  # kg
    torques: tuple[float, ...]  # N m: a motor's gear (torque at action 1); a muscle pair's peak torque
    damping: tuple[float, ...]  # N m s / rad
    moment_arms: tuple[float, ...] = ()  # m, muscles only

    @property
    def n_links(self) -> int:
        return len(self.lengths)

    @property
    def reach(self) -> float:
        return sum(self.lengths)

    @property
    def timestep(self) -> float:
        """MuJoCo's step: 5 ms for muscles (their activation's fastest time constant), else 10 ms."""
        return 0.005 if self.muscles else 0.01

    @property
    def frame_skip(self) -> int:
        return round(CONTROL_DT / self.timestep)

    @property
    def muscle_forces(self) -> tuple[float, ...]:
        """N: each joint's muscles' peak isometric force."""
        return tuple(_sig(MUSCLE_FORCE_MARGIN * t / r) for t, r in zip(self.torques, self.moment_arms))

    @property
    def env_id(self) -> str:
        return env_id(self.seed, self.muscles)


def env_id(seed: int, muscles: bool = False) -> str:
    return f"{'GeneratedMuscleArm' if muscles else 'GeneratedArm'}-s{seed}-v0"


def _sig(x: float) -> float:
    """x to 5 significant digits: what the spec stores, and the XML writes exactly."""
    return float(f"{x:.5g}")


def joint_inertias(lengths: tuple[float, ...], masses: tuple[float, ...]) -> list[float]:
    """kg m^2: what each joint turns with the arm straight (links as rods, point masses along them)."""
    out = []
    for k in range(len(lengths)):
        total, base = 0.0, 0.0
        for length, mass in zip(lengths[k:], masses[k:]):
            total += mass * ((base + length / 2) ** 2 + length**2 / 12)
            base += length
        out.append(total)
    return out


def gravity_torques(lengths: tuple[float, ...], masses: tuple[float, ...]) -> list[float]:
    """N m: the gravity torque each joint holds with the arm straight and horizontal."""
    out = []
    for k in range(len(lengths)):
        total, base = 0.0, 0.0
        for length, mass in zip(lengths[k:], masses[k:]):
            total += mass * GRAVITY * (base + length / 2)
            base += length
        out.append(total)
    return out


def generate(seed: int, muscles: bool = False) -> BodySpec:
    """The body of generator seed `seed` (the same seed gives the same body; `muscles` changes only its
    actuators, and draws moment arms after everything else)."""
    rng = np.random.default_rng(seed)
    r = RANGES
    n = int(rng.integers(r.links[0], r.links[1] + 1))
    vertical = bool(rng.random() < r.vertical_share)
    lengths = tuple(_sig(x) for x in rng.uniform(*r.length, n))
    masses = tuple(_sig(x) for x in rng.uniform(*r.mass, n))
    accel, strength, tau = rng.uniform(*r.accel, n), rng.uniform(*r.strength, n), rng.uniform(*r.damping_time, n)
    inertia, hold = joint_inertias(lengths, masses), gravity_torques(lengths, masses)
    torques = tuple(_sig(max(a * i, s * g if vertical else 0.0)) for a, s, i, g in zip(accel, strength, inertia, hold))
    damping = tuple(_sig(i / t) for i, t in zip(inertia, tau))
    arms = tuple(_sig(x) for x in rng.uniform(*r.moment_arm, n)) if muscles else ()
    return BodySpec(seed, muscles, vertical, lengths, masses, torques, damping, arms)


def joint_limits(spec: BodySpec) -> list[float]:
    """rad: each joint's +- limit (the muscle arms'; the targets' joint angles are drawn within them)."""
    return [SHOULDER_LIMIT] + [JOINT_LIMIT] * (spec.n_links - 1)


# ---------------------------------------------------------------------------------------- MJCF


def mjcf(spec: BodySpec) -> str:
    """The body's MuJoCo XML."""
    gravity = f"0 {-GRAVITY} 0" if spec.vertical else "0 0 0"
    limits = joint_limits(spec)
    # the shoulder's frame turned -90 degrees: joint angles 0 hang the arm along -y
    bodies, close = [], []
    for k, (length, mass, damp) in enumerate(zip(spec.lengths, spec.masses, spec.damping)):
        pos = "0 0 0" if k == 0 else f"{spec.lengths[k - 1]!r} 0 0"
        turn = f' euler="0 0 {-math.pi / 2!r}"' if k == 0 else ""
        limit = f' range="{-limits[k]!r} {limits[k]!r}"' if spec.muscles else ""
        indent = "  " * (k + 2)
        bodies.append(f'{indent}<body name="link{k}" pos="{pos}"{turn}>\n'
                      f'{indent}  <joint name="j{k}" damping="{damp!r}"{limit}/>\n'
                      f'{indent}  <geom fromto="0 0 0 {length!r} 0 0" mass="{mass!r}"/>')
        close.append(f"{indent}</body>")
    tip = "  " * (spec.n_links + 1) + f'  <site name="tip" pos="{spec.lengths[-1]!r} 0 0" size="0.01"/>'
    chain = "\n".join(bodies + [tip] + close[::-1])
    return f"""<mujoco model="{spec.env_id}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{spec.timestep!r}" gravity="{gravity}"/>
  <default>
    <joint type="hinge" axis="0 0 1"/>
    <geom type="capsule" size="0.015" rgba="0.3 0.5 0.8 1" contype="0" conaffinity="0"/>
  </default>
  <worldbody>
    <light pos="0 0 3"/>
{chain}
    <body name="target" mocap="true" pos="0 0 0">
      <site name="target" size="0.02" rgba="0.9 0.2 0.2 1"/>
    </body>
  </worldbody>
{_actuators(spec)}
</mujoco>
"""


def _actuators(spec: BodySpec) -> str:
    if not spec.muscles:
        motors = "\n".join(f'    <motor name="m{k}" joint="j{k}" gear="{t!r}" ctrlrange="-1 1"/>'
                           for k, t in enumerate(spec.torques))
        return f"  <actuator>\n{motors}\n  </actuator>"
    tendons, muscles = [], []
    for k, (arm, force, limit) in enumerate(zip(spec.moment_arms, spec.muscle_forces, joint_limits(spec))):
        for name, coef in (("flexor", arm), ("extensor", -arm)):
            tendons.append(f'    <fixed name="j{k}_{name}"><joint joint="j{k}" coef="{coef!r}"/></fixed>')
            span = sorted((coef * -limit, coef * limit))  # the tendon's length over the joint's range
            muscles.append(f'    <muscle name="j{k}_{name}" tendon="j{k}_{name}" force="{force!r}" '
                           f'lengthrange="{span[0]!r} {span[1]!r}" ctrlrange="0 1"/>')
    tendon_xml, muscle_xml = "\n".join(tendons), "\n".join(muscles)
    return f"  <tendon>\n{tendon_xml}\n  </tendon>\n  <actuator>\n{muscle_xml}\n  </actuator>"


# ---------------------------------------------------------------------------------------- the env


def xml_file(spec: BodySpec) -> Path:
    """The body's XML in a file (MujocoEnv loads a path; anything that reads env.fullpath finds the body), under
    the temp folder, named by its content's hash: written once, atomically (processes may race), never stale."""
    xml = mjcf(spec)
    digest = hashlib.sha256(xml.encode()).hexdigest()[:16]
    path = Path(tempfile.gettempdir()) / "motorlab-bodies" / f"{spec.env_id}-{digest}.xml"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            f.write(xml)
        os.replace(tmp, path)
    return path


class GeneratedArm(MujocoEnv):
    """A generated arm reaching a target (see the module's docstring)."""

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": round(1 / CONTROL_DT)}

    def __init__(self, body_seed: int, muscles: bool = False, **kwargs):
        self.body = generate(body_seed, muscles)
        n = self.body.n_links
        size = 3 * n + (2 * n if muscles else 0) + 2
        obs = gym.spaces.Box(-np.inf, np.inf, (size,), np.float64)
        MujocoEnv.__init__(self, str(xml_file(self.body)), self.body.frame_skip, observation_space=obs,
                           default_camera_config={"distance": 2.5 * self.body.reach, "elevation": -90.0,
                                                  "azimuth": 90.0}, **kwargs)

    def _obs(self) -> np.ndarray:
        q, v = self.data.qpos, self.data.qvel
        tip = self.data.site("tip").xpos[:2] - self.data.site("target").xpos[:2]
        return np.concatenate([np.cos(q), np.sin(q), v, self.data.act, tip])

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        self.do_simulation(action, self.frame_skip)
        mujoco.mj_kinematics(self.model, self.data)  # the tip where the joints are now
        obs = self._obs()
        reward = float(reward_np(obs, action, obs))
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, {}

    def reset_model(self) -> np.ndarray:
        self.data.mocap_pos[0, :2] = self._draw_target()
        qpos = self.init_qpos + self.np_random.uniform(-REST_NOISE, REST_NOISE, self.model.nq)
        self.set_state(qpos, self.init_qvel)
        return self._obs()

    def _draw_target(self) -> np.ndarray:
        """The tip at random joint angles, redrawn while it is near the shoulder."""
        limits = np.array(joint_limits(self.body))
        for _ in range(100):
            tip = tip_position(self.body, self.np_random.uniform(-limits, limits))
            if np.hypot(*tip) >= TARGET_MIN_REACH * self.body.reach:
                break
        return tip


def tip_position(spec: BodySpec, q: np.ndarray) -> np.ndarray:
    """(x, y) of the tip at joint angles q (the shoulder's frame turned -90 degrees)."""
    angle = np.cumsum(q) - np.pi / 2
    lengths = np.array(spec.lengths)
    return np.array([(lengths * np.cos(angle)).sum(), (lengths * np.sin(angle)).sum()])


# ---------------------------------------------------------------------------------------- the reward


def reward_np(obs: np.ndarray, action: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
    """The env's reward (numpy): the same arithmetic, in the same order, as `reward` (hypot, not sqrt of a
    sum of squares: torch.sqrt on CPU is not always correctly rounded, hypot agrees bit for bit)."""
    d = next_obs[..., -2:]
    return -np.hypot(d[..., 0], d[..., 1]) - ACTION_COST * _effort(action)


def reward(obs: torch.Tensor, action: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
    """The env's reward, batched over any leading dims, for every generated body (tip - target last)."""
    d = next_obs[..., -2:]
    return -torch.hypot(d[..., 0], d[..., 1]) - ACTION_COST * _effort(action)


def _effort(action):
    """|action|^2 summed left to right, numpy or torch alike (their own sums group 8 terms differently: 1 ulp)."""
    total = action[..., 0] * action[..., 0]
    for i in range(1, action.shape[-1]):
        total = total + action[..., i] * action[..., i]
    return total


for _seed in SEEDS:
    for _muscles in (False, True):
        gym.register(env_id(_seed, _muscles), entry_point=GeneratedArm, max_episode_steps=EPISODE_STEPS,
                     kwargs={"body_seed": _seed, "muscles": _muscles})
del _seed, _muscles
