"""Model-based workflow: collected transitions, forward model, fit, save/load, CEM planning."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch.nn import functional as F

from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.model import DEFAULT_NONLINEARITY, ForwardModel, Normalizer, load_model
from motorlab.dynamics.planner_rewards import reacher_v5
from motorlab.dynamics.train import fit_model, normalized_mse, split_episodes
from motorlab.dynamics.transitions import load_transitions
from motorlab.errors import MotorlabError
from motorlab.kinds.dynamics import ModelSettings
from motorlab.planning.mpc import model_scorer
from motorlab.planning.planners.cem import CEMPlanner
from motorlab.planning.planners.evotorch import EvoTorchCEM
from motorlab.planning.planners.mppi import MPPIPlanner

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


@pytest.fixture(scope="module")
def reacher_data():
    return collect_transitions("Reacher-v5", 120, seed=4, workers=2, progress=False)


def test_collected_reacher_transitions_are_gymnasiums(reacher_data):
    """Replay each collected episode in Gymnasium's env from its first state: same transitions
    (MuJoCo's constraint solver run to convergence, as the closed form solves the elbow's limit)."""
    d = reacher_data
    assert d.meta["simulator"] == "closed-form" and len(d) == 120 * 50
    env = gym.make("Reacher-v5")
    env.unwrapped.model.opt.tolerance = 0.0
    env.reset(seed=0)
    for e in range(0, 120, 17):
        rows = np.flatnonzero(d.episode == e)
        s0 = d.states[rows[0]]
        qpos = np.r_[np.arctan2(s0[2:4], s0[0:2]), d.goals[rows[0]]]
        qvel = np.r_[s0[4:6], 0.0, 0.0]
        env.unwrapped.set_state(qpos, qvel)
        for _i, r in enumerate(rows):
            obs, reward, *_ = env.step(d.actions[r])
            tip = obs[8:10] + obs[4:6]
            np.testing.assert_allclose(d.next_states[r][:6], np.r_[obs[0:4], obs[6:8]], atol=1e-9)
            np.testing.assert_allclose(d.next_states[r][6:], tip, rtol=0, atol=1e-12)
            assert abs(d.rewards[r] - reward) < 1e-12
            np.testing.assert_array_equal(d.goals[r], obs[4:6])
        assert d.dones[rows].tolist() == [False] * 49 + [True] and not d.terminated[rows].any()
    np.testing.assert_array_equal(d.states[1:][d.episode[1:] == d.episode[:-1]],
                                  d.next_states[:-1][d.episode[1:] == d.episode[:-1]])


def test_gymnasium_pool_does_not_depend_on_workers():
    one = collect_transitions("Pendulum-v1", 3, workers=1, seed=2, progress=False)
    two = collect_transitions("Pendulum-v1", 3, workers=2, seed=2, progress=False)
    for k in ("states", "actions", "next_states", "rewards", "dones", "episode"):
        np.testing.assert_array_equal(getattr(one, k), getattr(two, k))
    assert one.meta["simulator"] == "gymnasium" and one.goals.shape == (600, 0) and one.dones.sum() == 3


def test_transitions_round_trip_and_bad_files(reacher_data, tmp_path):
    path = tmp_path / "transitions.npz"
    reacher_data.save(path)
    back = load_transitions(tmp_path)
    np.testing.assert_array_equal(back.next_states, reacher_data.next_states)
    assert back.meta["state_labels"][6:] == ["tip x", "tip y"]

    arrays = dict(np.load(path))
    bad = dict(arrays, states=arrays["states"].copy())
    bad["states"][5, 1] = np.nan
    np.savez(tmp_path / "nan.npz", **bad)
    with pytest.raises(MotorlabError, match="NaN or Inf .* row 5"):
        load_transitions(tmp_path / "nan.npz")
    np.savez(tmp_path / "short.npz", **dict(arrays, actions=arrays["actions"][:-3]))
    with pytest.raises(MotorlabError, match="actions has"):
        load_transitions(tmp_path / "short.npz")
    np.savez(tmp_path / "nometa.npz", **{k: v for k, v in arrays.items() if k != "meta"})
    with pytest.raises(MotorlabError, match="lacks meta"):
        load_transitions(tmp_path / "nometa.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(MotorlabError, match=r"not a transitions file written by .* \(it is not an \.npz archive\)"):
        load_transitions(tmp_path / "junk.npz")


def test_normalizer_round_trip():
    x = np.random.default_rng(0).normal(3.0, [0.1, 5.0, 0.0], size=(500, 3))  # a constant column too
    norm = Normalizer(3).fit(x)
    z = norm(torch.as_tensor(x))
    assert torch.isfinite(z).all() and abs(float(z[:, 1].std()) - 1) < 1e-6
    np.testing.assert_allclose(norm.inverse(z).numpy(), x, atol=1e-9)


def test_validation_holds_out_whole_episodes():
    episode = np.repeat(np.arange(20), 5)
    train, valid = split_episodes(episode, 0.2, seed=0)
    assert len(valid) == 20 and not set(episode[train]) & set(episode[valid])
    assert sorted(np.r_[train, valid]) == list(range(100))


def test_tiny_fit_lowers_the_loss_and_saves_identically(reacher_data, tmp_path):
    model, result = fit_model(reacher_data, epochs=4, ensemble=2, batch_size=500, progress=False)
    history = [r["valid_mse"] for r in result["history"]]
    untrained = ForwardModel(8, 2, members=2)
    untrained.fit_normalizers(reacher_data.states, reacher_data.actions, reacher_data.next_states)
    x, y = model.training_pairs(reacher_data.states, reacher_data.actions, reacher_data.next_states)
    assert history[-1] < min(history[0], normalized_mse(untrained, x, y))  # (SiLU's first epoch is about untrained)
    assert result["valid_mse"] == min(history) and model.members == 2

    model.save(tmp_path, metrics={"valid_mse": result["valid_mse"]})
    back = load_model(tmp_path, env_id="Reacher-v5", state_layout="reacher")
    s = torch.as_tensor(reacher_data.states[:64], dtype=torch.float32)
    a = torch.as_tensor(reacher_data.actions[:64], dtype=torch.float32)
    assert torch.equal(model.predict(s, a), back.predict(s, a))
    assert back.metrics["valid_mse"] == result["valid_mse"]
    with pytest.raises(MotorlabError, match="models 'Reacher-v5', not 'Reacher-v4'"):
        load_model(tmp_path, env_id="Reacher-v4")
    with pytest.raises(MotorlabError, match="'reacher' state layout, not 'observation'"):
        load_model(tmp_path, state_layout="observation")
    (tmp_path / "model.safetensors").write_bytes(b"\x00" * 40)
    with pytest.raises(MotorlabError, match="damaged"):
        load_model(tmp_path)
    (tmp_path / "model.json").write_text("{")
    with pytest.raises(MotorlabError, match="not valid JSON"):
        load_model(tmp_path)


def test_a_fit_keeps_the_best_epochs_weights_or_the_last():
    """40 pendulum episodes, every 4th held out: the held-out error is lowest at epoch 24 of 30 here."""
    data = collect_transitions("InvertedPendulum-v5", 40, seed=4, workers=1, progress=False)
    fit = dict(epochs=30, hidden=(128, 128), batch_size=16, progress=False, valid_episodes=np.arange(0, 40, 4))
    best, kept_best = fit_model(data, keep_weights="best", **fit)
    last, kept_last = fit_model(data, keep_weights="last", **fit)
    history = [r["valid_mse"] for r in kept_last["history"]]
    assert history == [r["valid_mse"] for r in kept_best["history"]]  # the same training, only the weights kept differ
    assert kept_best["best_epoch"] == kept_last["best_epoch"] == 1 + int(np.argmin(history)) < 30
    assert kept_best["kept_epoch"] == kept_best["best_epoch"] and kept_best["valid_mse"] == min(history)
    assert kept_last["kept_epoch"] == 30 and kept_last["valid_mse"] == history[-1] > min(history)
    s, a = (torch.as_tensor(x[:50], dtype=torch.float32) for x in (data.states, data.actions))
    assert not torch.allclose(best.predict(s, a), last.predict(s, a))
    with pytest.raises(MotorlabError, match="keep_weights 'lowest'"):
        fit_model(data, keep_weights="lowest", **fit)


def test_dynamics_fit_keeps_the_best_epoch_and_the_loop_the_last():
    from motorlab.kinds.dynamics import DynamicsFitSettings
    from motorlab.kinds.planning import MbrlSettings

    assert DynamicsFitSettings.model_fields["keep_weights"].default == "best"
    assert MbrlSettings.model_fields["keep_weights"].default == "last"
    assert MbrlSettings(env="InvertedPendulum-v5").loop_plan().fit["keep_weights"] == "last"
    assert MbrlSettings(env="InvertedPendulum-v5", keep_weights="best").loop_plan().fit["keep_weights"] == "best"


def _rare_push(n: int, seed: int):
    """Transitions where entry 0 always changes with the action and entry 1 only where state 0 > 0.8
    (a tenth of the rows, as an object moves only while pushed): there by 2.5 (s0 - 0.8) a."""
    from motorlab.dynamics.transitions import Transitions

    rng = np.random.default_rng(seed)
    s, a = rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 1))
    push = s[:, 0] > 0.8
    delta = np.c_[0.1 * a[:, 0] + 0.05 * s[:, 0], np.where(push, 2.5 * (s[:, 0] - 0.8) * a[:, 0], 0.0)]
    flags = np.zeros(n, dtype=bool)
    return Transitions(s, a, s + delta, np.zeros(n), flags, flags, np.arange(n) // 50, np.zeros((n, 0))), push


def test_beta_nll_fits_the_mean_of_rare_changes_that_plain_nll_calls_noise():
    """PETS' plain NLL explains the rare pushes by variance and leaves their mean at ~0 (as the loop's
    members did with Pusher's object); beta-NLL (0.5) fits them. Shares of the pushes' variance
    explained on new rows: plain ~0.02, beta 0.40-0.47 (seeds 0, 1)."""
    train, _ = _rare_push(3000, seed=0)
    test, push = _rare_push(3000, seed=1)
    change = (test.next_states - test.states)[push, 1]

    def explained(nll_beta: float) -> float:
        model, _ = fit_model(train, epochs=30, hidden=(32, 32), ensemble=2, batch_size=64, probabilistic=True,
                             valid_fraction=0, progress=False, nll_beta=nll_beta)
        s, a = (torch.as_tensor(x, dtype=torch.float32) for x in (test.states, test.actions))
        with torch.no_grad():
            predicted = (model.predict(s, a).numpy() - test.states)[push, 1]
        return 1 - float(((predicted - change) ** 2).sum() / (change ** 2).sum())

    assert explained(0.0) < 0.1 and explained(0.5) > 0.3
    with pytest.raises(MotorlabError, match="--nll-beta must be in"):
        fit_model(train, epochs=1, probabilistic=True, progress=False, nll_beta=1.5)
    with pytest.raises(ValueError, match="nll_beta"):
        ModelSettings(nll_beta=-0.5)


def test_a_silu_model_fits_saves_and_loads_as_silu(reacher_data, tmp_path):
    """nonlinearity="silu" (the Python API's default, as the CLI's): SiLU hidden layers without layer norms (no layer-norm weights stored); it
    learns, and a saved model loads back with the same nonlinearity and predictions. A model.json
    written before the nonlinearity was recorded loads as tanh + layer norm."""
    model, result = fit_model(reacher_data, epochs=4, ensemble=2, batch_size=500, progress=False)  # the default
    history = [r["valid_mse"] for r in result["history"]]
    assert history[-1] < history[0]
    assert model.nonlinearity == "silu" and not any("ln_" in k for k in model.state_dict())
    model.save(tmp_path)
    assert json.loads((tmp_path / "model.json").read_text())["architecture"]["nonlinearity"] == "silu"
    back = load_model(tmp_path)
    s = torch.as_tensor(reacher_data.states[:64], dtype=torch.float32)
    a = torch.as_tensor(reacher_data.actions[:64], dtype=torch.float32)
    assert back.nonlinearity == "silu" and torch.equal(model.predict(s, a), back.predict(s, a))
    with torch.no_grad():  # the net is Linear -> SiLU -> Linear -> SiLU -> Linear, by hand
        x = back.inputs(s, a).expand(2, -1, -1)
        w, b = back.net.weights, back.net.biases
        by_hand = torch.baddbmm(b[2], F.silu(torch.baddbmm(b[1], F.silu(torch.baddbmm(b[0], x, w[0])), w[1])), w[2])
        torch.testing.assert_close(back.net(back.inputs(s, a)), by_hand)
    old, _ = fit_model(reacher_data, epochs=1, progress=False, nonlinearity="tanh")
    old.save(tmp_path / "old")
    meta = json.loads((tmp_path / "old" / "model.json").read_text())
    del meta["architecture"]["nonlinearity"]
    (tmp_path / "old" / "model.json").write_text(json.dumps(meta))
    assert load_model(tmp_path / "old").nonlinearity == "tanh"
    meta["architecture"]["nonlinearity"] = "gelu"
    (tmp_path / "old" / "model.json").write_text(json.dumps(meta))
    with pytest.raises(MotorlabError, match="nonlinearity 'gelu'"):
        load_model(tmp_path / "old")
    assert ModelSettings.model_fields["nonlinearity"].default == DEFAULT_NONLINEARITY  # one default everywhere


class PointMass:
    """A known linear system: position += velocity * dt, velocity += action * dt; the goal is a point."""

    dt = 0.1

    def predict(self, s, a):
        pos, vel = s[..., :2], s[..., 2:]
        return torch.cat([pos + vel * self.dt, vel + a * self.dt], -1)


def point_reward(s, a, s2, goal):
    return -torch.linalg.vector_norm(s2[..., :2] - goal, dim=-1) - 0.01 * a.square().sum(-1)


@pytest.mark.parametrize("planner_class, iterations", [(CEMPlanner, 4), (MPPIPlanner, 4), (EvoTorchCEM, 10)])
def test_cem_reaches_the_target_of_a_known_linear_system(planner_class, iterations):
    system = PointMass()
    planner = planner_class(model_scorer(system, point_reward), -np.ones(2), np.ones(2), horizon=15,
                            population=100, iterations=iterations, elites=10, seed=0)
    goals = torch.tensor([[0.5, -0.3], [-0.4, 0.2], [0.0, 0.45]])
    s = torch.zeros(3, 4)
    planner.reset(3)
    for _ in range(60):
        s = system.predict(s, planner.plan(s, goals))
    assert torch.linalg.vector_norm(s[:, :2] - goals, dim=-1).max() < 0.03


def test_reacher_reward_in_torch_matches_the_env(reacher_data):
    d = reacher_data
    r = reacher_v5(*(torch.as_tensor(x) for x in (d.states, d.actions, d.next_states, d.goals)))
    np.testing.assert_allclose(r.numpy(), d.rewards, atol=1e-12)


@pytest.mark.parametrize("nonlinearity", ["tanh", "silu"])
@pytest.mark.parametrize("members, probabilistic", [(1, False), (3, False), (3, True)])
def test_fast_predict_equals_predict(members, probabilistic, nonlinearity):
    """The planner's folded-normalizer model computes the same next states, step by step and over a
    horizon (probabilistic members: their Gaussians' means, as predict and mean propagation use)."""
    rng = np.random.default_rng(0)
    model = ForwardModel(8, 2, members=members, probabilistic=probabilistic, nonlinearity=nonlinearity)
    model.fit_normalizers(rng.normal(1, 3, (200, 8)), rng.uniform(-1, 1, (200, 2)), rng.normal(1, 3, (200, 8))
                          + rng.normal(0, 0.1, (200, 8)))
    s = torch.as_tensor(rng.normal(1, 3, (64, 8)), dtype=torch.float32)
    a = torch.as_tensor(rng.uniform(-1, 1, (64, 2)), dtype=torch.float32)
    with torch.no_grad():
        torch.testing.assert_close(model.fast_predict()(s, a), model.predict(s, a), rtol=1e-5, atol=1e-5)
        plans = torch.as_tensor(rng.uniform(-1, 1, (64, 6, 2)), dtype=torch.float32)
        path = model.fast_rollout()(s, plans)  # the planner's whole-horizon path, one step at a time
        assert path.shape == (64, 7, 8)
        torch.testing.assert_close(path[:, 0], s)
        for t in range(6):
            torch.testing.assert_close(path[:, t + 1], model.predict(path[:, t], plans[:, t]), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("nonlinearity", ["tanh", "silu"])
@pytest.mark.parametrize("members, probabilistic", [(1, False), (5, False), (5, True)])
def test_fast_rollout_with_a_reward_head_equals_step_fn(members, probabilistic, nonlinearity):
    """A model with heads plans on the fast path under mean propagation: the same path and reward-head
    predictions as step_fn's, and the same returns in model_scorer (learned reward, and an exact one
    on the head model); the termination column (and a probabilistic member's variances) left out."""
    from motorlab.dynamics.planner_rewards import Task

    rng = np.random.default_rng(members)
    torch.manual_seed(members)
    model = ForwardModel(8, 2, members=members, probabilistic=probabilistic, heads=("reward", "termination"),
                         nonlinearity=nonlinearity)
    model.fit_normalizers(rng.normal(1, 3, (200, 8)), rng.uniform(-1, 1, (200, 2)),
                          rng.normal(1, 3, (200, 8)) + rng.normal(0, 0.1, (200, 8)), rng.normal(-2, 5, 200))
    with torch.no_grad():  # members that differ, and layer norms whose affines are not the identity
        for p in model.parameters():
            p.add_(0.2 * torch.randn_like(p))
    s = torch.as_tensor(rng.normal(1, 3, (64, 8)), dtype=torch.float32)
    plans = torch.as_tensor(rng.uniform(-1, 1, (64, 6, 2)), dtype=torch.float32)
    step = model.step_fn("mean")
    path, rewards = [s], []
    for t in range(6):
        next_states, r, _ = step(path[-1], plans[:, t])
        path.append(next_states)
        rewards.append(r)
    path, rewards = torch.stack(path, 1), torch.stack(rewards, 1)

    fast_path, fast_rewards = model.fast_rollout(reward=True)(s, plans)
    assert fast_path.shape == (64, 7, 8) and fast_rewards.shape == (64, 6)
    # float32 sums in another order (the normalizers folded in) over 6 steps: SiLU's unbounded
    # outputs on these perturbed weights reach ~10, so it gets a relative tolerance of 1e-4 (tanh 1e-5)
    rtol = 1e-4 if nonlinearity == "silu" else 1e-5
    torch.testing.assert_close(fast_path, path, rtol=rtol, atol=1e-4)
    torch.testing.assert_close(fast_rewards, rewards, rtol=rtol, atol=1e-4)
    torch.testing.assert_close(model.fast_rollout()(s, plans), path, rtol=rtol, atol=1e-4)

    goals = torch.zeros(64, 0)
    learned = model_scorer(model, Task(None, None, "learned", "none"))(s, plans, goals)
    torch.testing.assert_close(learned, rewards.sum(1), rtol=1e-5, atol=1e-4)
    exact = model_scorer(model, Task(lambda s0, a, s1, g: -s1.square().sum(-1), None, "builtin", "none"))
    torch.testing.assert_close(exact(s, plans, goals), -path[:, 1:].square().sum((1, 2)), rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize("nonlinearity", ["tanh", "silu"])
@pytest.mark.parametrize("probabilistic, heads", [(True, ()), (True, ("reward",)), (False, ("reward",))])
def test_ts_rollout_equals_step_fn_trajectory_sampling(probabilistic, heads, nonlinearity):
    """The planner's TS path draws the same noise as step_fn's "ts" propagation (one seeded generator,
    the same draws in the same order) and so gives the same paths, each row on its member, and the same
    reward-head predictions; model_scorer plans on it (the same returns as stepping by hand)."""
    from motorlab.dynamics.planner_rewards import Task

    rng = np.random.default_rng(3)
    torch.manual_seed(3)
    k = 4
    model = ForwardModel(8, 2, members=k, probabilistic=probabilistic, heads=heads, nonlinearity=nonlinearity)
    model.fit_normalizers(rng.normal(1, 3, (200, 8)), rng.uniform(-1, 1, (200, 2)),
                          rng.normal(1, 3, (200, 8)) + rng.normal(0, 0.1, (200, 8)), rng.normal(-2, 5, 200))
    with torch.no_grad():  # members that differ, variances well inside their bounds and at them
        for p in model.parameters():
            p.add_(0.2 * torch.randn_like(p))
    # 8 candidates, each as k particles (row i on member i % k), as model_scorer lays them out
    s = torch.as_tensor(rng.normal(1, 3, (8, 8)), dtype=torch.float32).repeat_interleave(k, 0)
    plans = torch.as_tensor(rng.uniform(-1, 1, (8, 6, 2)), dtype=torch.float32).repeat_interleave(k, 0)
    step = model.step_fn("ts", torch.Generator().manual_seed(7))
    path, rewards = [s], []
    for t in range(6):
        next_states, r, _ = step(path[-1], plans[:, t])
        path.append(next_states)
        rewards.append(r)
    path = torch.stack(path, 1)

    learned = "reward" in heads
    fast = model.ts_rollout(torch.Generator().manual_seed(7), reward=learned)(s, plans)
    fast_path, fast_rewards = fast if learned else (fast, None)
    assert fast_path.shape == (32, 7, 8)
    # float32 sums in another order, compounding over 6 steps through the members: on some CPUs one element
    # in ~2,000 drifts past 1e-4 (absolute); a wrong draw or member would differ by the noise itself (~0.1-1)
    rtol = 1e-4 if nonlinearity == "silu" else 1e-5
    atol = 1e-4 * max(1.0, float(path.abs().max()))
    torch.testing.assert_close(fast_path, path, rtol=rtol, atol=atol)
    if learned:
        torch.testing.assert_close(fast_rewards, torch.stack(rewards, 1), rtol=rtol, atol=atol)
    if probabilistic:  # the draws differ between particles of one member: the noise is there
        assert not torch.allclose(fast_path[::k, 1], model.ts_rollout(None)(s, plans)[::k, 1])

    goals = torch.zeros(32, 0)
    task = Task(None, None, "learned", "none") if learned else \
        Task(lambda s0, a, s1, g: -s1.square().sum(-1), None, "builtin", "none")
    score = model_scorer(model, task, propagation="ts", generator=torch.Generator().manual_seed(7))
    expected = (torch.stack(rewards, 1) if learned else -path[:, 1:].square().sum(-1)).sum(1)
    torch.testing.assert_close(score(s[::k], plans[::k], goals[::k]),
                               expected.reshape(-1, k).mean(1), rtol=1e-4, atol=1e-3)


def test_fast_rollout_refuses_what_it_does_not_cover():
    with pytest.raises(MotorlabError, match="reward head"):
        ForwardModel(4, 1, members=2).fast_rollout(reward=True)
    with pytest.raises(MotorlabError, match="reward head"):
        ForwardModel(4, 1, members=2, probabilistic=True).ts_rollout(reward=True)


def test_damaged_model_json_is_checked_against_the_weights_before_allocating(reacher_data, tmp_path):
    """A model.json whose sizes were edited (a width of 10^12 would ask torch for terabytes) is
    refused from the weights file's header, before any tensor is made."""
    import json

    model, _ = fit_model(reacher_data, epochs=1, batch_size=500, progress=False)
    model.save(tmp_path)
    doc = json.loads((tmp_path / "model.json").read_text())
    for field, value, message in (("hidden", [10**12], "does not match model.safetensors"),
                                  ("members", 10**9, "does not match model.safetensors"),
                                  ("hidden", [0], "sizes must be positive"),
                                  ("state_size", "eight", "not a motorlab forward model")):
        broken = json.loads(json.dumps(doc))
        broken["architecture"][field] = value
        (tmp_path / "model.json").write_text(json.dumps(broken))
        with pytest.raises(MotorlabError, match=message):
            load_model(tmp_path)
    broken = json.loads(json.dumps(doc))
    broken["state_labels"] = ["x"]
    (tmp_path / "model.json").write_text(json.dumps(broken))
    with pytest.raises(MotorlabError, match="state_labels should be a list of 8 names"):
        load_model(tmp_path)
