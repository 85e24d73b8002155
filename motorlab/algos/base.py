"""What motorlab needs to know of an RL algorithm, as one frozen object per algorithm.

    Algorithm            a learner `motorlab train --algo NAME` runs: its name, one-line summary,
                         presets, the action spaces it acts in, its settings checks
      SB3Algorithm       one of Stable-Baselines3's (or sb3-contrib's) classes: the class, its policy
                         networks (names policy.json records), how an SB3 zip of it is recognised,
                         how its deterministic action is written as a torch graph (ONNX)
        OnPolicy         learns from its own fresh rollouts (PPO): evaluated between rollouts
        OffPolicy        learns from a replay buffer (SAC, TD3, ...): evaluated every 1000 steps

Each algorithm lives in its own module of this package (`ALGORITHM = ...`), found there by
`motorlab.algos.registry`. Nothing here imports torch or SB3: `motorlab --help` reads names,
summaries and presets; the SB3 classes are imported when a run needs them.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from motorlab.errors import MotorlabError

if TYPE_CHECKING:
    import gymnasium as gym


CONTINUOUS = ("Box",)
ANY_ACTIONS = ("Box", "Discrete", "MultiDiscrete", "MultiBinary")
OFF_POLICY_EVAL_EVERY = 1000  # env steps between evaluations when the settings give none


def _package() -> Any:
    """The registry (the package that imports this module), looked up when a message needs it: an
    import here would be a circle."""
    return importlib.import_module("motorlab.algos")


@dataclass(frozen=True)
class Preset:
    """Named settings under the given ones (TrainConfig fields; the algorithm's name is added)."""

    about: str  # one line, for --help
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class StateSpec:
    """A recurrent state the deployed graph takes as input and gives back (ONNX): `name` in,
    `next_<name>` out, `shape` with "batch" where the batch dimension is."""

    name: str
    shape: tuple[int | str, ...]
    description: str


def imported(path: str) -> Any:
    """`module:Name` imported (heavy modules only when asked for)."""
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Algorithm:
    """A learner motorlab trains. Subclasses say how; this base knows no network."""

    name: str  # --algo NAME
    title: str  # how messages name it: "PPO"
    summary: str  # one line for --help
    presets: dict[str, Preset] = field(default_factory=dict)
    actions: tuple[str, ...] = CONTINUOUS  # gymnasium.spaces class names it acts in
    bounded_actions: bool = False  # squashes or clips its Box actions into finite bounds, low < high
    vector_actions: bool = False  # its Box actions are one vector (a linear model's, LQR): 1-dim shape
    dict_obs: bool = False  # trains on a Dict observation kept as a Dict
    her: bool = False  # takes --her (a replay buffer whose goals can be relabelled)
    clip_range: bool = False  # takes --clip-range
    eval_cadence: str = ""  # what eval_every defaults to, in words (for --help)

    def check(self, cfg: Any) -> None:
        """Settings this algorithm refuses, in one line each."""
        if cfg.clip_range is not None and not self.clip_range:
            takes = " or ".join(f"--algo {a}" for a in _names_with("clip_range"))
            raise MotorlabError(f"--clip-range applies to {_titles_with('clip_range')} only, not {self.name}; drop "
                                f"it or use {takes}.")
        if cfg.her and not self.her:
            takes = " or ".join(f"--algo {a}" for a in _names_with("her"))
            raise MotorlabError(f"--her relabels the goals in a replay buffer of Dict observations, which {self.title} "
                                f"does not keep; use {takes}, or drop --her.")

    def learn(self, cfg: Any, run_dir: Any, monitor: Any) -> int:
        """Train to the budget and write the policy; returns env steps used. Only an algorithm that
        trains itself (LQR) has this: SB3 algorithms train in rl/sb3.py."""
        raise NotImplementedError(f"{self.name} trains in motorlab.rl.sb3")

    def acts_in(self, space: gym.Space) -> bool:
        """Whether it acts in `space`: a class it declares (`actions`), with finite bounds where it
        squashes or clips into them (`bounded_actions`), a vector where it needs one (`vector_actions`)."""
        return (type(space).__name__ in self.actions and (not self.bounded_actions or bounded(space))
                and (not self.vector_actions or len(getattr(space, "shape", ())) == 1))

    def check_actions(self, space: gym.Space, env_id: str) -> None:
        """Refuse, in one line naming the env's action space and the algorithms that do fit it, an
        action space this algorithm does not act in: the one door every training run passes
        (rl.envcheck), driven by what each algorithm declares.

        Raises:
            MotorlabError: e.g. "SAC needs Box actions with finite bounds (low < high), and X's
                actions are Box(-inf, inf, (2,), float32); use --algo ppo."
        """
        if self.acts_in(space):
            return
        fitting = [a.name for a in _package().registry().values() if a.acts_in(space)]
        box = isinstance(space, _box_class())  # a Box: its shape or bounds are what does not fit
        needs = (("continuous (Box)" if self.actions == CONTINUOUS else " or ".join(self.actions)) + " actions"
                 + (" of one dimension" if self.vector_actions and box else "")
                 + (" with finite bounds (low < high)" if self.bounded_actions and box else ""))
        instead = "; use " + " or ".join(f"--algo {name}" for name in fitting) if fitting else (
            "; no algorithm fits them: give your env a Box, Discrete, MultiDiscrete or MultiBinary action space"
            + (" with finite bounds" if isinstance(space, _box_class()) else ""))
        raise MotorlabError(f"{self.title} needs {needs}, and {env_id}'s actions are {space}{instead}.")

    @property
    def sb3(self) -> bool:
        return False


def bounded(space: gym.Space) -> bool:
    """A Box with finite bounds and room between them (an algorithm that squashes its actions into
    the bounds divides by high - low); any other space counts as bounded."""
    if not isinstance(space, _box_class()):
        return True
    low, high = np.asarray(space.low, dtype=np.float64), np.asarray(space.high, dtype=np.float64)
    return bool(np.isfinite(low).all() and np.isfinite(high).all() and (high > low).all())


def _box_class() -> type:
    import gymnasium as gym  # only where a space is checked: this module is read by --help

    return gym.spaces.Box


def _names_with(flag: str) -> list[str]:
    registry = _package().registry

    return [a.name for a in registry().values() if getattr(a, flag)]


def _titles_with(flag: str) -> str:
    return _package().titles_with(flag)


@dataclass(frozen=True)
class SB3Algorithm(Algorithm):
    """A Stable-Baselines3 (or sb3-contrib) algorithm."""

    cls: str = ""  # "module:Class", imported when a run needs it
    mlp_policy: str = "MlpPolicy"  # the policy SB3 is given for a Box observation ...
    multi_input_policy: str | None = "MultiInputPolicy"  # ... and for a Dict one (None: it has none)
    networks: dict[str, str] = field(default_factory=dict)  # policy.json's class name -> "module:Class"
    zip_modules: tuple[str, ...] = ()  # the policy modules an SB3 zip of it names (export)
    dict_obs: bool = True
    bounded_actions: bool = True  # SB3 clips (on-policy) or squashes (off-policy) Box actions into the bounds

    @property
    def sb3(self) -> bool:
        return True

    @property
    def on_policy(self) -> bool:
        raise NotImplementedError

    def sb3_class(self) -> type:
        """The SB3 class (imports SB3, torch)."""
        try:
            return imported(self.cls)
        except ImportError as e:  # a core dependency (stable-baselines3, sb3-contrib) left out
            raise MotorlabError(f"--algo {self.name} needs the Python package {e.name}, which is not installed; "
                                "reinstall motorlab (pip install motorlab) to get its dependencies.") from None

    def policy(self, dict_obs: bool, env_id: str = "") -> str:
        """The policy name SB3 is given for this observation."""
        if not dict_obs:
            return self.mlp_policy
        if self.multi_input_policy is None:
            raise MotorlabError(f"{self.title} has no policy for Dict observations ({env_id or 'the env'}'s); use "
                                "--algo " + " or ".join(_dict_names()) + ".")
        return self.multi_input_policy

    def network_classes(self) -> dict[str, type]:
        """The policy network classes policy.json names, by name (imports SB3)."""
        return {name: imported(path) for name, path in self.networks.items()}

    def eval_every(self, model: Any, n_envs: int) -> int:
        raise NotImplementedError

    def use_sde(self, model: Any) -> bool | None:
        """The use_sde the network is built with beside its policy_kwargs (None: it is in them)."""
        return None

    # ---- acting: the deterministic action of a saved network (motorlab.policies.SB3Policy) ----

    def initial_state(self, network: Any, n: int) -> Any:
        """The state a batch of n new episodes starts from (None: stateless)."""
        return None

    def reset_row(self, state: Any, i: int) -> Any:
        return state

    def predict(self, network: Any, obs: Any, state: Any, deterministic: bool) -> tuple[np.ndarray, Any]:
        action, _ = network.predict(obs, deterministic=deterministic)
        return action, state

    # ---- ONNX: the same action as a torch graph (motorlab.deploy_onnx) ----

    tanh_in_actor: bool = False  # the actor's output is tanh'd already (TD3)

    def onnx_states(self, network: Any) -> tuple[StateSpec, ...]:
        """Recurrent states the graph carries from step to step (none: stateless)."""
        return ()

    def actor(self, network: Any, x: Any, states: tuple) -> tuple[Any, tuple]:
        """The deterministic action before squashing and scaling, from preprocessed observations."""
        raise NotImplementedError


def _dict_names() -> list[str]:
    registry = _package().registry

    return [a.name for a in registry().values() if a.sb3 and a.multi_input_policy]


@dataclass(frozen=True)
class OnPolicy(SB3Algorithm):
    """Learns from rollouts of its current policy, which changes only between rollouts: evaluated
    and checkpointed at the start of each rollout."""

    actions: tuple[str, ...] = ANY_ACTIONS
    clip_range: bool = True
    eval_cadence: str = "every rollout"

    @property
    def on_policy(self) -> bool:
        return True

    def eval_every(self, model: Any, n_envs: int) -> int:
        return int(model.n_steps) * n_envs

    def use_sde(self, model: Any) -> bool | None:
        return bool(getattr(model, "use_sde", False))  # on-policy classes pass it beside policy_kwargs

    def actor(self, network: Any, x: Any, states: tuple) -> tuple[Any, tuple]:
        features = network.pi_features_extractor(x)
        return network.action_net(network.mlp_extractor.forward_actor(features)), states


@dataclass(frozen=True)
class OffPolicy(SB3Algorithm):
    """Learns from a replay buffer: evaluated and checkpointed every `eval_every` env steps."""

    her: bool = True
    eval_cadence: str = f"{OFF_POLICY_EVAL_EVERY} env steps"

    @property
    def on_policy(self) -> bool:
        return False

    def eval_every(self, model: Any, n_envs: int) -> int:
        return OFF_POLICY_EVAL_EVERY

    def actor(self, network: Any, x: Any, states: tuple) -> tuple[Any, tuple]:
        mean, _, _ = network.actor.get_action_dist_params(x)  # SAC-like: a squashed Gaussian's mean
        return mean, states
