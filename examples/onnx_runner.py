"""One episode of a policy from `motorlab export RUN --onnx`: numpy + onnxruntime + gymnasium, no torch.

    python examples/onnx_runner.py DIR/policy.onnx [--seed 0] [--env ENV_ID]

Prints {"return": ..., "length": ...} as JSON. On a robot, replace env.reset/env.step with
its sensors and motors; the graph holds normalization, history and the action's bounds.
"""
import argparse
import json

import gymnasium as gym
import numpy as np
import onnxruntime as ort

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("policy")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--env", help="env id (default: the one the policy was trained in)")
args = parser.parse_args()

session = ort.InferenceSession(args.policy, providers=["CPUExecutionProvider"])
meta = session.get_modelmeta().custom_metadata_map  # what motorlab wrote: env_id, history, interface ...
history = int(meta["history"])
try:  # Gymnasium-Robotics' ids (PointMaze_*, AdroitHand*) register when it is imported
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
except ImportError:
    pass
env = gym.make(args.env or meta["env_id"])
# a Dict observation (goal-conditioned tasks) goes in as the flat vector, keys in the order of
# policy.onnx.json's obs_layout: Gymnasium's own flattening
env = gym.wrappers.FlattenObservation(env) if isinstance(env.observation_space, gym.spaces.Dict) else env
obs, _ = env.reset(seed=args.seed)
stack = np.tile(np.asarray(obs, np.float32), history)[None]  # at the start: the first observation, K times
total, steps, done = 0.0, 0, False
while not done:
    feed = {"obs": np.asarray(obs, np.float32)[None]}
    if history > 1:
        feed["obs_stack"] = stack
    action, *rest = session.run(None, feed)  # action (and, with history, next_obs_stack)
    stack = rest[0] if rest else stack
    obs, reward, terminated, truncated, _ = env.step(action[0])
    total, steps, done = total + float(reward), steps + 1, terminated or truncated
print(json.dumps({"return": total, "length": steps}))
