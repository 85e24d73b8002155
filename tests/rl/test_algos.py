"""The algorithm registry (motorlab/algos/): found from the package's files, typed on- or
off-policy, the one source of --algo's names, the presets and their help."""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys

import pytest

from motorlab import algos
from motorlab.algos import OffPolicy, OnPolicy, SB3Algorithm
from motorlab.errors import MotorlabError

pytestmark = pytest.mark.fast


def test_every_module_but_base_and_private_ones_is_one_registered_algorithm():
    modules = {m.name for m in pkgutil.iter_modules(algos.__path__) if not m.name.startswith("_")} - algos.NOT_ALGORITHMS
    registered = {name: type(a).__module__ for name, a in algos.registry().items()}
    for module in modules:
        algo = importlib.import_module(f"motorlab.algos.{module}").ALGORITHM
        assert algos.registry()[algo.name] is algo
    assert len(registered) == len(modules)
    assert set(algos.names()) == {"ppo", "sac", "td3", "lqr", "tqc", "crossq", "recurrentppo"}


@pytest.mark.parametrize("name, kind", [("ppo", OnPolicy), ("recurrentppo", OnPolicy), ("sac", OffPolicy),
                                        ("td3", OffPolicy), ("tqc", OffPolicy), ("crossq", OffPolicy)])
def test_on_and_off_policy_are_types(name, kind):
    algo = algos.get(name)
    assert isinstance(algo, kind) and algo.on_policy == (kind is OnPolicy)


def test_lqr_is_an_algorithm_but_not_sb3():
    lqr = algos.get("lqr")
    assert not isinstance(lqr, SB3Algorithm) and not lqr.sb3 and not lqr.dict_obs


def test_presets_come_from_their_algorithms():
    from motorlab.rl.config import PRESETS

    owners = {"fast": "lqr", "sb3-ppo": "ppo", "upkie-balancer": "ppo", "sb3-sac": "sac", "sar-sac": "sac",
              "sar-sac-synergy": "sac", "sar-sac-fast": "sac"}
    assert {name: PRESETS[name]["algo"] for name in owners} == owners
    assert PRESETS["sar-sac-synergy"]["hyperparams"]["learning_starts"] == 5000
    for name in PRESETS:
        assert f"{name}: " in algos.preset_help()


def test_help_texts_are_read_from_the_registry():
    from motorlab.rl.config import TrainConfig

    fields = TrainConfig.model_fields
    for name in algos.names():
        assert f"{name}: " in fields["algo"].description
    assert all(f"{p}: " in fields["preset"].description for p in algos.presets())
    assert "TQC" in fields["her"].description and "CrossQ" not in fields["her"].description
    assert "RecurrentPPO" in fields["clip_range"].description


def test_unknown_algorithm_is_one_line_with_close_matches():
    from motorlab.rl.config import TrainConfig

    with pytest.raises(MotorlabError, match=r"--algo 'tcq': unknown algorithm \(did you mean tqc\?\); algorithms: "):
        TrainConfig(algo="tcq")


@pytest.mark.parametrize("settings, fragment", [
    ({"algo": "sac", "clip_range": "0.1"}, "--clip-range applies to PPO, RecurrentPPO only"),
    ({"algo": "ppo", "her": True}, "--algo sac or --algo td3 or --algo tqc"),
    ({"algo": "lqr", "her": True}, "LQR"),
])
def test_settings_an_algorithm_refuses(settings, fragment):
    from motorlab.rl.config import TrainConfig

    with pytest.raises(MotorlabError, match=fragment):
        TrainConfig(**settings)


def test_actions_each_algorithm_fits():
    import gymnasium as gym

    from motorlab.envs import EnvConfig
    from motorlab.rl.config import TrainConfig
    from motorlab.rl.envcheck import check_actions

    discrete = gym.spaces.Discrete(2)
    check_actions(TrainConfig(algo="recurrentppo", env=EnvConfig(id="CartPole-v1")), discrete)
    with pytest.raises(MotorlabError, match="TQC needs continuous .*--algo ppo or --algo recurrentppo"):
        check_actions(TrainConfig(algo="tqc", env=EnvConfig(id="CartPole-v1")), discrete)


def test_sb3_algorithms_and_hyperparameters():
    from motorlab.rl.sb3 import ALGORITHMS, check_hyperparams

    assert set(ALGORITHMS) == {n for n, a in algos.registry().items() if a.sb3} and "lqr" not in ALGORITHMS
    assert check_hyperparams("tqc", {"top_quantiles_to_drop_per_net": 2}) == {"top_quantiles_to_drop_per_net": 2}
    with pytest.raises(MotorlabError, match="unknown hyperparameter 'n_step' for RecurrentPPO"):
        check_hyperparams("recurrentppo", {"n_step": 64})


def test_zip_modules_name_each_algorithm():
    from motorlab.export import ALGO_OF_MODULE

    assert ALGO_OF_MODULE["stable_baselines3.a2c.policies"] == "ppo"
    assert ALGO_OF_MODULE["sb3_contrib.tqc.policies"] == "tqc"
    assert ALGO_OF_MODULE["sb3_contrib.common.recurrent.policies"] == "recurrentppo"


def test_registry_and_help_import_no_torch():
    code = ("import sys; from motorlab import algos; from motorlab.rl.config import TrainConfig; algos.registry(); "
            "assert not {'torch', 'stable_baselines3', 'sb3_contrib'} & set(sys.modules), 'imported'")
    subprocess.run([sys.executable, "-c", code], check=True)
