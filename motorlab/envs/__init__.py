"""Make environments by id, with motorlab's wrappers applied in a fixed order:

    base env -> numerical guard -> reward shaping -> low-pass delay -> synergy actions -> observation history

Reward shaping sees the true state; the policy sees delayed, stacked observations.
Upkie ids (`Upkie-PyBullet-Pendulum`, ...) get motorlab's learning defaults and
balancing reward as their base env (see `motorlab.envs.upkie`). What motorlab knows about an env
family (falls, success, the extra that installs it, ...) is in `motorlab.envs.catalog`.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

import gymnasium as gym
from pydantic import ConfigDict, Field, field_validator, model_validator

from motorlab.envs.catalog import EnvFacts, facts, register_env
from motorlab.envs.disturbances import (
    GaussianNoise,
    Latency,
    MotorNoise,
    RandomPush,
    muscle_fatigue,
    parse_span,
    span_text,
)
from motorlab.envs.rewards import check_reward, resolve_reward
from motorlab.envs.spaces import check_spaces, is_dict, obs_layout, require_actions
from motorlab.envs.upkie import make_upkie, register_upkie
from motorlab.envs.wrappers import (
    DelayOn,
    EpisodeCap,
    LowPassDelay,
    NumericalGuard,
    RewardShaping,
    delay_alpha,
    env_dt_of,
    has_time_limit,
    user_code_error,
)
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.extras import missing
from motorlab.settings import Settings, StrictModel, UserCode
from motorlab.user_modules import (
    import_inherited,
    import_modules,
    registered_by,
    split_env_id,
    user_env_ids,
)

__all__ = ["EnvConfig", "EnvSettings", "ENV_KEYS", "DISTURBANCES", "describe_env", "make_env", "check_env_id", "max_return", "env_dt", "LowPassDelay", "RewardShaping",
           "delay_alpha", "register_myosuite", "register_robotics", "reads_observations", "early_end_label", "EnvFacts",
           "facts", "register_env", "fold_env", "given_env", "env_record", "is_bare", "option_name", "refuse_settings"]

def _route_mujoco_warnings() -> None:
    """Send MuJoCo's C-level warnings to Python logging instead of stderr and a
    MUJOCO_LOG.TXT in the working directory. MyoSuite models warn on every load;
    instabilities are still counted from mjData.warning by NumericalGuard."""
    import mujoco

    log = logging.getLogger("motorlab.mujoco")
    mujoco.set_mju_user_warning(lambda message: log.debug("MuJoCo: %s", message.strip()))


_route_mujoco_warnings()

# Envs motorlab ships (motorlab/envs/<module>.py and its MuJoCo model): id -> (entry point, time
# limit, the return that counts as solved). Registered when motorlab.envs is imported, which every process that makes an env does;
# the entry point is a string, so a module's model is read only when its env is made.
BUNDLED_ENVS = {
    # PETS' swing-up; solved: 170 of the 200 a pole held upright from the first step would earn
    "CartpoleSwingup-v0": ("motorlab.envs.cartpole_swingup:CartpoleSwingup", 200, 170.0),
}


def register_bundled() -> None:
    """Register motorlab's own envs with Gymnasium (once: an id already registered is left as it is)."""
    for env_id, (entry_point, steps, solved) in BUNDLED_ENVS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=entry_point, max_episode_steps=steps, reward_threshold=solved)


register_bundled()


class EnvConfig(StrictModel):
    """Which env, and how it is wrapped."""

    model_config = ConfigDict(extra="forbid")

    # UserCode: `run --check` finds the user's module an id or a reward names (motorlab.settings.check_user_code)
    id: Annotated[str, UserCode(lambda v: check_env_id(v))] = Field(
        "InvertedPendulum-v5", description="Gymnasium env id, e.g. InvertedPendulum-v5")
    delay: float | str | None = Field(None, description="Low-pass delay time constant TAU in seconds (alpha = "
                                      "dt/TAU must be in (0, 1)), e.g. 0.2, or a range drawn per episode, e.g. "
                                      "0.05..0.3")
    # Actuation and perception delay, as in the robust-policy workflow (docs/design.md).
    delay_on: DelayOn = Field("both", description="What the delay filters: both (actuation and perception), "
                              "action or observation")
    history: int = Field(1, ge=1, description="Stack the last K observations (K=1: none)")
    # What real robots do beyond the lag (motorlab.envs.disturbances); any amount may be a range
    # "LOW..HIGH" drawn anew each episode (domain randomization).
    latency: int | str | None = Field(None, description="Transport latency in whole env steps (nothing arrives "
                                      "early, unlike --delay), e.g. 2, or a range per episode, e.g. 0..3")
    latency_on: DelayOn = Field("both", description="What the latency holds back: both, action or observation")
    obs_noise: float | str | list[float] | None = Field(
        None, description="Gaussian noise std on every observation the policy sees: one std (0.01), a range per "
        "episode (0..0.02) or one std per element (0.01,0,0.05,0)")
    action_noise: float | str | list[float] | None = Field(
        None, description="Gaussian noise std on every command before the env gets it (then clipped to the "
        "action space): one std, a range per episode, or one std per element")
    push_body: str | None = Field(None, description="Push this body of the MuJoCo model at random times (e.g. "
                                  "pole, torso); with --push-force")
    push_force: float | str = Field(10.0, description="Push magnitude in newtons, or a range per push, e.g. 5..20")
    push_interval: float | str = Field("1..3", description="Seconds from one push to the next, drawn from this "
                                       "range (or fixed)")
    push_duration: float | None = Field(None, gt=0, description="Seconds each push lasts (default: one env "
                                        "step, an impulse)")
    push_direction: Literal["horizontal", "x", "y", "z", "any"] = Field(
        "horizontal", description="Push direction: a random horizontal one, along x, y or z (random sign), or any")
    motor_noise: float | str | None = Field(None, description="MyoSuite: motor noise on the muscle excitations, "
                                            "as a multiple of van Beers et al. 2004 (1 = signal-dependent std "
                                            "0.103 + constant std 0.185), or a range per episode, e.g. 0..1")
    fatigue: Literal["off", "fresh", "random"] = Field(
        "off", description="MyoSuite: 3CC-r muscle fatigue, muscles rested at each reset (fresh) or in a random "
        "fatigue state (random)")
    reward: Annotated[str | None, UserCode(check_reward)] = Field(None, description="Reward shaping: task, alive, quadratic, action-penalty, or "
                               "module:function (fn(next_obs, action, reward, terminated, info) -> float)")
    sar: str | None = Field(None, description="Act in synergy space: a sar.npz from `motorlab synergies fit` or "
                            "`import-sklearn`")
    phi: float = Field(1.0, gt=0, le=1, description="With a SAR: 1 = synergies only; <1 = action is [synergies, "
                       "raw muscles] blended phi*decode(syn) + (1-phi)*raw (the reference used 0.66)")
    kwargs: dict[str, Any] = Field(default_factory=dict,
                                   description="keyword arguments for the env (gymnasium.make), e.g. Upkie's time_limit")
    # How an episode's success is read from the env's per-step flag (info["solved"]): "any" step
    # (manipulation: the object reached its goal once), or the "final" step (walking: upright and
    # at the commanded speed when the episode ended). "auto" takes the env's catalogue entry: final
    # for MyoSuite's walking tasks, whose flag is a state, not an event: under "any", even a policy
    # that falls forward is counted as walking once (see motorlab.evaluation.success_mode).
    success: Literal["auto", "any", "final"] = Field(
        "auto", description="When an episode counts as a success, from the env's per-step flag (MyoSuite: "
        "info['solved']): any (solved at any step), final (solved at its last step), or auto (final for "
        "MyoSuite's walking tasks, any otherwise)")

    @field_validator("delay", "latency", "push_force", "push_interval", "motor_noise", mode="before")
    @classmethod
    def _amount(cls, v, info):
        """A number or a range LOW..HIGH ([LOW, HIGH] in TOML), stored as the number or "LOW..HIGH"."""
        if v is None:
            return v
        what = {"delay": "delay time constant (s)", "latency": "latency (steps)", "push_force": "push force (N)",
                "push_interval": "push interval (s)", "motor_noise": "motor noise"}[info.field_name]
        low, high = parse_span(v, what, integer=info.field_name == "latency")
        if low == high:
            return int(low) if info.field_name == "latency" else low
        return span_text((low, high))

    @field_validator("obs_noise", "action_noise", mode="before")
    @classmethod
    def _noise(cls, v, info):
        if v is None or isinstance(v, list):
            return v
        if isinstance(v, str) and "," in v:  # one std per element, from the command line
            try:
                return [float(x) for x in v.split(",") if x.strip()]
            except ValueError:
                raise MotorlabError(f"{info.field_name.replace('_', ' ')} {v!r}: write stds separated by commas, "
                                    "e.g. 0.01,0,0.05,0.") from None
        low, high = parse_span(v, {"obs_noise": "observation noise", "action_noise": "action noise"}[info.field_name])
        return low if low == high else span_text((low, high))

    @field_validator("sar")
    @classmethod
    def _absolute(cls, v):
        # run folders record where the SAR is, wherever the run is evaluated from
        return str(Path(v).resolve()) if v and not v.startswith("@") else v  # "@step": a recipe's, resolved when it runs


# The disturbance settings (noise, latency, pushes, MyoSuite's motor noise and fatigue), named alike
# everywhere: a recipe's fields, the CLI's --obs-noise ..., robustness' --vary obs-noise=...
DISTURBANCES = ("latency", "latency_on", "obs_noise", "action_noise", "push_body", "push_force", "push_interval",
                "push_duration", "push_direction", "motor_noise", "fatigue")

# Recipe and CLI names of the env settings every env-taking step shares (EnvConfig's fields).
ENV_KEYS = {"env": "id", "delay": "delay", "delay_on": "delay_on", "history": "history", "reward": "reward",
            "sar": "sar", "phi": "phi", "env_kwargs": "kwargs", "success": "success",
            **{k: k for k in DISTURBANCES}}


class EnvSettings(Settings):
    """Settings of a step that builds an env: recipes and the CLI give the env's settings flat
    (env, delay, history, ...); they are folded into one `EnvConfig`.

    A kind says which of them it takes flat (`aliases`), whether the env id must be given (its
    `env` field without a default: required), and which EnvConfig settings it cannot honour
    (`env_refused`: the field and the rest of the one-line error, why and what to do instead), so
    that a setting it would not apply is refused, never silently ignored. A field of the kind's own
    that shares a flat env name (mpc's planner `reward`) stays the kind's."""

    aliases: ClassVar[frozenset[str]] = frozenset(ENV_KEYS)
    env_refused: ClassVar[dict[str, str]] = {}
    env: EnvConfig = Field(default_factory=EnvConfig)

    @model_validator(mode="before")
    @classmethod
    def _fold_env(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        folded = fold_env(data, keep=frozenset(cls.model_fields) - {"env"})
        if cls.model_fields["env"].is_required() and "id" not in folded["env"]:
            folded.pop("env")  # pydantic says the id is missing, beside the other fields' errors
        elif not folded["env"] and cls.model_fields["env"].default is None:  # an optional env, not given
            folded.pop("env")
        return folded

    @model_validator(mode="after")
    def _honoured(self):
        env = getattr(self, "env", None)
        if env is not None:
            refuse_settings(env, type(self).env_refused, type(self).aliases)
        return self


def option_name(field: str) -> str:
    """The command-line option of an EnvConfig field: --env (id), --env-arg (kwargs), --history, ..."""
    alias = {f: k for k, f in ENV_KEYS.items()}[field]
    return "--env-arg" if alias == "env_kwargs" else "--" + alias.replace("_", "-")


def refuse_settings(cfg: EnvConfig, refused: dict[str, str], flat: frozenset[str] = frozenset(ENV_KEYS)) -> None:
    """Refuse, in one line, the first env setting of `refused` that `cfg` sets (to other than its
    default): `refused` maps an EnvConfig field to why it does not apply and what to do instead.
    A setting is named as the command line names it where it is one of the `flat` ones (--history),
    else as a field of the env ("env.reward": a kind whose --reward is its own).

    Raises:
        MotorlabError: "--history 3: <why>".
    """
    names = {field: key for key, field in ENV_KEYS.items()}
    for field, why in refused.items():
        value = getattr(cfg, field)
        if value != EnvConfig.model_fields[field].get_default(call_default_factory=True):
            name = option_name(field) if names[field] in flat else f"env.{field}"
            raise MotorlabError(f"{name} {value!r}: {why}")


def given_env(cfg: EnvConfig) -> dict[str, Any]:
    """The env settings `cfg` was given (not its defaults), as EnvConfig names them."""
    return cfg.model_dump(mode="json", include=cfg.model_fields_set)


def env_record(cfg: EnvConfig) -> dict[str, Any]:
    """`cfg` as files record it: its id and the settings that differ from their defaults."""
    return {"id": cfg.id, **cfg.model_dump(mode="json", exclude_defaults=True, exclude={"id"})}


def is_bare(cfg: EnvConfig) -> bool:
    """Whether `cfg` is its env id alone: no wrapper, no disturbance, no argument."""
    return env_record(cfg).keys() == {"id"}


def fold_env(fields: dict[str, Any], keep: frozenset[str] = frozenset()) -> dict[str, Any]:
    """Flat env settings (env = "id", delay, history, ...) folded into one "env" dict (a str env
    is its id: config.toml files that recorded only the id load as before); `keep`: names that
    are the settings' own fields, left where they are."""
    data = dict(fields)
    env = data.get("env")
    if env is not None and not isinstance(env, (str, Mapping, EnvConfig)):
        raise MotorlabError(f"--env {env!r}: give an env id (e.g. InvertedPendulum-v5) or a table of env settings.")
    env = {"id": env} if isinstance(env, str) else dict(env or {})
    for key, field in ENV_KEYS.items():
        if key != "env" and key in data and key not in keep:
            env[field] = data.pop(key)
    data["env"] = env
    return data


def register_myosuite() -> bool:
    """Import MyoSuite, which registers its env ids (myoHandReorient8-v0, myoLegWalk-v0, ...).

    Returns:
        False when MyoSuite is not installed (the `myosuite` extra).
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import myosuite  # noqa: F401  (import registers the envs)
    except ImportError:
        return False
    return True


def register_robotics() -> bool:
    """Import Gymnasium-Robotics, which registers its env ids (PointMaze_UMaze-v3, AntMaze_*,
    AdroitHand*, ...), without the notice it prints to stderr on import.

    Returns:
        False when Gymnasium-Robotics is not installed (the `robotics` extra).
    """
    import contextlib
    import io

    try:
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            import gymnasium_robotics  # noqa: F401  (import registers the envs)
    except ImportError:
        return False
    return True


def is_robotics(env_id: str) -> bool:
    """An id of Gymnasium-Robotics' families (registered or not)."""
    return facts(env_id).extra == "robotics"


def check_env_id(env_id: str) -> None:
    """Raise a clear error for an env id Gymnasium does not know, with close matches.

    A "module:EnvId" id imports the module first (Gymnasium's convention: the import registers
    the id), as do the modules given with --import or a recipe's `imports`. MyoSuite ids
    (`myo...`) are registered on first use; without MyoSuite installed they get a message
    saying how to install it.
    """
    import_inherited()
    module, name = split_env_id(env_id)
    if module is not None:
        import_modules([module], f"for env {env_id}")
        if name not in gym.registry:
            ids = registered_by(module)
            raise MotorlabError(f"module {module!r} registers no env {name!r}; it registers "
                                f"{', '.join(ids) if ids else 'no env at all'}.")
        return
    if facts(env_id).extra == "upkie":
        register_upkie()  # clear message when upkie or pybullet is missing
    if env_id not in gym.registry and is_robotics(env_id):  # registered on first use, like MyoSuite's
        if not register_robotics():
            raise missing(f"{env_id} needs Gymnasium-Robotics", "robotics")
    if env_id not in gym.registry:
        installed = register_myosuite()
        if env_id in gym.registry:
            return
        if facts(env_id).extra == "myosuite" and not installed:
            raise missing(f"{env_id} needs MyoSuite", "myosuite")
        if not is_robotics(env_id) and register_robotics() and env_id in gym.registry:
            return  # one of its families this list does not name
        raise MotorlabError(
            f"unknown env id {env_id!r}{did_you_mean(env_id, gym.registry.keys())}; "
            "`python -c \"import gymnasium; gymnasium.pprint_registry()\"` lists the ids; an env of your own: "
            "give MODULE:ID (e.g. mypkg.envs:MyArm-v0) or --import MODULE."
        )


_checked: set[str] = set()  # user env ids Gymnasium's checker passed in this process


def check_user_env(env: gym.Env, env_id: str) -> None:
    """Gymnasium's env checker, once per process, on an env a user's module registered: spaces,
    reset and step signatures, observations inside their space, seeding. A rejected env stops
    here with the checker's message instead of deep inside training.

    Raises:
        MotorlabError: the checker's first complaint.
    """
    if env_id in _checked:
        return
    from gymnasium.utils.env_checker import check_env

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its advice (float32, bounds) is not an error
            check_env(env.unwrapped, skip_render_check=True)
    except Exception as e:  # the checker asserts, and the env's own code may raise anything
        message = " ".join(str(e).split()) or type(e).__name__
        raise MotorlabError(f"{env_id}: Gymnasium's env checker rejects it: {message}") from None
    _checked.add(env_id)


# Steps an episode of an env without a time limit may run before the run stops with one line
# saying how to give it one (--env-arg max_episode_steps=N): an env that ends its episodes itself
# runs as it is, one that never ends no longer hangs evaluation.
UNLIMITED_EPISODE_CAP = 100_000


def make_env(cfg: EnvConfig, shaped: bool = True, render_mode: str | None = None, dict_obs: bool = False,
             **kwargs: Any) -> gym.Env:
    """Build the env described by `cfg`.

    Args:
        cfg: env id and wrappers.
        shaped: apply reward shaping (evaluation passes False to report the task's return).
        render_mode: passed to `gymnasium.make` (e.g. "rgb_array" for videos).
        dict_obs: keep a Dict observation space as it is (SB3 training: MultiInputPolicy, HER),
            unless a wrapper that reads observations as one array is asked for (a delay or latency
            on observations, observation noise, history, a reward shaping that reads the
            observation). Otherwise a Dict observation is flattened
            as `gymnasium.spaces.flatten` does (motorlab.envs.spaces: the layout of its keys).

    An env with no time limit (no max_episode_steps) gets `EpisodeCap`: an episode past
    UNLIMITED_EPISODE_CAP steps stops the run with one line; `--env-arg max_episode_steps=N`
    gives it Gymnasium's TimeLimit. What the env (or a --reward function) raises while it runs is
    one MotorlabError line naming it, the exception and where (`wrappers.user_code_error`).

    Raises:
        MotorlabError: unknown id, bad delay, unknown reward, an env that cannot render (with
            render_mode), a setting that acts on Box actions on an env whose actions are not,
            observations no motorlab policy reads or actions none acts in (`spaces.check_spaces`).
    """
    check_env_id(cfg.id)
    name = split_env_id(cfg.id)[1]
    if facts(cfg.id).extra == "upkie":
        env = make_upkie(cfg.id, render_mode, **{**cfg.kwargs, **kwargs})
    else:
        env = _gym_make(cfg, name, render_mode, kwargs)
        if name in user_env_ids():
            check_user_env(env, cfg.id)
    try:
        check_spaces(env, cfg.id)  # what no motorlab policy reads or acts in: refused at every kind's door
        _require_box_wrappers(env, cfg)
    except MotorlabError:
        env.close()
        raise
    if not has_time_limit(env) and facts(cfg.id).extra != "upkie":  # Upkie's envs end on their time_limit
        env = EpisodeCap(env, cfg.id, UNLIMITED_EPISODE_CAP)
    if cfg.motor_noise is not None:
        env = MotorNoise(env, cfg.motor_noise)  # MyoSuite's own wrappers, on the muscle excitations
    if cfg.fatigue != "off":
        env = muscle_fatigue(env, cfg.fatigue)
    env = NumericalGuard(env, cfg.id)  # also: the env's own exceptions as one line naming it
    if is_dict(env.observation_space) and not (dict_obs and not reads_observations(cfg)):
        obs_layout(env.observation_space)  # Box entries only: one line naming the key otherwise
        env = gym.wrappers.FlattenObservation(env)
    if shaped and cfg.reward and cfg.reward != "task":
        env = RewardShaping(env, resolve_reward(cfg.reward), name=cfg.reward)
    if cfg.push_body:
        env = RandomPush(env, cfg.push_body, cfg.push_force, cfg.push_interval, cfg.push_duration, cfg.push_direction)
    if cfg.delay:
        env = LowPassDelay(env, cfg.delay, on=cfg.delay_on)
    if cfg.latency:
        env = Latency(env, cfg.latency, on=cfg.latency_on)
    if cfg.obs_noise is not None or cfg.action_noise is not None:
        env = GaussianNoise(env, cfg.obs_noise, cfg.action_noise)
    if cfg.sar:
        from motorlab.synergies.wrapper import SynergyActionWrapper

        env = SynergyActionWrapper(env, cfg.sar, cfg.phi)  # outside the delay: muscles are what lags
    if cfg.history > 1:
        env = gym.wrappers.FrameStackObservation(env, cfg.history, padding_type="reset")
        env = gym.wrappers.FlattenObservation(env)
    return env


def _gym_make(cfg: EnvConfig, name: str, render_mode: str | None, kwargs: dict[str, Any]) -> gym.Env:
    """`gymnasium.make`, its mistakes in one line: an argument the env does not take, an env that
    cannot render, a Gymnasium-Robotics model that fails to build under this MuJoCo."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # -v4 deprecation notices are noise here
        try:
            # render_mode only when asked: a user's env need not take the argument
            rendering = {"render_mode": render_mode} if render_mode is not None else {}
            return gym.make(name, **rendering, **cfg.kwargs, **kwargs)
        except TypeError as e:  # an env argument it does not take
            if render_mode is not None and "render_mode" in str(e):
                raise MotorlabError(f"{cfg.id} cannot render: it takes no render_mode argument. A video needs a "
                                    "MuJoCo env, or an env that takes render_mode='rgb_array' and returns frames "
                                    "from render().") from None
            raise MotorlabError(f"{cfg.id} does not take these settings: {e}.") from None
        except AssertionError as e:
            if not facts(name).broken:
                raise user_code_error(f"making {cfg.id}", e) from None
            import mujoco

            raise MotorlabError(f"{cfg.id} fails to build inside Gymnasium-Robotics with MuJoCo {mujoco.__version__} "
                                "(an upstream incompatibility of its Fetch, Shadow-hand and Kitchen models); "
                                "its mazes (PointMaze_*, AntMaze_*) and the Adroit hand (AdroitHand*) work.") from None
        except MotorlabError:
            raise
        except Exception as e:  # the env's constructor (often a user's) may raise anything
            raise user_code_error(f"making {cfg.id}", e) from None


def _require_box_wrappers(env: gym.Env, cfg: EnvConfig) -> None:
    """Refuse, in one line, the settings that act on Box actions when the env's actions are not."""
    on_actions = ("action", "both")
    uses = [("--delay on actions", bool(cfg.delay) and cfg.delay_on in on_actions, "give --delay-on observation"),
            ("--latency on actions", bool(cfg.latency) and cfg.latency_on in on_actions,
             "give --latency-on observation"),
            ("--action-noise", cfg.action_noise is not None, "drop it"),
            ("--sar (synergy actions)", bool(cfg.sar), "drop it")]
    for user, used, instead in uses:
        if used:
            require_actions(env.action_space, user, instead=instead, env_id=cfg.id)


# Reward shapings that never look at the observation (the others are given one array)
OBS_FREE_REWARDS = (None, "task", "alive", "action-penalty")


def reads_observations(cfg: EnvConfig) -> bool:
    """Whether a wrapper `cfg` asks for works on the observation as one array (a Dict one is then
    flattened first, even for training)."""
    on_obs = ("observation", "both")
    return bool((cfg.delay and cfg.delay_on in on_obs) or (cfg.latency and cfg.latency_on in on_obs)
                or cfg.obs_noise is not None or cfg.history > 1 or cfg.reward not in OBS_FREE_REWARDS)


def describe_env(env: EnvConfig) -> str:
    """The env and its wrappers in a few words: "InvertedPendulum-v5, delay 0.2 s on both, history 10"."""
    tags = [env.id]
    if env.delay:
        tags.append(f"delay {env.delay} s on {env.delay_on}")  # action, observation or both
    if env.latency:
        tags.append(f"latency {env.latency} steps on {env.latency_on}")
    for key, unit in (("obs_noise", "observation noise std"), ("action_noise", "action noise std"),
                      ("motor_noise", "motor noise x")):
        value = getattr(env, key)
        if value is not None:
            tags.append(f"{unit} {','.join(f'{v:g}' for v in value) if isinstance(value, list) else value}")
    if env.push_body:
        tags.append(f"pushes on {env.push_body}: {env.push_force} N every {env.push_interval} s")
    if env.fatigue != "off":
        tags.append(f"muscle fatigue ({env.fatigue})")
    if env.history > 1:
        tags.append(f"history {env.history}")
    if env.sar:
        tags.append(f"synergies {Path(env.sar).name}, phi {env.phi:g}")
    return ", ".join(tags)


def env_dt(env: gym.Env) -> float | None:
    """Seconds per env step: `dt` where the env has one (Gymnasium MuJoCo envs), else
    MuJoCo's timestep times the frame skip (MyoSuite)."""
    return env_dt_of(env.unwrapped)


def max_return(env_id: str) -> float | None:
    """The best return an episode can reach, where the task defines one.

    The catalogue's `max_return` (a number, or the time limit where the reward is +1 per step
    alive: InvertedPendulum's 1000); otherwise the env's registered reward threshold, else None.
    """
    check_env_id(env_id)
    spec = gym.spec(split_env_id(env_id)[1])
    best = facts(env_id).max_return
    if best == "time_limit":
        if spec.max_episode_steps:
            return float(spec.max_episode_steps)
    elif best is not None:
        return float(best)
    return float(spec.reward_threshold) if spec.reward_threshold is not None else None


def early_end_label(env_id: str) -> str:
    """What reports call episodes of this env that ended before the time limit: "falls" where the
    catalogue says an early end is a fall (the pole or the body fell), else "ended early"."""
    return facts(env_id).early_end
