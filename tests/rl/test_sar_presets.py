"""The learner-per-hour contenders (benchmarks/learner_per_hour.py): each preset trains a few hundred
steps on a MyoSuite task and evaluates, with the gradient steps per env step it names."""

from __future__ import annotations

import json
import zipfile

import pytest

from motorlab.kinds.train import TRAIN
from motorlab.rl.config import resolve

TASK = "myoFingerPoseRandom-v0"
STEPS, STARTS = 400, 200  # whole episodes of 100 steps: sar-sac-256 trains at episode ends


def n_updates(run_dir) -> int:
    """SB3's count of gradient steps, from model.zip's JSON part (no pickle is loaded)."""
    with zipfile.ZipFile(run_dir / "model.zip") as z:
        return int(json.loads(z.read("data"))["_n_updates"])


@pytest.mark.parametrize(("preset", "every"), [("sar-sac-half", 2), ("sar-sac-quarter", 4), ("sar-sac-eighth", 8),
                                               ("sar-sac-256", 1), ("sar-crossq", 1)])
def test_off_policy_contenders_train_at_their_ratio_and_evaluate(tmp_path, preset, every):
    cfg = resolve({"env": {"id": TASK}, "preset": preset, "timesteps": STEPS, "solve_episodes": 2, "progress": False,
                   "hyperparams": {"learning_starts": STARTS}})
    s = TRAIN.perform(cfg, tmp_path / preset).keys()
    assert s["timesteps"] == STEPS and s["eval_episodes"] == 2 and 0.0 <= s["eval_success_rate"] <= 1.0
    expected = (STEPS - STARTS) // every  # one gradient step per `every` env steps once learning starts
    assert abs(n_updates(tmp_path / preset) - expected) <= 1, preset


def test_sar_sac_256_has_smaller_networks_than_the_reference():
    small = resolve({"preset": "sar-sac-256"}).hyperparams["policy_kwargs"]["net_arch"]
    reference = resolve({"preset": "sar-sac"}).hyperparams["policy_kwargs"]["net_arch"]
    assert small == {"pi": [256, 256], "qf": [256, 256]} and reference == {"pi": [400, 300], "qf": [400, 300]}


def test_ppo_contender_trains_on_four_env_processes_and_evaluates(tmp_path):
    cfg = resolve({"env": {"id": TASK}, "preset": "sar-ppo", "timesteps": STEPS, "solve_episodes": 2,
                   "progress": False, "hyperparams": {"n_steps": 64, "batch_size": 64, "n_epochs": 2}})
    s = TRAIN.perform(cfg, tmp_path / "ppo").keys()
    assert cfg.n_envs == 4 and cfg.normalize
    assert s["timesteps"] == 4 * 64 * 2  # whole rollouts of 4 envs x n_steps, to the first past the budget
    assert n_updates(tmp_path / "ppo") == 2 * 2  # rollouts x epochs (SB3's PPO counts epochs)
    assert 0.0 <= s["eval_success_rate"] <= 1.0 and s["eval_episodes"] == 2


def test_sar_sac_fast_trains_on_four_env_processes_at_four_updates_per_hundred_env_steps(tmp_path):
    """The SAR recipes' learner, as they run it: 4 env processes, 4 gradient steps every 25 vectorized
    steps (100 env steps), trained once learning starts."""
    cfg = resolve({"env": {"id": TASK}, "preset": "sar-sac-fast", "timesteps": STEPS, "solve_episodes": 2,
                   "progress": False, "hyperparams": {"learning_starts": STARTS}})
    s = TRAIN.perform(cfg, tmp_path / "fast").keys()
    assert cfg.n_envs == 4 and cfg.normalize and s["timesteps"] == STEPS
    # rollouts of 100 env steps end at 100, 200, 300, 400; SB3 trains after those past learning_starts
    assert n_updates(tmp_path / "fast") == 4 * ((STEPS - STARTS) // 100)
    assert 0.0 <= s["eval_success_rate"] <= 1.0 and s["eval_episodes"] == 2
