"""Which env, and how it is wrapped: EnvConfig (the settings every env-taking step shares), and its flat
command-line spelling (EnvSettings, ENV_KEYS)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from motorlab.envs.disturbances import (
    parse_span,
    span_text,
)
from motorlab.envs.ids import check_env_id
from motorlab.envs.rewards import check_reward
from motorlab.envs.wrappers import (
    DelayOn,
)
from motorlab.errors import MotorlabError
from motorlab.settings import Settings, StrictModel, UserCode


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
