"""Model-based control on any body: rewards from three sources, probabilistic ensembles, TS-inf,
MPPI, the collect -> refit -> evaluate loop and its resume, `dynamics check` beyond Reacher."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.model import ForwardModel, device_for
from motorlab.dynamics.train import fit_model
from motorlab.dynamics.transitions import Transitions
from motorlab.errors import MotorlabError
from motorlab.kinds.dynamics import DYNAMICS_CHECK, DYNAMICS_FIT
from motorlab.kinds.planning import MPC
from tests.helpers import USER_PACKAGES, assert_ok, assert_one_line_error, read_summary, run_cli, run_here, run_kind

IP = "InvertedPendulum-v5"
ARM = "userpkg.arm:ArmReach-v0"
USER_ENV = {"PYTHONPATH": os.pathsep.join([USER_PACKAGES, os.environ.get("PYTHONPATH", "")])}
TINY_PLAN = dict(horizon=8, population=60, iterations=2, elites=6)
# the loop on the pendulum, small enough for a test: 3 rounds of 4 episodes, 2 evaluation episodes
LOOP_ARGS = ["--rounds", "3", "--episodes-per-round", "4", "--eval-episodes", "2", "--ensemble", "3",
             "--epochs", "20", "--horizon", "8", "--population", "60", "--iterations", "2", "--elites", "6",
             "--seed", "1"]


@pytest.fixture(scope="module")
def ip_data(tmp_path_factory):
    out = tmp_path_factory.mktemp("ip-data")
    data = collect_transitions(IP, 150, workers=1, seed=0, progress=False)
    data.save(out / "transitions.npz")
    return out


@pytest.fixture(scope="module")
def ip_model(ip_data, tmp_path_factory):
    """A probabilistic 3-member ensemble with reward and termination heads, fit on random episodes."""
    out = tmp_path_factory.mktemp("ip-model")
    s = run_kind(DYNAMICS_FIT, out, transitions=str(ip_data), ensemble=3, probabilistic=True, learn_reward=True,
                 learn_termination=True, epochs=40, batch_size=256)
    return out, s


def cli(*args) -> subprocess.CompletedProcess:
    """The CLI with tests/ on PYTHONPATH: an earlier test of this process imported the user's arm
    module, and motorlab passes the modules it imported on to the processes it starts."""
    return run_cli(*args, env=USER_ENV)


def random_return(env_id: str, episodes: int, seed: int = 0) -> float:
    data = collect_transitions(env_id, episodes, workers=1, seed=seed, progress=False)
    return float(np.bincount(data.episode, weights=data.rewards).mean())


# ---- the model --------------------------------------------------------------------------------


def test_nll_ensemble_variance_grows_off_the_data():
    """Trained by Gaussian NLL on states in [-1, 1] with noise std 0.05, each member's predicted variance
    matches the noise on the data and is larger far from it; so is the members' disagreement."""
    rng = np.random.default_rng(0)
    n = 2000
    s = rng.uniform(-1, 1, (n, 1))
    a = rng.uniform(-1, 1, (n, 1))
    s2 = s + 0.3 * np.sin(3 * s) + 0.2 * a + rng.normal(0, 0.05, (n, 1))
    data = Transitions(states=s, actions=a, next_states=s2, rewards=np.zeros(n), dones=np.zeros(n, bool),
                       terminated=np.zeros(n, bool), episode=np.arange(n) // 50, goals=np.zeros((n, 0)),
                       meta={"env_id": "Toy-v0", "state_layout": "observation", "state_labels": ["x"]}).check()
    model, result = fit_model(data, epochs=50, hidden=(32, 32), ensemble=4, lr=5e-3, batch_size=250,
                              probabilistic=True, progress=False, threads=1)
    assert result["valid_nll"] is not None

    def variance(x: float) -> tuple[float, float]:
        states, actions = torch.full((64, 1), x), torch.linspace(-1, 1, 64)[:, None]
        with torch.no_grad():
            _, logvar, _ = model.split(model(states, actions))
        real = logvar.exp() * model.delta_norm.std ** 2  # back to state units
        return float(real.mean()), float(model.disagreement(states, actions).mean())

    on_var, on_spread = variance(0.0)
    off_var, off_spread = variance(4.0)
    assert 0.5 * 0.05 ** 2 < on_var < 2 * 0.05 ** 2  # the noise it was trained on
    assert off_var > 3 * on_var
    assert off_spread > 3 * on_spread


def test_trajectory_sampling_keeps_each_particle_on_its_member():
    """TS-inf: row i always steps with member i % K (deterministic members: exactly that member's mean)."""
    torch.manual_seed(0)
    model = ForwardModel(4, 1, (16,), members=3).eval()
    states, actions = torch.randn(6, 4), torch.randn(6, 1)
    step = model.step_fn("ts")
    next_states, reward, end = step(states, actions)
    assert reward is None and end is None
    with torch.no_grad():
        each = model(states, actions)  # (K, 6, S): every member on every row
    for i in range(6):
        expected = states[i] + model.delta_norm.inverse(each[i % 3, i])
        torch.testing.assert_close(next_states[i], expected)
    mean_next, _, _ = model.step_fn("mean")(states, actions)
    torch.testing.assert_close(mean_next, model.predict(states, actions))


def test_a_model_without_heads_loads_as_before_and_heads_round_trip(ip_model, tmp_path):
    from motorlab.dynamics.model import load_model

    folder, summary = ip_model
    model = load_model(folder)
    assert model.probabilistic and model.heads == ("reward", "termination")
    assert summary["heads"] == ["reward", "termination"] and summary["valid_termination_accuracy"] > 0.9
    plain = ForwardModel(4, 1, members=2, meta={"env_id": IP, "state_layout": "observation"})
    plain.save(tmp_path)
    arch = json.loads((tmp_path / "model.json").read_text())
    del arch["architecture"]["probabilistic"], arch["architecture"]["heads"]  # as models were written before
    (tmp_path / "model.json").write_text(json.dumps(arch))
    old = load_model(tmp_path)
    assert not old.probabilistic and old.heads == () and old.plain


def test_device_auto_is_the_cpu_without_a_gpu_and_a_missing_gpu_is_one_line():
    if torch.cuda.is_available():
        assert device_for("auto").type == "cuda"
    else:
        assert device_for("auto").type == "cpu"
        with pytest.raises(MotorlabError, match="torch sees no CUDA GPU here"):
            device_for("cuda")
    with pytest.raises(MotorlabError, match="not a torch device"):
        device_for("gpu0")


# ---- rewards from three sources ------------------------------------------------------------------


@pytest.mark.parametrize("reward, termination", [("builtin", "auto"), ("learned", "learned")])
def test_mpc_with_a_builtin_or_learned_reward_balances_longer_than_random(ip_model, tmp_path, reward, termination):
    folder, _ = ip_model
    s = run_kind(MPC, tmp_path, env=IP, model=str(folder), episodes=3, reward=reward, termination=termination,
                 **TINY_PLAN)
    assert s["reward_source"] == reward
    assert s["termination_source"] == ("builtin" if reward == "builtin" else "learned")
    assert s["disagreement_mean"] > 0  # three members: their disagreement is reported, step by step
    steps, returns = (np.load(tmp_path / "episodes.npz")[k] for k in ("disagreement", "returns"))
    # the pendulum pays 1 a step, but 0 for the step it falls on
    assert returns.sum() <= len(steps) <= returns.sum() + len(returns)
    assert np.isclose(steps.mean(), s["disagreement_mean"])
    assert s["final_distance_mean"] is None  # no fingertip in the pendulum's state
    assert s["return_mean"] > 3 * random_return(IP, 20)


def test_ts_propagation_with_particles_and_mppi_plan_the_pendulum(ip_model, tmp_path):
    folder, _ = ip_model
    s = run_kind(MPC, tmp_path, env=IP, model=str(folder), episodes=2, reward="builtin", propagation="ts",
                 particles=3, optimizer="mppi", horizon=8, population=60, iterations=2)
    assert s["propagation"] == "ts" and s["particles"] == 3 and s["temperature"] == 0.5 and s["elites"] is None
    assert s["return_mean"] > 3 * random_return(IP, 20)


@pytest.fixture(scope="module")
def arm_model(tmp_path_factory):
    """A model of the user's arm (tests/userpkg/arm.py) with a learned reward head."""
    from motorlab import user_modules

    out = tmp_path_factory.mktemp("arm")
    user_modules.import_modules(["userpkg.arm"])
    data = collect_transitions(ARM, 60, workers=1, seed=0, progress=False)
    data.save(out / "data" / "transitions.npz")
    run_kind(DYNAMICS_FIT, out / "model", transitions=str(out / "data"), ensemble=2, learn_reward=True, epochs=40)
    return out / "model"


def test_a_user_reward_function_and_a_learned_reward_plan_the_users_arm(arm_model, tmp_path):
    random = random_return(ARM, 10)
    user = run_kind(MPC, tmp_path / "user", env=ARM, model=str(arm_model), episodes=2,
                    reward="userpkg.arm_reward:reward", **TINY_PLAN)
    learned = run_kind(MPC, tmp_path / "learned", env=ARM, model=str(arm_model), episodes=2, reward="auto",
                       **TINY_PLAN)
    assert user["reward_source"] == "userpkg.arm_reward:reward" and learned["reward_source"] == "learned"
    assert user["termination_source"] == "none"
    # ArmReach pays minus the distance to the target every step: planning gets closer than flailing
    assert user["return_mean"] > random + 5
    assert learned["return_mean"] > random + 5


def test_bad_rewards_and_an_env_without_one_are_one_line_errors(arm_model, tmp_path):
    # in this process (run_here): what each command answers, not a process start (7 of them: ~20 s)
    done = tmp_path / "done"
    assert_ok(run_here("mpc", ARM, "--model", arm_model, "--episodes", "1", "--horizon", "3", "--population", "20",
                  "--iterations", "1", "--elites", "2", "--reward", "userpkg.arm_reward:reward", "--out", done))
    before = (done / "summary.json").read_bytes()
    wrong_shape = run_here("mpc", ARM, "--model", arm_model, "--reward", "userpkg.arm_reward:keepdim_reward",
                      "--out", done)
    assert_one_line_error(wrong_shape, "userpkg.arm_reward:keepdim_reward")
    wrong_signature = run_here("mpc", ARM, "--model", arm_model, "--reward", "userpkg.arm_reward:two_arguments",
                              "--out", done)
    assert_one_line_error(wrong_signature, "(obs, action, next_obs)")
    assert (done / "summary.json").read_bytes() == before  # the finished run is untouched

    # a model without a reward head, on an env motorlab has no reward for: the three ways, in one line
    plain = tmp_path / "plain"
    assert_ok(run_here("dynamics", "fit", arm_model.parent / "data", "--epochs", "2", "--out", plain))
    missing = run_here("mpc", ARM, "--model", plain, "--out", tmp_path / "x")
    assert_one_line_error(missing, "--reward builtin", "--reward MODULE:FUNCTION", "--reward learned")
    ts = run_here("mpc", ARM, "--model", arm_model, "--reward", "learned", "--propagation", "ts", "--particles", "3",
                 "--out", tmp_path / "y")
    assert_one_line_error(ts, "--particles 3", "multiple of 2")


# ---- dynamics check on any env -----------------------------------------------------------------------


def test_dynamics_check_reports_each_observation_entry_of_an_env_that_terminates(ip_model, tmp_path):
    folder, _ = ip_model
    s = run_kind(DYNAMICS_CHECK, tmp_path, model=str(folder), episodes=4)
    assert s["worst_dimension"] in ("cart position (m)", "pole angle (rad)", "cart velocity (m/s)",
                                    "pole angular velocity (rad/s)")
    assert np.isfinite(s["state_nrmse_h1"]) and s["state_nrmse_h1"] < s["state_nrmse_final"] + 1e-9
    rows = list(csv.reader((tmp_path / "error_by_dimension.csv").open()))
    assert rows[0][1:] == ["cart position (m)", "pole angle (rad)", "cart velocity (m/s)",
                           "pole angular velocity (rad/s)"]
    assert float(rows[1][1]) < 1e-6  # step 0: the true initial state
    rollouts = np.load(tmp_path / "rollouts.npz")
    assert (~rollouts["live"]).any()  # random actions topple the pendulum: episodes end at their own step
    assert (tmp_path / "plots" / "error_by_dimension.png").is_file()


# ---- the loop --------------------------------------------------------------------------------------


def curve(run_dir: Path) -> list[dict]:
    return list(csv.DictReader((Path(run_dir) / "curve.csv").open()))


DETERMINISTIC = ("round", "env_steps", "episodes", "collect_return_mean", "eval_return_mean", "valid_mse",
                 "valid_mse_first", "disagreement_mean")


@pytest.fixture(scope="module")
def loop_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("loop") / "run"
    proc = cli("mbrl", IP, *LOOP_ARGS, "--out", out)
    assert_ok(proc)
    return out


def test_the_loop_learns_the_pendulum_and_its_model_improves(loop_run):
    rows = curve(loop_run)
    assert [int(r["round"]) for r in rows] == [1, 2, 3]
    steps = [int(r["env_steps"]) for r in rows]
    assert steps == sorted(steps) and len(set(steps)) == 3
    first = [float(r["valid_mse_first"]) for r in rows]
    assert first[1] < first[0]  # the refit model predicts round 1's held-out episodes better
    evals = [float(r["eval_return_mean"]) for r in rows]
    assert evals[-1] > evals[0] and evals[-1] > 3 * float(rows[0]["collect_return_mean"])
    s = read_summary(loop_run)
    assert s["rounds"] == 3 and s["env_steps"] == steps[-1] and s["reward_source"] == "builtin"
    for r in range(3):
        folder = loop_run / "rounds" / f"{r:02d}"
        record = json.loads((folder / "round.json").read_text())
        assert record["record"]["env_steps"] == steps[r]
        assert (folder / "transitions.npz").is_file() and (folder / "model" / "model.json").is_file()
        assert record["collected_with"] == "random actions" if r == 0 else record["collected_with"]["horizon"] == 8
    assert (loop_run / "model" / "model.json").is_file() and (loop_run / "plots" / "learning_curve.png").is_file()


def test_resume_after_sigkill_mid_round_loses_nothing(loop_run, tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "motorlab", "mbrl", IP, *LOOP_ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**os.environ, **USER_ENV})
    cut = out / "rounds" / "01" / "transitions.npz"  # round 2 collected, not yet refit or evaluated
    deadline = time.monotonic() + 120
    while not cut.is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists() and not (out / "rounds" / "02").exists()

    again = cli("mbrl", IP, *LOOP_ARGS, "--out", out)  # without --resume: refused, nothing touched
    assert_one_line_error(again, "--resume")
    changed = cli("mbrl", IP, *LOOP_ARGS, "--horizon", "9", "--out", out, "--resume")
    assert_one_line_error(changed, "horizon")
    assert_ok(cli("mbrl", IP, *LOOP_ARGS, "--out", out, "--resume"))
    assert read_summary(out)["resumed_rounds"] >= 1
    resumed, whole = curve(out), curve(loop_run)
    assert [{k: r[k] for k in DETERMINISTIC} for r in resumed] == [{k: r[k] for k in DETERMINISTIC} for r in whole]


def test_the_loop_runs_on_a_users_env_with_a_users_reward(tmp_path):
    out = tmp_path / "arm"
    proc = cli("mbrl", ARM, "--reward", "userpkg.arm_reward:reward", "--rounds", "2", "--episodes-per-round", "3",
               "--eval-episodes", "1", "--ensemble", "2", "--epochs", "10", "--horizon", "5", "--population", "30",
               "--iterations", "1", "--elites", "4", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["reward_source"] == "userpkg.arm_reward:reward" and s["env_steps"] == 2 * 3 * 100
    assert "userpkg.arm" in json.loads((out / "environment.json").read_text())["imports"]


# ---- the env setting: one EnvConfig, flat on the command line ------------------------------------

TINY_LOOP = ["--rounds", "2", "--episodes-per-round", "2", "--eval-episodes", "1", "--ensemble", "2", "--epochs",
             "3", "--horizon", "5", "--population", "20", "--iterations", "1", "--elites", "4"]


def test_mbrl_and_mpc_take_env_settings_flat_and_plan_through_the_wrappers(tmp_path):
    """--history and --delay act through the env's wrappers: the loop collects from the wrapped env, its
    model's state is the stacked observations and the bundled reward reads the newest; config.toml records
    the env as EnvConfig does, and mpc plans on the model in the same env (another env: one line)."""
    import tomllib

    out = tmp_path / "loop"
    assert_ok(cli("mbrl", IP, "--history", "2", "--delay", "0.05", *TINY_LOOP, "--out", out))
    s = read_summary(out)
    assert s["env_id"] == IP and s["reward_source"] == "builtin" and s["termination_source"] == "builtin"
    env = tomllib.loads((out / "config.toml").read_text())["env"]
    assert (env["id"], env["history"], env["delay"]) == (IP, 2, 0.05)
    assert json.loads((out / "loop.json").read_text())["env"] == {"delay": 0.05, "history": 2}
    model = json.loads((out / "model" / "model.json").read_text())
    assert model["architecture"]["state_size"] == 2 * 4 and model["env"] == {"id": IP, "delay": 0.05, "history": 2}

    mpc = tmp_path / "mpc"
    assert_ok(cli("mpc", IP, "--model", out / "model", "--history", "2", "--delay", "0.05", "--episodes", "1",
                  "--horizon", "5", "--population", "20", "--iterations", "1", "--elites", "4", "--out", mpc))
    assert tomllib.loads((mpc / "config.toml").read_text())["env"]["history"] == 2
    assert read_summary(mpc)["reward_source"] == "builtin"
    assert_one_line_error(run_here("mpc", IP, "--model", out / "model", "--out", tmp_path / "bare"),
                          "predicts 8 state entries", "plan on the env it was fit on", "history 2")
    assert not (tmp_path / "bare").exists()


def test_the_builtin_reward_reads_the_newest_of_stacked_observations():
    """Under --history the bundled reward (written for one observation) equals the env's own reward."""
    from motorlab.dynamics.planner_rewards import resolve_task
    from motorlab.envs import EnvConfig

    for env_id in ("Reacher-v5", IP):
        data = collect_transitions(EnvConfig(id=env_id, history=3), 3, workers=1, seed=0, progress=False)
        size = data.states.shape[1]
        task = resolve_task(env_id, "observation", size, data.actions.shape[1], frames=3)
        s, a, n = (torch.as_tensor(x) for x in (data.states, data.actions, data.next_states))
        goal = torch.zeros(len(s), 0, dtype=s.dtype)
        np.testing.assert_allclose(task.reward(s, a, n, goal).numpy(), data.rewards, atol=1e-9)
        if task.termination is not None:
            np.testing.assert_array_equal(task.termination(s, a, n, goal).numpy(), data.terminated)
    # synergy actions (--sar): the bundled reward's control cost is on the env's own actions
    with pytest.raises(MotorlabError, match="--reward builtin: Reacher-v5's bundled reward charges the env's own"):
        resolve_task("Reacher-v5", "observation", 10, 2, synergies=True)
    assert resolve_task("Reacher-v5", "observation", 10, 2, synergies=True,
                        learned=frozenset({"reward"})).reward_source == "learned"


def test_planning_refuses_env_settings_it_cannot_honour_in_one_line(tmp_path):
    from motorlab.kinds.planning import MBRL

    # reward shaping and a success rule: mpc and mbrl report the env's own return, and --reward is the planner's
    with pytest.raises(MotorlabError, match=r"^env\.reward 'alive': mbrl reports the env's own return"):
        MBRL.make(env={"id": IP, "reward": "alive"})
    with pytest.raises(MotorlabError, match=r"^env\.success 'final': mpc reports returns"):
        MPC.make(env=IP, model="m", success="final")
    assert MPC.make(env=IP, model="m", reward="learned").reward == "learned"  # the planner's own
    # a layout of one observation under --history, and no env id: one line, nothing written
    assert_one_line_error(run_here("mbrl", "Reacher-v5", "--state", "reacher", "--history", "2", *TINY_LOOP,
                                   "--out", tmp_path / "a"), "--history 2", "--state observation")
    assert_one_line_error(run_here("mbrl", *TINY_LOOP, "--out", tmp_path / "b"), "Missing argument 'ENV'")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_config_toml_and_loop_json_written_before_still_load(tmp_path):
    """Run folders written before the env was an EnvConfig: `env = "InvertedPendulum-v5"` in config.toml
    (the planner's `reward` beside it stays the planner's), and a loop.json without the env's settings
    resumes with the same (bare) env."""
    import tomllib
    from dataclasses import asdict

    from motorlab.envs import EnvConfig
    from motorlab.kinds.planning import MBRL
    from motorlab.planning.mbrl import LOOP_JSON, _comparable, check_resumable

    old = f'env = "{IP}"\nmodel = "runs/m"\nreward = "builtin"\nepisodes = 5\nhorizon = 15\n'
    mpc = MPC.validate(tomllib.loads(old))
    assert mpc.env == EnvConfig(id=IP) and mpc.reward == "builtin" and mpc.model == "runs/m"
    assert MPC.describe(mpc) == f"MPC (cem) on runs/m · {IP}"
    loop = MBRL.validate(tomllib.loads(f'env = "{IP}"\nrounds = 6\nreward = "auto"\n'))
    assert loop.env == EnvConfig(id=IP) and loop.rounds == 6
    plan = loop.loop_plan()
    before = {k: v for k, v in _comparable(asdict(plan)).items() if k != "env"}  # what loop.json held before
    (tmp_path / LOOP_JSON).write_text(json.dumps(before))
    check_resumable(tmp_path, plan, resume=True)  # the same settings: no complaint
    with pytest.raises(MotorlabError, match="history"):
        check_resumable(tmp_path, MBRL.make(env=IP, rounds=6, history=2).loop_plan(), resume=True)


def test_collect_steps_cuts_collected_episodes_and_the_catalogue_sets_it_for_the_pendulum(tmp_path):
    """--collect-steps ends each collected episode (truncated, not terminated) after that many steps, so
    the model is refit that often; evaluation episodes still run to the time limit. The pendulum's
    catalogue entry cuts at 200, and the user's setting wins."""
    from motorlab.dynamics.transitions import load_transitions
    from motorlab.kinds.planning import MBRL

    assert MBRL.make(env=IP).collect_steps == 200 and MBRL.make(env=IP, collect_steps=50).collect_steps == 50
    assert MBRL.make(env="Reacher-v5").collect_steps is None
    cut = 6  # random pendulum episodes mostly last longer (~5-30 steps), so some are cut, some fall first
    s = run_kind(MBRL, tmp_path / "run", rounds=2, episodes_per_round=6, eval_episodes=1, collect_steps=cut,
                 ensemble=2, epochs=5, seed=3, **TINY_PLAN, env=IP)
    lengths, ends = [], []
    for r in range(2):
        data = load_transitions(tmp_path / "run" / "rounds" / f"{r:02d}" / "transitions.npz")
        for e in np.unique(data.episode):
            rows = data.episode == e
            lengths.append(int(rows.sum()))
            ends.append((bool(data.terminated[rows][-1]), bool(data.dones[rows][-1])))  # (terminated, ended)
    assert max(lengths) == cut and s["env_steps"] == sum(lengths) <= 2 * 6 * cut
    assert all(ended for _, ended in ends)
    # an episode that did not fall was cut at exactly `cut` steps; falls stay falls
    assert all(n == cut for n, (terminated, _) in zip(lengths, ends) if not terminated)
    assert any(not terminated for terminated, _ in ends) and any(terminated for terminated, _ in ends)
    record = json.loads((tmp_path / "run" / "rounds" / "01" / "round.json").read_text())["record"]
    assert record["eval_return_mean"] > cut  # the evaluation episode was not cut
    # the cut is the loop's way of collecting, not the env: the model records the env as given
    assert json.loads((tmp_path / "run" / "model" / "model.json").read_text())["env"] == {"id": IP}


def test_exploration_noise_widens_the_collected_actions_and_leaves_the_plan_and_evaluation_alone(tmp_path):
    """MPCPolicy's `explore`: Gaussian noise of that share of each action's half-range on the planned
    actions, clipped to the bounds, seeded; 0 is the plan itself. In the loop (--collect-noise) it
    changes what the later rounds collect, not how a round's model is evaluated."""
    from types import SimpleNamespace

    from motorlab.dynamics.transitions import load_transitions
    from motorlab.kinds.planning import MBRL
    from motorlab.planning.mbrl import _comparable
    from motorlab.planning.mpc import MPCPolicy

    planned = torch.tensor([[0.5, -1.9]]).repeat(4000, 1)
    planner = SimpleNamespace(plan=lambda s, g: planned.clone(), low=torch.tensor([-1.0, -2.0]),
                              high=torch.tensor([1.0, 2.0]))
    layout = SimpleNamespace(state=lambda obs: obs, goal=lambda obs: obs[:, :0])
    obs = np.zeros((4000, 3))
    np.testing.assert_array_equal(MPCPolicy(planner, layout).act(obs), planned.numpy())
    acts = MPCPolicy(planner, layout, explore=0.2, seed=5).act(obs)
    np.testing.assert_array_equal(acts, MPCPolicy(planner, layout, explore=0.2, seed=5).act(obs))
    assert (acts >= [-1, -2]).all() and (acts <= [1, 2]).all() and acts[:, 1].min() == -2  # clipped
    # the first action's noise, far from its bounds: std 0.2 x half-range 1
    assert abs((acts[:, 0] - 0.5).std() - 0.2) < 0.01 and abs((acts[:, 0] - 0.5).mean()) < 0.01
    assert (acts[:, 1] > -1.9).mean() > 0.4  # the second's, near its bound: pushed up where not clipped
    with pytest.raises(MotorlabError, match="exploration"):
        MPCPolicy(planner, layout, explore=-0.1)

    runs = {}
    for noise in (0.0, 0.5):
        out = tmp_path / f"noise{noise}"
        run_kind(MBRL, out, rounds=2, episodes_per_round=3, eval_episodes=1, ensemble=2, epochs=5, seed=3,
                 collect_noise=noise, **TINY_PLAN, env=IP)
        rounds = [json.loads((out / "rounds" / f"{r:02d}" / "round.json").read_text()) for r in range(2)]
        runs[noise] = rounds, load_transitions(out / "rounds" / "01" / "transitions.npz")
    (quiet, quiet_data), (noisy, noisy_data) = runs[0.0], runs[0.5]
    # round 1 collects random actions and fits the same model either way: its evaluation is the same
    assert quiet[0]["record"]["eval_return_mean"] == noisy[0]["record"]["eval_return_mean"]
    # round 2 collected with that model's planner, with noise on its actions
    assert noisy[1]["collected_with"]["explore"] == 0.5 and "explore" not in quiet[1]["collected_with"]
    assert noisy[1]["collected_with"]["seed"] == 3 * 1000 + 1  # the planner's seed in round 2 (round.json said 3000)
    n = min(len(quiet_data.actions), len(noisy_data.actions))
    assert not np.allclose(quiet_data.actions[:n], noisy_data.actions[:n])
    # a loop written before the setting (loop.json without it) resumes at its default; so does one
    # written before --nll-beta
    assert "collect_noise" not in _comparable(asdict(MBRL.make(env=IP).loop_plan()))
    assert _comparable(asdict(MBRL.make(env=IP, collect_noise=0.5).loop_plan()))["collect_noise"] == 0.5
    assert "nll_beta" not in _comparable(asdict(MBRL.make(env=IP).loop_plan()))["fit"]
    assert _comparable(asdict(MBRL.make(env=IP, nll_beta=0.5).loop_plan()))["fit"]["nll_beta"] == 0.5


@settings(max_examples=200, deadline=None)
@given(rounds=st.integers(1, 30), every=st.integers(1, 12), per_round=st.integers(1, 400),
       budget=st.one_of(st.none(), st.integers(1, 6000)))
def test_eval_every_always_evaluates_the_round_that_ends_the_loop(rounds, every, per_round, budget):
    """Whatever the cap, the budget and --eval-every, the loop's last round is evaluated (its return is
    the loop's) and the others exactly on multiples of eval_every: walked as run_loop walks them."""
    from motorlab.kinds.planning import MBRL
    from motorlab.planning.mbrl import evaluates, is_last_round

    plan = replace(MBRL.make(env=IP).loop_plan(), rounds=rounds, eval_every=every, max_env_steps=budget)
    walked = []
    for r in range(rounds):
        steps = (r + 1) * per_round
        walked.append(evaluates(plan, r, steps))
        if is_last_round(plan, r, steps):
            break
    assert walked[-1]
    assert walked[:-1] == [(r + 1) % every == 0 for r in range(len(walked) - 1)]
    assert len(walked) == (rounds if budget is None else min(rounds, -(-budget // per_round)))


def test_eval_every_leaves_the_models_alone_and_a_resume_may_change_it(tmp_path):
    """Evaluating every 2nd round (and the last) skips round 1's evaluation and changes nothing the
    rounds learn: the same collected returns, held-out errors and evaluated returns as every round's."""
    from motorlab.kinds.planning import MBRL
    from motorlab.planning.mbrl import _comparable

    kept = {}
    for every in (1, 2):
        out = tmp_path / f"every{every}"
        s = run_kind(MBRL, out, rounds=3, episodes_per_round=3, eval_episodes=1, ensemble=2, epochs=5, seed=4,
                     eval_every=every, **TINY_PLAN, env=IP)
        kept[every] = curve(out), s
    (whole, s1), (sparse, s2) = kept[1], kept[2]
    assert [r["eval_return_mean"] for r in sparse][0] == ""  # round 1: not evaluated
    assert all(r["eval_return_mean"] != "" for r in sparse[1:])  # round 2 (every 2nd) and round 3 (the last)
    same = ("env_steps", "collect_return_mean", "valid_mse", "valid_mse_first")
    assert [{k: r[k] for k in same} for r in whole] == [{k: r[k] for k in same} for r in sparse]
    assert [r["eval_return_mean"] for r in whole[1:]] == [r["eval_return_mean"] for r in sparse[1:]]
    assert s1["final_return_mean"] == s2["final_return_mean"]
    assert "eval_every" not in _comparable(asdict(MBRL.make(env=IP, eval_every=3).loop_plan()))
    with pytest.raises(Exception, match="eval_every|greater"):
        MBRL.make(env=IP, eval_every=0)
