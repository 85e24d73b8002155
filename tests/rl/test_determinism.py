"""The same command with the same seed gives the same numbers on the same machine, each
command run twice in fresh processes: PPO training, SAR fit, forward-model fit, MPC."""

from __future__ import annotations

import json

import numpy as np
from safetensors.numpy import load_file

from motorlab.runs import read_metrics
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, read_summary, run_cli


def _twice(tmp_path, *args) -> tuple:
    outs = (tmp_path / "first", tmp_path / "second")
    for out in outs:
        assert_ok(run_cli(*args, "--out", out))
    return outs


def test_ppo_training_repeats(ppo_run, tmp_path):
    # ppo_run (conftest.py) is the first of the two: the same command, in a fresh process
    a, b = ppo_run, tmp_path / "second"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--seed", "0", "--no-progress", "--out", b))
    sa, sb = read_summary(a), read_summary(b)
    for key in ("eval_return_mean", "eval_return_min", "eval_episode_lengths", "train_episodes"):
        assert sa[key] == sb[key], key
    returns = [[r["episode_return"] for r in read_metrics(d) if np.isfinite(r["episode_return"])] for d in (a, b)]
    assert returns[0] == returns[1] and returns[0]
    wa, wb = load_file(a / "policy.safetensors"), load_file(b / "policy.safetensors")
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)


def test_sar_fit_repeats(hand_activations, tmp_path):
    a, b = _twice(tmp_path, "synergies", "fit", hand_activations, "--n", "5", "--seed", "2")
    with np.load(a / "sar.npz") as za, np.load(b / "sar.npz") as zb:
        assert za.files == zb.files
        for k in (k for k in za.files if k != "metadata"):
            np.testing.assert_array_equal(za[k], zb[k], err_msg=k)
        meta = [json.loads(str(z["metadata"])) for z in (za, zb)]
        assert meta[0].pop("created") != "" and meta[1].pop("created")  # only when it was made may differ
        assert meta[0] == meta[1]


def test_dynamics_fit_and_mpc_repeat(tmp_path):
    data = tmp_path / "data"
    assert_ok(run_cli("dynamics", "collect", "Reacher-v5", "--episodes", "60", "--seed", "1", "--out", data))
    fits = _twice(tmp_path / "fit", "dynamics", "fit", data, "--epochs", "2", "--batch-size", "500", "--seed", "4")
    assert read_summary(fits[0])["valid_mse"] == read_summary(fits[1])["valid_mse"]
    wa, wb = load_file(fits[0] / "model.safetensors"), load_file(fits[1] / "model.safetensors")
    assert all(np.array_equal(wa[k], wb[k]) for k in wa)
    plans = _twice(tmp_path / "mpc", "mpc", "Reacher-v5", "--model", fits[0], "--episodes", "2", "--horizon", "5",
                   "--population", "64", "--iterations", "3", "--seed", "5")
    sa, sb = read_summary(plans[0]), read_summary(plans[1])
    for key in ("return_mean", "return_std", "final_distance_mean"):
        assert sa[key] == sb[key], key
