"""SynergyActionWrapper: the env receives exactly decode(z) (phi = 1) or the blend
phi*decode(z) + (1-phi)*raw (phi < 1); bad phi or a SAR for another body is a clear error."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.synergies import SynergyActionWrapper, fit_sar, load_sar, save_sar
from tests.helpers import HAND_ID, HAND_MUSCLES, assert_cli_error, run_cli

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

M, N = 6, 3  # muscles of the tiny env, synergies of its SAR


class RecordingEnv(gym.Env):
    """A tiny muscle-like env: Box(M,) actions in [0, 1]; remembers every action it gets."""

    metadata = {"render_modes": []}

    def __init__(self, m: int = M):
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(np.zeros(m, np.float32), np.ones(m, np.float32), dtype=np.float32)
        self.received: list[np.ndarray] = []
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.np_random.uniform(-1, 1, 2).astype(np.float32), {}

    def step(self, action):
        self.received.append(np.array(action, copy=True))
        self.t += 1
        obs = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        return obs, float(np.sum(action)), False, self.t >= 20, {}


@pytest.fixture(scope="module")
def sar():
    """A SAR fitted to synthetic activations: N sources mixed into M muscles, in [0, 1]."""
    rng = np.random.default_rng(0)
    sources = rng.uniform(0, 1, (400, N))
    mixing = rng.uniform(0, 1, (N, M))
    acts = np.clip(sources @ mixing / N + rng.normal(0, 0.01, (400, M)), 0, 1)
    return fit_sar(acts, n_synergies=N, method="pca-ica", seed=0)


def test_phi_one_acts_in_synergy_space(sar):
    env = SynergyActionWrapper(RecordingEnv(), sar, phi=1.0)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (N,), dtype=np.float32)
    env.reset(seed=0)
    zs = np.random.default_rng(1).uniform(-1, 1, (10, N)).astype(np.float32)
    for z in zs:
        env.step(z)
    received = np.array(env.unwrapped.received)
    assert received.shape == (10, M)
    assert received.dtype == np.float32  # the inner env's own action dtype
    np.testing.assert_allclose(received, sar.decode(zs), atol=1e-6)
    # decode is the affine map z @ W + b
    np.testing.assert_allclose(received, zs.astype(np.float64) @ sar.weight + sar.bias, atol=1e-6)


@pytest.mark.parametrize("phi", [0.66, 0.25])
def test_phi_below_one_blends_synergies_with_raw_actions(sar, phi):
    inner = RecordingEnv()
    env = SynergyActionWrapper(inner, sar, phi=phi)
    assert env.action_space.shape == (N + M,)
    np.testing.assert_array_equal(env.action_space.low, np.concatenate([-np.ones(N), inner.action_space.low]))
    np.testing.assert_array_equal(env.action_space.high, np.concatenate([np.ones(N), inner.action_space.high]))
    env.reset(seed=0)
    env.action_space.seed(3)
    actions = np.array([env.action_space.sample() for _ in range(10)])
    for a in actions:
        env.step(a)
    z, raw = actions[:, :N], actions[:, N:]
    expected = phi * sar.decode(z) + (1 - phi) * raw
    np.testing.assert_allclose(np.array(inner.received), expected, atol=1e-6)


def test_wrapper_loads_a_sar_file(sar, tmp_path):
    save_sar(sar, tmp_path / "sar.npz")
    env = SynergyActionWrapper(RecordingEnv(), tmp_path / "sar.npz", phi=1.0)
    env.reset(seed=0)
    z = np.linspace(-1, 1, N).astype(np.float32)
    env.step(z)
    np.testing.assert_allclose(env.unwrapped.received[-1], load_sar(tmp_path / "sar.npz").decode(z), atol=1e-6)


def test_sar_for_another_body_names_both_sizes(sar):
    with pytest.raises(MotorlabError) as e:
        SynergyActionWrapper(RecordingEnv(m=M - 1), sar)
    message = str(e.value)
    assert f"{M} muscles" in message and f"({M - 1},)" in message


@pytest.mark.parametrize("phi", [0.0, -1.0, 1.5, float("nan")])
def test_phi_out_of_range(sar, phi):
    with pytest.raises(MotorlabError, match="phi"):
        SynergyActionWrapper(RecordingEnv(), sar, phi=phi)


@pytest.mark.parametrize("phi", [1.0, 0.5])
def test_tiny_wrapped_env_passes_check_env(sar, phi):
    check_env(SynergyActionWrapper(RecordingEnv(), sar, phi=phi), skip_render_check=True)


# ---- on the MyoSuite hand, with the SAR MyoSuite published ----------------------------

def test_published_hand_sar_on_myosuite_passes_check_env(hand_sar):
    sar = load_sar(hand_sar)
    assert sar.n_muscles == HAND_MUSCLES
    for phi in (1.0, 0.66):
        env = make_env(EnvConfig(id=HAND_ID))
        wrapped = SynergyActionWrapper(env, sar, phi=phi)
        check_env(wrapped, skip_render_check=True)
        expected = sar.n_synergies if phi == 1.0 else sar.n_synergies + HAND_MUSCLES
        assert wrapped.action_space.shape == (expected,)
        wrapped.close()


def test_make_env_builds_the_blended_synergy_env(hand_sar):
    sar = load_sar(hand_sar)
    env = make_env(EnvConfig(id=HAND_ID, sar=str(hand_sar), phi=0.66))
    wrapper = env
    while not isinstance(wrapper, SynergyActionWrapper):
        assert isinstance(wrapper, gym.Wrapper), "make_env did not apply SynergyActionWrapper"
        wrapper = wrapper.env
    assert wrapper.phi == pytest.approx(0.66)
    assert env.action_space.shape == (sar.n_synergies + HAND_MUSCLES,)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape
    a = env.action_space.sample()
    np.testing.assert_allclose(wrapper.action(a), 0.66 * sar.decode(a[:sar.n_synergies]) + 0.34 * a[sar.n_synergies:],
                               atol=1e-6)
    obs, reward, terminated, truncated, info = env.step(a)
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    env.close()


def test_legs_sar_on_the_hand_is_a_clear_error(legs_sar):
    with pytest.raises(MotorlabError) as e:
        make_env(EnvConfig(id=HAND_ID, sar=str(legs_sar)))
    assert "80 muscles" in str(e.value) and f"({HAND_MUSCLES},)" in str(e.value)


def test_cli_train_with_legs_sar_on_the_hand(legs_sar, tmp_path):
    out = tmp_path / "out"
    proc = run_cli("train", HAND_ID, "--sar", legs_sar, "--timesteps", "100", "--no-progress", "--out", out)
    assert_cli_error(proc, "80 muscles", f"({HAND_MUSCLES},)")
    assert not (out / "summary.json").exists()


def test_cli_train_with_phi_out_of_range(hand_sar, tmp_path):
    out = tmp_path / "out"
    proc = run_cli("train", HAND_ID, "--sar", hand_sar, "--phi", "1.5", "--timesteps", "100", "--no-progress",
                   "--out", out)
    assert_cli_error(proc, "--phi")
    assert not (out / "summary.json").exists()
