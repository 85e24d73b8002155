"""The env catalogue (motorlab.envs.catalog): the bundled families' facts, a user's env declaring
the same facts (register_env, or its class's metadata["motorlab"]), evaluation, PID and reports
honouring them, and no env-id prefix test left outside the catalogue."""

from __future__ import annotations

import re
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import pytest

import motorlab
from motorlab.envs import EnvConfig, catalog, early_end_label, max_return
from motorlab.envs.catalog import SUCCESS_KEYS, facts, register_env
from motorlab.errors import MotorlabError
from tests.helpers import assert_ok, read_summary, run_here

pytestmark = pytest.mark.fast

PACKAGE = Path(motorlab.__file__).parent


@pytest.fixture(autouse=True)
def clean_catalogue():
    """Each test's declarations and Gymnasium ids are dropped afterwards."""
    exact, patterns, ids = dict(catalog._EXACT), list(catalog._PATTERNS), set(gym.registry)
    yield
    catalog._EXACT.clear()
    catalog._EXACT.update(exact)
    catalog._PATTERNS[:] = patterns
    for name in set(gym.registry) - ids:
        del gym.registry[name]


# ---- the bundled families -----------------------------------------------------------------------

@pytest.mark.parametrize("env_id, early_end, mode, keys, extra", [
    ("InvertedPendulum-v5", "falls", "any", SUCCESS_KEYS, None),
    ("InvertedDoublePendulum-v5", "falls", "any", SUCCESS_KEYS, None),
    ("Hopper-v5", "falls", "any", SUCCESS_KEYS, None),
    ("Walker2d-v5", "falls", "any", SUCCESS_KEYS, None),
    ("Humanoid-v5", "falls", "any", SUCCESS_KEYS, None),
    ("HumanoidStandup-v5", "ended early", "any", SUCCESS_KEYS, None),
    ("Ant-v5", "falls", "any", SUCCESS_KEYS, None),
    ("Reacher-v5", "ended early", "any", SUCCESS_KEYS, None),
    ("Pusher-v5", "ended early", "any", SUCCESS_KEYS, None),
    ("myoLegWalk-v0", "falls", "final", ("solved",), "myosuite"),
    ("myoLegRoughTerrainWalk-v0", "falls", "final", ("solved",), "myosuite"),
    ("myoHandReorient8-v0", "ended early", "any", ("solved",), "myosuite"),
    ("myoElbowPose1D6MRandom-v0", "ended early", "any", ("solved",), "myosuite"),
    ("Upkie-PyBullet-Pendulum", "falls", "any", ("success",), "upkie"),
    ("PointMaze_UMaze-v3", "ended early", "any", SUCCESS_KEYS, "robotics"),
    ("AntMaze_UMaze-v5", "ended early", "any", SUCCESS_KEYS, "robotics"),
    ("CartPole-v1", "ended early", "any", SUCCESS_KEYS, None),
])
def test_bundled_families(env_id, early_end, mode, keys, extra):
    f = facts(env_id)
    assert (f.early_end, f.success_mode, f.success_keys, f.extra) == (early_end, mode, keys, extra)
    assert early_end_label(env_id) == early_end


def test_bundled_specifics():
    assert facts("InvertedPendulum-v5").max_return == "time_limit" and max_return("InvertedPendulum-v5") == 1000
    assert facts("InvertedPendulum-v4").pid_gains["kp"] == (1.0, 20.0, 0.0, 0.0)
    assert facts("Upkie-Spine-Pendulum").pid_gains["kp"] == (10.0, 0.3, 0.3, 0.5)
    assert facts("Reacher-v5").pid_gains is None and facts("Reacher-v4").state_layout == "reacher"
    assert facts("Reacher-v5").closed_form == "reacher" and facts("Pusher-v5").state_layout == "observation"
    v5, v4 = ({p.layout: p.reward for p in facts(i).planning} for i in ("Reacher-v5", "Reacher-v4"))
    assert v5 == {"reacher": "motorlab.dynamics.planner_rewards:reacher_v5", "observation":
                  "motorlab.dynamics.planner_rewards:reacher_obs_v5"}
    assert v4["observation"].endswith("reacher_obs_v4")  # v4 scores the state before the step
    assert facts("InvertedPendulum-v5").planning[0].termination.endswith("inverted_pendulum_rail_end")
    assert facts("FetchReach-v4").broken and not facts("AdroitHandDoor-v1").broken
    assert facts("mypkg.envs:Hopper-v5").falls  # MODULE:ID is looked up by its id
    assert facts("NoSuch-v0") == catalog.DEFAULT and facts("NoSuch-v0").planner == {}


# ---- a user's env declares its facts ------------------------------------------------------------

def test_register_env_exact_and_pattern():
    declared = register_env("Mine-v0", falls=True, pid_gains={"kp": [1, 2]}, planner={"horizon": 4})
    assert facts("Mine-v0") == declared and declared.early_end == "falls" and declared.pid_gains["kp"] == (1.0, 2.0)
    assert facts("Mine-v0").planner["horizon"] == 4 and facts("Mine-v1") == catalog.DEFAULT
    register_env("Mine-*", success_key="done")
    assert facts("Mine-v1").success_keys == ("done",) and facts("Mine-v0").success_keys == SUCCESS_KEYS
    # a user's pattern is checked before the bundled families; an exact id keeps its family's facts
    register_env("Hopper-v9*", falls=False)
    assert not facts("Hopper-v9").falls and facts("Hopper-v5").falls
    register_env("Reacher-v5", camera="side")
    assert facts("Reacher-v5").camera == "side" and facts("Reacher-v5").state_layout == "reacher"
    assert facts("Reacher-v5").planning  # its builtin rewards stay


def test_the_loop_takes_an_envs_model_and_planner_defaults_and_the_user_overrides_them():
    from motorlab.kinds.planning import MbrlSettings

    register_env("Pendulum-v1", model={"hidden": [32, 32, 32], "epochs": 7}, planner={"horizon": 9},
                 loop={"collect_steps": 50})
    plain = MbrlSettings(env="Pendulum-v1")
    assert (plain.hidden, plain.epochs, plain.horizon, plain.collect_steps) == ([32, 32, 32], 7, 9, 50)
    given = MbrlSettings(env="Pendulum-v1", hidden=[16], horizon=3, collect_steps=20)
    assert (given.hidden, given.epochs, given.horizon, given.collect_steps) == ([16], 7, 3, 20)


@pytest.mark.parametrize("facts_, fragment", [
    ({"fall": True}, "unknown env fact 'fall'"), ({"success_mode": "last"}, "any or final"),
    ({"pid_gains": {"kx": [1]}}, "kp, ki and kd"), ({"planner": {"horizn": 3}}, "did you mean horizon"),
    ({"model": {"hiden": [8]}}, "did you mean hidden"), ({"loop": {"collect_step": 8}}, "did you mean collect_steps"),
    ({"max_return": "best"}, "time_limit"),
])
def test_register_env_refuses_wrong_facts_in_one_line(facts_, fragment):
    with pytest.raises(MotorlabError, match=re.escape(fragment)) as e:
        register_env("Mine-v0", **facts_)
    assert "\n" not in str(e.value)


def test_metadata_facts_and_evaluation_honours_them():
    from motorlab.evaluation import evaluate, success_by, success_mode
    from motorlab.policies import load_policy
    from motorlab.user_modules import import_modules

    import_modules(["userpkg.drift"])  # as --import does: the worker processes import it too
    f = facts("CatalogDrift-v0")
    assert (f.falls, f.success_key, f.success_mode, f.max_return) == (True, "reached", "final", 30)
    assert early_end_label("CatalogDrift-v0") == "falls" and early_end_label("CatalogPlain-v0") == "ended early"
    cfg, plain = EnvConfig(id="CatalogDrift-v0"), EnvConfig(id="CatalogPlain-v0")
    assert success_mode(cfg) == "final" and max_return(cfg.id) == 30 and max_return(plain.id) is None
    env = gym.make("CatalogDrift-v0")
    policy = load_policy("zero", env, cfg.id)
    env.close()
    for workers in (1, 2):  # the worker processes read the same key
        result = evaluate(policy, cfg, episodes=4, seed=0, workers=workers)
        assert result.success_key == "reached" and not result.success.any()  # the point drifted away
        assert result.falls == 4
    assert success_by(cfg, "reached") == '"reached" at the final step'
    # the same env without the facts: the usual keys (info["solved"]), at any step
    result = evaluate(policy, plain, episodes=2, seed=0, workers=1)
    assert result.success_key == "solved" and result.success.all()
    # register_env beats the metadata
    register_env("CatalogDrift-v0", falls=False)
    assert early_end_label("CatalogDrift-v0") == "ended early"


def test_planner_reward_declared_for_a_user_env(tmp_path, monkeypatch):
    from motorlab.dynamics.planner_rewards import UserFunction, builtin_envs, resolve_task

    (tmp_path / "catalog_task.py").write_text(textwrap.dedent("""
        def reward(obs, action, next_obs):
            return -next_obs[..., 0].abs()

        def out(obs, action, next_obs):
            return next_obs[..., 0].abs() > 1
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    register_env("CatalogArm-v0", reward="catalog_task:reward", termination="catalog_task:out")
    assert "CatalogArm-v0" in builtin_envs("observation") and builtin_envs()[:2] == ["Reacher-v5", "Reacher-v4"]
    task = resolve_task("CatalogArm-v0", "observation", state_size=2, action_size=1)
    assert (task.reward_source, task.termination_source) == ("builtin", "builtin")
    assert isinstance(task.reward, UserFunction) and isinstance(task.termination, UserFunction)
    register_env("CatalogArm-v1", reward="catalog_task:nothing_here")
    with pytest.raises(MotorlabError, match="has no 'nothing_here'"):
        resolve_task("CatalogArm-v1", "observation", state_size=2, action_size=1)


USER_MODULE = '''
"""A user's env module: registers CatalogCart-v0 and declares its facts."""
import gymnasium as gym
import numpy as np

from motorlab.envs.catalog import register_env


class Cart(gym.Env):
    metadata = {"render_modes": []}
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    dt = 0.1

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.v = float(self.np_random.uniform(-0.5, 0.5)), 0.0
        return np.array([self.x, self.v]), {}

    def step(self, action):
        self.v += 0.1 * (float(np.clip(action[0], -1, 1)) + 0.5)  # drifts right unless pushed back
        self.x += 0.1 * self.v
        return np.array([self.x, self.v]), 1.0, abs(self.x) > 1, False, {}


gym.register("CatalogCart-v0", entry_point=Cart, max_episode_steps=50)
register_env("CatalogCart-v0", falls=True, pid_gains={"kp": [-2.0, -2.0]})
'''


def test_pid_uses_the_gains_a_user_module_declares(tmp_path, monkeypatch):
    (tmp_path / "catalog_cart.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    proc = run_here("--import", "catalog_cart", "evaluate", "pid", "--env", "CatalogCart-v0", "--episodes", "3",
                    "--workers", "1", "--out", tmp_path / "pid")
    assert_ok(proc)
    summary = read_summary(tmp_path / "pid")
    assert summary["episode_length_mean"] == 50 and summary["falls"] == 0  # the declared gains hold it
    assert "falls" in proc.stdout  # the report's column: an early end of this env is a fall
    proc = run_here("--import", "catalog_cart", "evaluate", "zero", "--env", "CatalogCart-v0", "--episodes", "3",
                    "--workers", "1", "--out", tmp_path / "zero")
    assert_ok(proc)
    assert read_summary(tmp_path / "zero")["falls"] == 3
    sys.modules.pop("catalog_cart", None)


# ---- no env-id prefix test outside the catalogue ------------------------------------------------

# The modules that tested env-id prefixes before the catalogue, and what they tested with
FORMER = ["envs/__init__.py", "evaluation/rollouts.py", "evaluation/pool.py", "dynamics/collection.py",
          "dynamics/state.py", "dynamics/planner_rewards.py", "controllers/pid.py", "report/video.py"]
FAMILIES = ("Reacher", "Inverted", "Pusher", "myo", "Upkie", "Cookie", "Hopper", "Walker", "Humanoid", "Ant",
            "Fetch", "PointMaze", "AntMaze", "Hand", "Adroit", "Franka")
PREFIX_TEST = re.compile(r"startswith\(\s*(?:\"(?:%s)|[A-Z_]*(?:PREFIX|FALL|ALIVE|BROKEN|GAINS))" % "|".join(FAMILIES))


@pytest.mark.parametrize("module", FORMER)
def test_former_prefix_tests_are_gone(module):
    source = (PACKAGE / module).read_text()
    assert not PREFIX_TEST.search(source), module
    assert not re.search(r"re\.compile\(r?\"\^?(?:%s)" % "|".join(FAMILIES), source), module
    assert not re.search(r"^register\(\"", source, re.MULTILINE), module  # per-id tables: in the catalogue
    assert not re.search(r"_(?:ALIVE_REWARD|FALL)_PREFIXES|ROBOTICS_(?:PREFIXES|BROKEN)|DEFAULT_GAINS|_STATE_SUCCESS",
                         source), module


def test_no_family_literal_in_a_prefix_test_anywhere():
    offenders = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
                 if p.name != "catalog.py" and re.search(r"startswith\(\s*\(?\"(?:%s)" % "|".join(FAMILIES),
                                                         p.read_text())]
    assert not offenders
