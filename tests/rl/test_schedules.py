"""Learning-rate and clip-range schedules: parsing, values, and their effect on SB3."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from motorlab.errors import MotorlabError
from motorlab.rl.config import resolve
from motorlab.rl.schedules import parse_schedule

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


@pytest.mark.parametrize(
    "spec, start, end",
    [
        ("3e-4", 3e-4, 3e-4),
        (" 0.2 ", 0.2, 0.2),
        (0.1, 0.1, 0.1),
        ("linear:1e-3,0", 1e-3, 0.0),
        ("linear:0.3, 0.1", 0.3, 0.1),
        ("1e-3->1e-5", 1e-3, 1e-5),
        ("0.1 -> 0.3", 0.1, 0.3),  # increasing works too
    ],
)
def test_schedule_values(spec, start, end):
    schedule = parse_schedule(spec)
    assert schedule(1.0) == pytest.approx(start)
    assert schedule(0.5) == pytest.approx((start + end) / 2)
    assert schedule(0.0) == pytest.approx(end)
    # SB3 calls it with progress_remaining: 1 at the start, 0 at the end.
    assert float(schedule(1.0)) == pytest.approx(start)
    assert float(schedule(0.0)) == pytest.approx(end)


@pytest.mark.parametrize(
    "spec",
    ["abc", "", "linear:1", "linear:1,2,3", "linear:a,b", "1->", "->1", "1->2->3", "-1", "linear:1e-3,-1",
     "nan", "inf", "linear:nan,0"],
)
def test_bad_schedules_raise(spec):
    with pytest.raises(MotorlabError):
        parse_schedule(spec, "learning-rate")


def test_bad_schedule_is_rejected_by_train_config():
    with pytest.raises(MotorlabError, match="lr-typo"):
        resolve({"lr": "lr-typo"})
    with pytest.raises(MotorlabError):
        resolve({"clip_range": "linear:0.3"})


def _scalars(run_dir, tag: str) -> list[tuple[int, float]]:
    files = sorted((run_dir / "tensorboard").glob("PPO_*"))
    assert files, f"no SB3 TensorBoard folder in {run_dir / 'tensorboard'}"
    acc = EventAccumulator(str(files[0]))
    acc.Reload()
    return [(e.step, e.value) for e in acc.Scalars(tag)]


def test_ppo_learning_rate_and_clip_schedules_reach_sb3(tmp_path):
    from motorlab.rl.sb3 import build_model

    total, n_steps = 192, 64
    cfg = resolve({"algo": "ppo", "timesteps": total, "lr": "linear:1e-3,0", "clip_range": "linear:0.3,0.1",
                   "device": "cpu", "progress": False,
                   "hyperparams": {"n_steps": n_steps, "batch_size": 64, "n_epochs": 1}})
    model = build_model(cfg, tmp_path)
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(1e-3)  # the schedule's start
    assert model.clip_range(1.0) == pytest.approx(0.3) and model.clip_range(0.0) == pytest.approx(0.1)
    model.learn(total_timesteps=total, tb_log_name="PPO")
    # After the last update (progress remaining 0) the optimizer runs at the schedule's end value.
    assert model._current_progress_remaining == pytest.approx(0.0)
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(0.0)
    model.get_env().close()

    lrs = _scalars(tmp_path, "train/learning_rate")
    clips = _scalars(tmp_path, "train/clip_range")
    assert len(lrs) >= 2 and len(clips) == len(lrs)
    # Each logged update used the schedule at progress remaining p = 1 - k * n_steps / total.
    allowed = [1 - k * n_steps / total for k in range(1, total // n_steps + 1)]
    for (_, lr), (_, clip) in zip(lrs, clips):
        p = lr / 1e-3
        assert min(abs(p - a) for a in allowed) < 1e-5, (lr, allowed)
        assert clip == pytest.approx(0.1 + 0.2 * p, abs=1e-6)  # same progress for both schedules
    values = [lr for _, lr in lrs]
    assert all(a > b for a, b in zip(values, values[1:]))  # decreasing: the schedule is used


def test_constant_learning_rate_stays_constant(tmp_path):
    from motorlab.rl.sb3 import build_model

    cfg = resolve({"algo": "ppo", "timesteps": 128, "lr": "5e-4", "device": "cpu", "progress": False,
                   "hyperparams": {"n_steps": 64, "batch_size": 64, "n_epochs": 1}})
    model = build_model(cfg, tmp_path)
    model.learn(total_timesteps=128, tb_log_name="PPO")
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(5e-4)
    model.get_env().close()
    assert all(math.isclose(v, 5e-4, rel_tol=1e-6) for _, v in _scalars(tmp_path, "train/learning_rate"))


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_clip_range_with_off_policy_algo_raises(algo):
    # rejected with the settings, before any model or run folder exists
    with pytest.raises(MotorlabError, match="PPO"):
        resolve({"algo": algo, "timesteps": 100, "clip_range": "0.2", "device": "cpu"})


def test_sac_accepts_learning_rate_schedule(tmp_path):
    from motorlab.rl.sb3 import build_model

    cfg = resolve({"algo": "sac", "timesteps": 100, "lr": "linear:1e-3,1e-4", "device": "cpu"})
    model = build_model(cfg, tmp_path)
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)
    assert model.lr_schedule(0.0) == pytest.approx(1e-4)
    assert np.isclose(model.actor.optimizer.param_groups[0]["lr"], 1e-3)
    model.get_env().close()
