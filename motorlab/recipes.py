"""Recipes: a study as a TOML file of steps, validated before anything runs.

    name = "pendulum"
    description = "..."

    [defaults]                 # fields every step gets unless it sets them
    env = "InvertedPendulum-v5"

    [[steps]]
    name = "ppo"               # the step's run folder: <study>/<name>/
    kind = "train"             # train | evaluate
    algo = "ppo"
    timesteps = 100000
    until_solved = true

    [[steps]]
    name = "ppo-on-delay"
    kind = "evaluate"
    policy = "@ppo"            # the policy trained by an earlier step (or pid, pid:kp=..., a folder)
    delay = 0.2

Train steps take every `motorlab train` setting (env, delay, delay_on, history,
reward, algo, preset, timesteps, seed, lr, clip_range, until_solved, ...);
evaluate steps take policy, env, delay, delay_on, history, episodes, seed.
Bundled recipes live in motorlab/recipes/ and are addressed by name.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from motorlab.envs import EnvConfig
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.rl.config import TrainConfig, resolve

ENV_KEYS = {"env": "id", "delay": "delay", "delay_on": "delay_on", "history": "history", "reward": "reward",
            "sar": "sar", "phi": "phi"}


class EvalStep(BaseModel):
    model_config = ConfigDict(extra="forbid")

    policy: str
    env: EnvConfig
    episodes: int = Field(10, gt=0)
    seed: int = Field(0, ge=0)


class Step(BaseModel):
    """One validated step: its name, kind and settings."""

    name: str
    kind: Literal["train", "evaluate"]
    train: TrainConfig | None = None
    evaluate: EvalStep | None = None

    @property
    def policy_ref(self) -> str | None:
        p = self.evaluate.policy if self.evaluate else None
        return p[1:] if p and p.startswith("@") else None


class Recipe(BaseModel):
    name: str
    description: str = ""
    source: str = ""
    steps: list[Step]


class _RecipeFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str
    description: str = ""
    defaults: dict[str, Any] = Field(default_factory=dict)
    steps: list[dict[str, Any]] = Field(min_length=1)


def bundled() -> dict[str, Path]:
    """Bundled recipe names and their files."""
    folder = resources.files("motorlab") / "recipes"
    return {p.name[:-5]: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml")}


def find_recipe(name_or_path: str) -> Path:
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise MotorlabError(f"recipe file {path} does not exist.")
        return path
    recipes = bundled()
    if name_or_path not in recipes:
        raise MotorlabError(
            f"unknown recipe {name_or_path!r}{did_you_mean(name_or_path, recipes)}; "
            f"bundled recipes: {', '.join(sorted(recipes))}, or give a path to a .toml file."
        )
    return recipes[name_or_path]


def _split_env(fields: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in fields.items() if k not in ENV_KEYS}
    env = {ENV_KEYS[k]: v for k, v in fields.items() if k in ENV_KEYS}
    if env:
        out["env"] = env
    return out


def _explain(e: ValidationError, where: str, known: set[str]) -> str:
    """First validation problem as one line: file, step, field, what is wrong."""
    err = e.errors()[0]
    loc = [str(x) for x in err["loc"]]
    field = ".".join(loc) if loc else "?"
    if field.startswith("env."):
        field = {v: k for k, v in ENV_KEYS.items()}.get(field[4:], field[4:])
    if err["type"] == "extra_forbidden":
        name = loc[-1]
        return f"{where}: unknown field {name!r}{did_you_mean(name, known)}"
    if err["type"] == "missing":
        return f"{where}: missing field {field!r}"
    return f"{where}: field {field!r}: {err['msg']}"


TRAIN_FIELDS = (set(TrainConfig.model_fields) - {"env"}) | set(ENV_KEYS)
EVAL_FIELDS = (set(EvalStep.model_fields) - {"env"}) | set(ENV_KEYS) - {"reward"}


def parse_recipe(text: str, source: str = "<recipe>") -> Recipe:
    """Validate a recipe's text; every step is checked before any runs.

    Raises:
        MotorlabError: TOML syntax, unknown or mistyped field (named with file and step),
            reference to an unknown or later step.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise MotorlabError(f"{source}: not valid TOML ({e}).") from None
    try:
        raw = _RecipeFile.model_validate(data)
    except ValidationError as e:
        raise MotorlabError(_explain(e, source, set(_RecipeFile.model_fields))) from None
    unknown_defaults = [k for k in raw.defaults if k not in TRAIN_FIELDS | EVAL_FIELDS]
    if unknown_defaults:
        k = unknown_defaults[0]
        raise MotorlabError(f"{source}: [defaults]: unknown field {k!r}{did_you_mean(k, TRAIN_FIELDS | EVAL_FIELDS)}")
    steps: list[Step] = []
    seen: set[str] = set()
    for i, fields in enumerate(raw.steps):
        kind = fields.get("kind", "train")
        known = TRAIN_FIELDS if kind == "train" else EVAL_FIELDS
        fields = {**{k: v for k, v in raw.defaults.items() if k in known}, **fields}
        name = str(fields.pop("name", f"step{i + 1}"))
        fields.pop("kind", None)
        where = f"{source}: steps[{i}] ({name})"
        if name in seen:
            raise MotorlabError(f"{where}: another step is already named {name!r}; step names must be unique.")
        if kind == "train":
            unknown = [k for k in fields if k not in known]
            if unknown:
                raise MotorlabError(f"{where}: unknown field {unknown[0]!r}{did_you_mean(unknown[0], known)}")
            try:
                step = Step(name=name, kind="train", train=resolve(_split_env(fields)))
            except ValidationError as e:
                raise MotorlabError(_explain(e, where, known)) from None
            except MotorlabError as e:
                raise MotorlabError(f"{where}: {e}") from None
        elif kind == "evaluate":
            unknown = [k for k in fields if k not in known]
            if unknown:
                raise MotorlabError(f"{where}: unknown field {unknown[0]!r}{did_you_mean(unknown[0], known)}")
            policy = str(fields.get("policy", ""))
            settings = _split_env(fields)
            if policy.startswith("@"):
                ref = next((s for s in steps if s.name == policy[1:]), None)
                if ref is None or ref.kind != "train":
                    raise MotorlabError(f"{where}: policy {policy!r} names no earlier train step; "
                                        f"train steps so far: {', '.join(s.name for s in steps if s.kind == 'train') or 'none'}.")
                # by default, evaluate on the env the policy was trained on, without its reward shaping
                trained_env = ref.train.env.model_dump(exclude={"reward"})
                settings["env"] = {**trained_env, **settings.get("env", {})}
            try:
                step = Step(name=name, kind="evaluate", evaluate=EvalStep.model_validate(settings))
            except ValidationError as e:
                raise MotorlabError(_explain(e, where, known)) from None
        else:
            raise MotorlabError(f"{where}: unknown kind {kind!r}; use 'train' or 'evaluate'.")
        _check_env(step.train.env if step.train else step.evaluate.env, where)
        seen.add(name)
        steps.append(step)
    return Recipe(name=raw.name, description=raw.description, source=source, steps=steps)


def _check_env(env: EnvConfig, where: str) -> None:
    """Build the env once, so a bad id, delay or reward fails before any step runs."""
    from motorlab.envs import make_env

    try:
        make_env(env).close()
    except MotorlabError as e:
        raise MotorlabError(f"{where}: {e}") from None


def load_recipe(name_or_path: str) -> Recipe:
    """Load a bundled recipe by name, or a recipe file by path."""
    path = find_recipe(name_or_path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise MotorlabError(f"cannot read recipe {path}: {e}") from None
    return parse_recipe(text, str(path))
