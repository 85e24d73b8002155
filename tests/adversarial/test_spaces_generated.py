"""Generated spaces through train -> evaluate -> export (issue 52): an env of a user's, made of a
Hypothesis-drawn observation and action space (Box with random, infinite or degenerate bounds,
dtypes and 1-3 dimensions; Discrete with a start; MultiDiscrete; MultiBinary; Dict; Tuple;
uint8 images), either works end to end or is refused before any work: exit status 2, one line
`error: ...` naming the env's space, and no run folder content.

Commands run in this process (`run_here`); the env class is registered in-process under a fresh
id per example. Examples are bounded (derandomized) so the file stays well under a minute."""

from __future__ import annotations

import itertools
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import assert_ok, assert_one_line_error, run_here

SPACES = settings(max_examples=12, deadline=None, derandomize=True, database=None,
                  suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
EPISODE = 20  # steps per episode: the time limit every generated env registers
_ids = itertools.count()


class GeneratedEnv(gym.Env):
    """A user's env of any spaces: observations drawn from its space (seeded by reset's seed, so
    Gymnasium's checker finds it deterministic), reward 1 per step, `EPISODE` steps long, a success
    flag (info["is_success"]) at its end."""

    def __init__(self, observation_space: gym.Space, action_space: gym.Space):
        self.observation_space, self.action_space = observation_space, action_space
        self.t = 0

    def _obs(self):
        self.observation_space.seed(int(self.np_random.integers(2**31)))
        return self.observation_space.sample()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), 1.0, False, self.t >= EPISODE, {"is_success": self.t >= EPISODE}


def register(observation_space: gym.Space, action_space: gym.Space) -> str:
    """A fresh env id for these spaces, registered in this process with a time limit."""
    env_id = f"GeneratedSpaces{next(_ids)}-v0"
    gym.register(env_id, entry_point=GeneratedEnv, max_episode_steps=EPISODE,
                 kwargs={"observation_space": observation_space, "action_space": action_space})
    return env_id


# ---- spaces ---------------------------------------------------------------------------------

def shapes(max_dims: int = 3) -> st.SearchStrategy[tuple[int, ...]]:
    return st.lists(st.integers(1, 3), min_size=1, max_size=max_dims).map(tuple)


@st.composite
def boxes(draw, float_only: bool = False) -> gym.spaces.Box:
    """Boxes with random bounds: finite, infinite on either side, or degenerate (low == high)."""
    shape = draw(shapes())
    dtype = np.float32 if float_only else draw(st.sampled_from([np.float32, np.float64, np.int64]))
    if np.issubdtype(dtype, np.integer):
        low = draw(st.integers(-5, 0))
        return gym.spaces.Box(low, low + draw(st.integers(0, 5)), shape, dtype)
    low = draw(st.sampled_from([-np.inf, -10.0, -1.0, 0.0]))
    high = draw(st.sampled_from([np.inf, 10.0, 1.0, 0.0 if low == 0.0 else 1.0, low if np.isfinite(low) else 1.0]))
    return gym.spaces.Box(low, high, shape, dtype)


def images() -> st.SearchStrategy[gym.spaces.Box]:
    return st.sampled_from([(8, 8, 3), (36, 36, 1), (3, 16, 16)]).map(lambda s: gym.spaces.Box(0, 255, s, np.uint8))


def leaves() -> st.SearchStrategy[gym.Space]:
    return st.one_of(
        boxes(),
        st.builds(gym.spaces.Discrete, st.integers(2, 4), start=st.integers(-2, 2)),
        st.lists(st.integers(2, 4), min_size=1, max_size=3).map(gym.spaces.MultiDiscrete),
        st.integers(1, 4).map(gym.spaces.MultiBinary),
    )


def observation_spaces() -> st.SearchStrategy[gym.Space]:
    leaf = st.one_of(leaves(), images())
    return st.one_of(
        boxes(), leaf,
        st.dictionaries(st.sampled_from(["a", "b", "c"]), leaf, min_size=1, max_size=2).map(gym.spaces.Dict),
        leaf.map(lambda s: gym.spaces.Dict({"nested": gym.spaces.Dict({"x": s})})),
        st.lists(leaf, min_size=1, max_size=2).map(lambda s: gym.spaces.Tuple(tuple(s))),
    )


def action_spaces() -> st.SearchStrategy[gym.Space]:
    return st.one_of(leaves(), st.lists(leaves(), min_size=1, max_size=2).map(lambda s: gym.spaces.Tuple(tuple(s))))


# ---- the property ---------------------------------------------------------------------------

TRAIN = {"ppo": ["--timesteps", "64", "--set", "n_steps=32", "--set", "batch_size=32"],
         "sac": ["--timesteps", "64", "--set", "learning_starts=32", "--set", 'policy_kwargs={"net_arch":[8]}'],
         "lqr": ["--timesteps", "150"]}


def refused_before_work(proc, out: Path, *names: str) -> None:
    """One line (naming `names`), exit 2, and nothing written where the run would have gone."""
    assert_one_line_error(proc, *names)
    assert not out.exists() or not any(out.iterdir()), sorted(p.name for p in out.iterdir())


@SPACES
@given(obs=observation_spaces(), act=action_spaces(), algo=st.sampled_from(["ppo", "ppo", "sac", "lqr"]))
def test_a_generated_env_trains_evaluates_and_exports_or_is_refused_at_the_door(tmp_path_factory, obs, act, algo):
    root = tmp_path_factory.mktemp("spaces")
    env_id = register(obs, act)
    run = root / "train"
    proc = run_here("train", env_id, "--algo", algo, *TRAIN[algo], "--solve-episodes", "2", "--no-progress",
                    "--out", run)
    if proc.returncode != 0:
        refused_before_work(proc, run, env_id)
        return
    assert (run / "policy.json").is_file()
    assert_ok(run_here("evaluate", run, "--episodes", "2", "--workers", "1", "--out", root / "eval"))
    assert_ok(run_here("export", run, "--out", root / "shared"))
    assert (root / "shared" / "policy.json").is_file()
    onnx = run_here("export", run, "--onnx", "--out", root / "onnx")
    if onnx.returncode != 0:  # an LQR gain or a space ONNX cannot carry: refused before any file
        refused_before_work(onnx, root / "onnx")


@SPACES
@given(obs=observation_spaces(), act=action_spaces())
def test_a_generated_env_is_evaluated_by_a_built_in_policy_or_refused_at_the_door(tmp_path, obs, act):
    env_id = register(obs, act)
    out = tmp_path / f"eval-{env_id}"
    proc = run_here("evaluate", "random", "--env", env_id, "--episodes", "2", "--workers", "1", "--out", out)
    if proc.returncode != 0:
        refused_before_work(proc, out, env_id)
    else:
        assert out.joinpath("summary.json").is_file()


pytestmark = pytest.mark.filterwarnings("ignore")
