"""`synergies collect` (motorlab.synergy_runs.activations): muscle activations of a policy's
episodes at or above the P-th percentile of the preview returns; the result depends on seeds,
not on workers."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
import torch

from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.kinds.synergies import COLLECT
from motorlab.policies import load_run_policy
from motorlab.synergy_runs.activations import Episode
from tests.helpers import (
    COLLECT_EPISODES,
    COLLECT_PERCENTILE,
    COLLECT_PREVIEW,
    COLLECT_SEED,
    HAND_ID,
    HAND_MUSCLES,
    assert_one_line_error,
    read_summary,
    run_cli,
    run_kind,
)

collect_mod = importlib.import_module("motorlab.synergy_runs.activations")


def collect(run_dir, out, progress=False, **fields):
    return run_kind(COLLECT, out, progress, run=str(run_dir), **fields)


def load(path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:  # plain arrays only: no pickle needed
        return {k: data[k] for k in data.files}


def test_threshold_is_the_percentile_of_the_preview_returns(hand_activations):
    d = load(hand_activations)
    meta = json.loads(str(d["metadata"]))
    assert meta["percentile"] == COLLECT_PERCENTILE and meta["preview"] == COLLECT_PREVIEW
    assert d["preview_returns"].shape == (COLLECT_PREVIEW,)
    assert float(d["threshold"]) == pytest.approx(float(np.percentile(d["preview_returns"], COLLECT_PERCENTILE)),
                                                  rel=1e-12, abs=1e-12)
    assert np.all(d["returns"] >= d["threshold"])  # the rule is return >= threshold


def test_kept_episodes_are_those_requested(hand_activations):
    d = load(hand_activations)
    assert d["returns"].shape == d["seeds"].shape == d["solved"].shape == (COLLECT_EPISODES,)
    # kept episodes come after the preview's seeds, in seed order
    assert np.all(d["seeds"] >= COLLECT_SEED + COLLECT_PREVIEW)
    assert np.all(np.diff(d["seeds"]) > 0)
    s = read_summary(hand_activations.parent)
    assert s["episodes_kept"] == s["episodes_requested"] == COLLECT_EPISODES
    assert s["episodes_tried"] >= COLLECT_EPISODES
    assert s["threshold"] == pytest.approx(float(d["threshold"]))
    assert s["kept_return_mean"] == pytest.approx(float(d["returns"].mean()))
    assert s["kept_success_rate"] == pytest.approx(float(d["solved"].mean()))


def test_activations_layout(hand_activations):
    d = load(hand_activations)
    acts, episode = d["activations"], d["episode"]
    assert acts.ndim == 2 and acts.shape[1] == HAND_MUSCLES
    assert episode.shape == (acts.shape[0],)
    assert np.all(np.diff(episode) >= 0)  # episodes are stored one after the other
    lengths = np.bincount(episode)
    assert len(lengths) == COLLECT_EPISODES and np.all(lengths > 0)
    assert lengths.sum() == acts.shape[0]
    assert np.all(np.isfinite(acts)) and acts.min() >= 0.0 and acts.max() <= 1.0
    assert acts.std(axis=0).max() > 0  # muscles did something
    s = read_summary(hand_activations.parent)
    assert (s["samples"], s["n_muscles"]) == acts.shape


def test_kept_episode_is_that_seed_replayed(hand_play_run, hand_activations):
    """The activations of the first kept episode are MuJoCo's data.act after each step of
    the policy (sampling, torch seeded with the episode seed) from reset(seed)."""
    d = load(hand_activations)
    seed = int(d["seeds"][0])
    env = make_env(EnvConfig(id=HAND_ID), shaped=False)
    policy = load_run_policy(hand_play_run)
    policy.deterministic = False
    torch.manual_seed(seed)
    obs, _ = env.reset(seed=seed)
    acts, ret, done = [], 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(policy.act(obs[None])[0])
        acts.append(np.array(env.unwrapped.data.act, dtype=np.float32))
        ret += float(reward)
        done = terminated or truncated
    env.close()
    np.testing.assert_array_equal(np.stack(acts), d["activations"][d["episode"] == 0])
    assert ret == pytest.approx(float(d["returns"][0]))


def test_two_workers_give_the_same_result(hand_play_run, hand_activations, tmp_path):
    collect(hand_play_run, episodes=COLLECT_EPISODES, percentile=COLLECT_PERCENTILE, preview=COLLECT_PREVIEW,
            seed=COLLECT_SEED, workers=2, out=tmp_path, progress=False)
    one, two = load(hand_activations), load(tmp_path / "activations.npz")
    assert set(one) == set(two)
    for key in one:
        if key != "metadata":
            np.testing.assert_array_equal(one[key], two[key], err_msg=key)


def test_deterministic_collection_repeats(hand_play_run, tmp_path):
    kwargs = dict(episodes=2, percentile=0.0, preview=2, seed=3, workers=1, progress=False)
    a = collect(hand_play_run, deterministic=True, out=tmp_path / "a", **kwargs)
    b = collect(hand_play_run, deterministic=True, out=tmp_path / "b", **kwargs)
    da, db = load(tmp_path / "a" / "activations.npz"), load(tmp_path / "b" / "activations.npz")
    for key in ("activations", "returns", "preview_returns", "seeds"):
        np.testing.assert_array_equal(da[key], db[key], err_msg=key)
    assert a["threshold"] == b["threshold"]
    assert json.loads(str(da["metadata"]))["deterministic"] is True
    # the policy's mean action differs from a sample of it
    collect(hand_play_run, deterministic=False, out=tmp_path / "c", **kwargs)
    dc = load(tmp_path / "c" / "activations.npz")
    assert dc["activations"].shape != da["activations"].shape or not np.array_equal(dc["activations"], da["activations"])


# ---- the threshold rule, on scripted episode returns -----------------------------------

def scripted(returns_by_seed):
    """A stand-in for the worker pool: episode `seed` has return returns_by_seed(seed)."""

    def episodes(seeds, workers, init_args):
        for s in seeds:
            yield Episode(seed=s, ret=float(returns_by_seed(s)), length=3, solved=False,
                          activations=np.full((3, HAND_MUSCLES), (s % 10) / 10, dtype=np.float32))

    return episodes


def test_return_equal_to_threshold_is_kept(hand_play_run, tmp_path, monkeypatch):
    # preview seeds 0..3 return 0..3: the 100th percentile is 3; later seeds return 3 or 2.
    monkeypatch.setattr(collect_mod, "_episodes", scripted(lambda s: s if s < 4 else (3 if s % 2 else 2)))
    s = collect(hand_play_run, episodes=3, percentile=100, preview=4, seed=0, out=tmp_path, progress=False)
    d = load(tmp_path / "activations.npz")
    assert float(d["threshold"]) == 3.0 == s["threshold"]
    assert list(d["seeds"]) == [5, 7, 9] and np.all(d["returns"] == 3.0)
    assert s["episodes_tried"] == 6  # seeds 4..9


def test_fewer_episodes_than_requested_are_reported(hand_play_run, tmp_path, monkeypatch):
    monkeypatch.setattr(collect_mod, "_episodes", scripted(lambda s: s if s < 4 else (5 if s == 6 else 0)))
    s = collect(hand_play_run, episodes=3, percentile=100, preview=4, seed=0, max_episodes=5, out=tmp_path,
                progress=False)
    assert s["episodes_kept"] == 1 and s["episodes_requested"] == 3 and s["episodes_tried"] == 5
    assert read_summary(tmp_path)["episodes_kept"] == 1
    assert list(load(tmp_path / "activations.npz")["seeds"]) == [6]


def test_no_episode_reaching_the_threshold_is_an_error(hand_play_run, tmp_path, monkeypatch):
    monkeypatch.setattr(collect_mod, "_episodes", scripted(lambda s: s if s < 4 else -1))
    with pytest.raises(MotorlabError, match=r"no episode in 5 reached the threshold .*--percentile"):
        collect(hand_play_run, episodes=2, percentile=100, preview=4, seed=0, max_episodes=5, out=tmp_path / "out",
                progress=False)
    assert not (tmp_path / "out" / "activations.npz").exists()


# ---- user mistakes ---------------------------------------------------------------------

def test_env_without_muscles(ppo_run, tmp_path):
    # muscle activations asked for by name; `auto` records the pendulum's controls instead
    # (tests/synergies/test_signals.py)
    with pytest.raises(MotorlabError, match=r"data\.act.*--signal ctrl"):
        collect(ppo_run, episodes=2, preview=2, workers=1, signal="act", out=tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def test_hand_activations_say_they_are_muscle_activations(hand_activations):
    d = load(hand_activations)
    assert str(d["signal"]) == "act" and json.loads(str(d["metadata"]))["signal"] == "act"
    np.testing.assert_array_equal(d["low"], np.zeros(HAND_MUSCLES))
    np.testing.assert_array_equal(d["high"], np.ones(HAND_MUSCLES))
    s = read_summary(hand_activations.parent)
    assert s["signal"] == "act" and s["n_signals"] == s["n_muscles"] == HAND_MUSCLES


@pytest.mark.parametrize("kwargs, fragment", [
    ({"episodes": 0}, "--episodes"),
    ({"preview": 0}, "--preview"),
    ({"percentile": 120.0}, "--percentile"),
    ({"percentile": -1.0}, "--percentile"),
])
def test_bad_counts(hand_play_run, tmp_path, kwargs, fragment):
    args = {"episodes": 2, "preview": 2, "percentile": 50.0, **kwargs}
    with pytest.raises(MotorlabError, match=fragment):
        collect(hand_play_run, workers=1, out=tmp_path / "out", progress=False, **args)
    assert not (tmp_path / "out").exists()


def test_cli_bad_percentile(hand_play_run, tmp_path):
    proc = run_cli("synergies", "collect", hand_play_run, "--percentile", "120", "--out", tmp_path / "out")
    assert_one_line_error(proc, "--percentile", "120")
    assert not (tmp_path / "out").exists()
