"""Recipes: a study as a TOML file of steps, validated before anything runs.

    name = "pendulum"
    description = "..."
    parallel_steps = 2         # optional: train steps that need nothing from each other run at once,
                               # each its own process, at most 2 (default 1: one step after another)

    [defaults]                 # fields every step gets unless it sets them (where its kind has them)
    env = "InvertedPendulum-v5"

    [[steps]]
    name = "ppo"               # the step's run folder: <study>/<name>/ (<name>/seed<k>/ with several seeds)
    kind = "train"
    algo = "ppo"
    timesteps = 100000
    seeds = 3                  # optional: one run per seed (0, 1, 2; or a list), run in parallel;
                               # `seeds = N` at the top of the file applies to every train step
    until_solved = true

    [[steps]]
    name = "ppo-on-delay"
    kind = "evaluate"
    policy = "@ppo"            # the policy trained by an earlier step (or pid, pid:kp=..., a folder)
    delay = 0.2

Kinds and their fields ("@step" names an earlier step's output):
    train      every `motorlab train` setting (env, env_kwargs, delay, delay_on, history, reward, sar, phi, success,
               algo, preset, timesteps, seed, seeds, lr, clip_range, until_solved, ...);
               sar = "@fit-step" trains in that step's synergy space
    evaluate   policy, env, env_kwargs, delay, delay_on, history, sar, phi, success, episodes, seed
               (policy = "@train-step" with several seeds: each seed's policy, aggregated)
    video      run = "@train-step" or "@evaluate-step", episodes, seed
    collect    run = "@train-step", episodes, percentile, preview, deterministic, workers, seed
    vaf        activations = "@collect-step", threshold, method, max_n
    fit        activations = "@collect-step", n_synergies | vaf, method, seed
    zeroshot   runs = ["@train-step", ...], envs = [...], episodes, seed
    compare    groups = { "LABEL" = ["@train-step", ...] }, title
    dynamics-collect  env, episodes, policy ("random" or "@train-step"), workers, state, simulator, seed
    dynamics-fit      transitions = "@dynamics-collect-step", epochs, hidden, ensemble, lr, batch_size,
                      valid_fraction, patience, seed
    dynamics-check    model = "@dynamics-fit-step", episodes, steps, seed
    mpc               env, model = "@dynamics-fit-step", episodes, horizon, population, iterations, elites,
                      optimizer (cem | evotorch), parallel, video, seed
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
            "sar": "sar", "phi": "phi", "env_kwargs": "kwargs",
            "success": "success"}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class EvalStep(_Strict):
    policy: str
    env: EnvConfig
    episodes: int = Field(10, gt=0)
    seed: int = Field(0, ge=0)


class CollectStep(_Strict):
    run: str
    episodes: int = Field(100, gt=0)
    percentile: float = Field(80.0, ge=0, le=100)
    preview: int = Field(50, gt=0)
    deterministic: bool = False
    workers: int | None = Field(None, gt=0)
    seed: int = Field(0, ge=0)


class VideoStep(_Strict):
    run: str
    episodes: int = Field(1, gt=0)
    seed: int = Field(0, ge=0)


class VafStep(_Strict):
    activations: str
    threshold: float = Field(0.8, gt=0, le=1)
    method: Literal["pca", "pca-ica", "nmf"] = "pca"
    max_n: int | None = Field(None, gt=0)


class FitStep(_Strict):
    activations: str
    n_synergies: int | None = Field(None, gt=0)
    vaf: float | None = Field(None, gt=0, le=1)
    method: Literal["pca-ica", "pca", "nmf"] = "pca-ica"
    seed: int = Field(0, ge=0)


class ZeroshotStep(_Strict):
    runs: list[str] = Field(min_length=1)
    envs: list[str] = Field(min_length=1)
    episodes: int = Field(500, gt=0)
    seed: int = Field(0, ge=0)


class CompareStep(_Strict):
    groups: dict[str, list[str]] = Field(min_length=1)
    title: str = "Learning curves"


class DynamicsCollectStep(_Strict):
    env: str
    episodes: int = Field(1000, gt=0)
    policy: str = "random"
    workers: int | None = Field(None, gt=0)
    state: Literal["auto", "reacher", "observation"] = "auto"
    simulator: Literal["auto", "closed-form", "mujoco", "gymnasium"] = "auto"
    seed: int = Field(0, ge=0)


class DynamicsFitStep(_Strict):
    transitions: str
    epochs: int = Field(50, gt=0)
    hidden: list[int] = Field(default_factory=lambda: [64, 64], min_length=1)
    ensemble: int = Field(1, gt=0)
    lr: float = Field(2e-3, gt=0)
    batch_size: int = Field(2000, gt=0)
    valid_fraction: float = Field(0.1, ge=0, lt=1)
    patience: int | None = Field(None, gt=0)
    seed: int = Field(0, ge=0)


class DynamicsCheckStep(_Strict):
    model: str
    episodes: int = Field(5, gt=0)
    steps: int | None = Field(None, gt=0)
    seed: int = Field(0, ge=0)


class MpcStep(_Strict):
    env: str
    model: str
    episodes: int = Field(50, gt=0)
    horizon: int | None = Field(None, gt=0)
    population: int | None = Field(None, gt=0)
    iterations: int | None = Field(None, gt=0)
    elites: int | None = Field(None, gt=0)
    optimizer: Literal["cem", "evotorch"] = "cem"
    parallel: int = Field(1, gt=0)
    video: bool = False
    seed: int = Field(0, ge=0)


KINDS: dict[str, type[BaseModel]] = {"evaluate": EvalStep, "video": VideoStep, "collect": CollectStep, "vaf": VafStep, "fit": FitStep,
                                     "zeroshot": ZeroshotStep, "compare": CompareStep,
                                     "dynamics-collect": DynamicsCollectStep, "dynamics-fit": DynamicsFitStep,
                                     "dynamics-check": DynamicsCheckStep, "mpc": MpcStep}
# Which kind of earlier step each reference field must name.
REFERENCES = {("evaluate", "policy"): "train", ("video", "run"): ("train", "evaluate"), ("collect", "run"): "train", ("vaf", "activations"): "collect",
              ("fit", "activations"): "collect", ("zeroshot", "runs"): "train", ("compare", "groups"): "train",
              ("train", "sar"): "fit", ("dynamics-collect", "policy"): "train",
              ("dynamics-fit", "transitions"): "dynamics-collect", ("dynamics-check", "model"): "dynamics-fit",
              ("mpc", "model"): "dynamics-fit"}


class Step(BaseModel):
    """One validated step: its name, kind and settings (`train` for training, else `settings`)."""

    name: str
    kind: Literal["train", "evaluate", "video", "collect", "vaf", "fit", "zeroshot", "compare", "dynamics-collect",
                  "dynamics-fit", "dynamics-check", "mpc"]
    train: TrainConfig | None = None
    seeds: list[int] | None = None
    sar_ref: str | None = None  # train: "@fit" resolved when the study runs
    settings: Any = None

    @property
    def evaluate(self) -> EvalStep | None:
        return self.settings if self.kind == "evaluate" else None

    @property
    def policy_ref(self) -> str | None:
        p = self.evaluate.policy if self.evaluate else None
        return p[1:] if p and p.startswith("@") else None


class Recipe(BaseModel):
    name: str
    description: str = ""
    source: str = ""
    parallel_steps: int = 1
    steps: list[Step]


class _RecipeFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str
    description: str = ""
    seeds: int | list[int] | None = None  # every train step that sets none: seeds 0..N-1 (or this list)
    parallel_steps: int = Field(1, ge=1)  # train steps that need nothing from each other, run at once
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


TRAIN_FIELDS = (set(TrainConfig.model_fields) - {"env"}) | set(ENV_KEYS) | {"seeds"}
EVAL_FIELDS = (set(EvalStep.model_fields) - {"env"}) | set(ENV_KEYS) - {"reward"}
FIELDS = {"train": TRAIN_FIELDS, "evaluate": EVAL_FIELDS,
          **{k: set(m.model_fields) for k, m in KINDS.items() if k != "evaluate"}}
ALL_FIELDS = set().union(*FIELDS.values())


def _refs(value: Any) -> list[str]:
    """Step names referenced ("@name") in a field value (a string, a list, or a dict of lists)."""
    items = value if isinstance(value, list) else list(value.values()) if isinstance(value, dict) else [value]
    flat = [x for item in items for x in (item if isinstance(item, list) else [item])]
    return [x[1:] for x in flat if isinstance(x, str) and x.startswith("@")]


def _check_refs(kind: str, fields: dict, steps: list[Step], where: str) -> None:
    for (k, field), wanted in REFERENCES.items():
        if k != kind or field not in fields:
            continue
        kinds = wanted if isinstance(wanted, tuple) else (wanted,)
        for ref in _refs(fields[field]):
            target = next((s for s in steps if s.name == ref), None)
            if target is None or target.kind not in kinds:
                names = ", ".join(s.name for s in steps if s.kind in kinds) or "none"
                label = " or ".join(kinds)
                raise MotorlabError(f"{where}: {field} '@{ref}' names no earlier {label} step; "
                                    f"{label} steps so far: {names}.")


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
    unknown_defaults = [k for k in raw.defaults if k not in ALL_FIELDS]
    if unknown_defaults:
        k = unknown_defaults[0]
        raise MotorlabError(f"{source}: [defaults]: unknown field {k!r}{did_you_mean(k, ALL_FIELDS)}")
    steps: list[Step] = []
    for i, fields in enumerate(raw.steps):
        kind = fields.get("kind", "train")
        name = str(fields.get("name", f"step{i + 1}"))
        where = f"{source}: steps[{i}] ({name})"
        if kind not in FIELDS:
            raise MotorlabError(f"{where}: unknown kind {kind!r}{did_you_mean(str(kind), FIELDS)}; "
                                f"kinds: {', '.join(FIELDS)}.")
        known = FIELDS[kind]
        fields = {**({"seeds": raw.seeds} if kind == "train" and raw.seeds is not None else {}),
                  **{k: v for k, v in raw.defaults.items() if k in known},
                  **{k: v for k, v in fields.items() if k not in ("name", "kind")}}
        if any(s.name == name for s in steps):
            raise MotorlabError(f"{where}: another step is already named {name!r}; step names must be unique.")
        unknown = [k for k in fields if k not in known]
        if unknown:
            raise MotorlabError(f"{where}: unknown field {unknown[0]!r}{did_you_mean(unknown[0], known)}")
        _check_refs(kind, fields, steps, where)
        try:
            step = _make_step(name, kind, fields, steps)
        except ValidationError as e:
            raise MotorlabError(_explain(e, where, known)) from None
        except MotorlabError as e:
            raise MotorlabError(f"{where}: {e}") from None
        env = step.train.env if step.train else step.evaluate.env if step.evaluate else None
        if env is not None:
            _check_env(env, where)
        steps.append(step)
    return Recipe(name=raw.name, description=raw.description, source=source, parallel_steps=raw.parallel_steps,
                  steps=steps)


def _make_step(name: str, kind: str, fields: dict, steps: list[Step]) -> Step:
    if kind == "train":
        fields = dict(fields)
        seeds = fields.pop("seeds", None)
        if isinstance(seeds, int) and not isinstance(seeds, bool) and seeds > 0:
            seeds = list(range(seeds))  # seeds = N: 0..N-1
        if seeds is not None and (not isinstance(seeds, list) or not seeds or len(set(seeds)) != len(seeds)
                                  or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in seeds)):
            raise MotorlabError("seeds must be a count (seeds = 5: seeds 0..4) or a list of distinct "
                                "non-negative integers (seeds = [0, 1, 2]).")
        sar = fields.get("sar")
        sar_ref = sar if isinstance(sar, str) and sar.startswith("@") else None
        if sar_ref:
            fields.pop("sar")  # the fit step's sar.npz exists only once the study runs
        return Step(name=name, kind="train", train=resolve(_split_env(fields)), seeds=seeds, sar_ref=sar_ref)
    if kind == "evaluate":
        from motorlab.evaluate import merge_env

        settings = _split_env(fields)
        policy = str(fields.get("policy", ""))
        if policy.startswith("@"):
            ref = next(s for s in steps if s.name == policy[1:])
            # by default, evaluate on the env the policy was trained on, without its reward shaping
            trained_env = ref.train.env.model_dump(exclude={"reward"})
            settings["env"] = merge_env(trained_env, settings.get("env", {}))
        return Step(name=name, kind="evaluate", settings=EvalStep.model_validate(settings))
    step = Step(name=name, kind=kind, settings=KINDS[kind].model_validate(fields))
    if kind in ("dynamics-collect", "mpc"):
        from motorlab.envs import check_env_id

        check_env_id(step.settings.env)
    return step


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
