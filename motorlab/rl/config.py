"""Training settings as data (one validated model), and named presets.

A preset is a partial TrainConfig; settings given explicitly (CLI flags, recipe
fields) win over the preset's.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator, model_validator

from motorlab import algos
from motorlab.controllers.lqr import LQRSettings
from motorlab.envs import EnvSettings, fold_env
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.rl.schedules import schedule_ends
from motorlab.settings import MAX_SEED

# Every algorithm's presets, from its own module (motorlab/algos/<name>.py).
PRESETS: dict[str, dict[str, Any]] = algos.presets()


class TrainConfig(EnvSettings):
    """Everything `motorlab train` needs; written to the run folder's config.toml."""

    algo: str = Field("ppo", description="the learner: " + algos.summary_help())
    preset: str | None = Field(None, description="named settings under the given ones: " + algos.preset_help())
    preset_file: str | None = Field(None, description="TOML file of these fields (e.g. best.toml of motorlab tune), "
                                    "applied over the named preset and under the given settings")
    timesteps: int = Field(100_000, gt=0, description="Env-step budget")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (training, env resets, evaluation)")
    lr: str | None = Field(None, description="Learning-rate schedule: 3e-4 (constant) or linear:START,END (over "
                           "the budget)")
    clip_range: str | None = Field(None, description=algos.titles_with("clip_range") + " clip-range schedule, e.g. "
                                   "linear:0.3,0.1")
    until_solved: bool = Field(False, description="Stop once solve_episodes deterministic episodes all reach the "
                               "maximum return; summary.json gets steps_to_success")
    solve_episodes: int = Field(10, gt=0, description="Episodes that must all succeed")
    solve_return: float | None = Field(None, description="Return that counts as solved (default: the env's "
                                       "maximum, 1000 for InvertedPendulum)")
    eval_every: int | None = Field(None, gt=0, description="Env steps between evaluations (default: "
                                   + algos.eval_cadence_help() + ")")
    minutes: float | None = Field(None, gt=0, description="Wall-clock budget: minutes of training (evaluations "
                                  "and checkpoints not counted); training stops at whichever of it and --timesteps "
                                  "comes first, and summary.json says which (stopped_by)")
    eval_every_minutes: float | None = Field(None, gt=0, description="Minutes of training between evaluations, "
                                             "instead of env steps: learners of different speeds evaluated at "
                                             "the same wall times")
    n_envs: int = Field(1, gt=0, description="Parallel envs (subprocesses when > 1)")
    normalize: bool = Field(False, description="Normalize observations with running statistics (VecNormalize)")
    device: str = Field("auto", description="auto (CUDA when present) | cpu | cuda")
    # Small MLPs train fastest on one CPU thread; more threads contend with the envs.
    torch_threads: int = Field(1, ge=1, description="CPU threads for PyTorch")
    progress: bool = Field(True, description="Show a progress bar")
    checkpoint_every: int | None = Field(None, ge=0, description="Env steps between checkpoints for --resume "
                                         "(default: a tenth of the budget; 0: none)")
    hyperparams: dict[str, Any] = Field(default_factory=dict, description="extra keyword arguments for the SB3 algorithm")
    her: bool = Field(False, description="Hindsight experience replay (" + algos.titles_with("her") + ") on a goal-conditioned env (a Dict "
                      "observation with achieved_goal and desired_goal, e.g. PointMaze_UMaze-v3): SB3's "
                      "HerReplayBuffer relabels each transition with 4 goals reached later in its episode (future; "
                      "--set replay_buffer_kwargs={...} changes them); learning starts after the first full episode "
                      "unless learning_starts is set")
    lqr: LQRSettings = Field(default_factory=LQRSettings, json_schema_extra={"cli": False})  # recipes and --config only

    @field_validator("lr", "clip_range", mode="before")
    @classmethod
    def _number_as_schedule(cls, v):
        """A constant given as a number (Python's lr=3e-4, a sweep grid's [3e-4, 1e-3]): its exact text."""
        return repr(float(v)) if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    @field_validator("lr", "clip_range")
    @classmethod
    def _check_schedule(cls, v, info):
        if v is not None:
            flag = f"--{info.field_name.replace('_', '-')}"
            try:
                schedule_ends(v, "learning-rate" if info.field_name == "lr" else "clip-range")
            except MotorlabError as e:  # named as the option, as pydantic's errors are
                raise MotorlabError(f"{flag}: {e}") from None
        return v


    @field_validator("algo")
    @classmethod
    def _known_algo(cls, v: str) -> str:
        algos.get(v)  # one line with close matches for an unknown name
        return v

    @model_validator(mode="after")
    def _one_evaluation_clock(self):
        if self.eval_every is not None and self.eval_every_minutes is not None:
            raise MotorlabError("--eval-every counts env steps and --eval-every-minutes minutes of training: "
                                "give one of them.")
        return self

    @model_validator(mode="after")
    def _algo_takes_settings(self):
        algos.get(self.algo).check(self)  # --clip-range, --her: by what the algorithm is
        if self.her and "replay_buffer_class" in self.hyperparams:
            raise MotorlabError("--her sets replay_buffer_class (SB3's HerReplayBuffer); drop one of them.")
        return self


def resolve(settings: dict[str, Any]) -> TrainConfig:
    """Apply the named preset (if any), then the preset file (if any), under the given settings,
    and validate. The file may name a preset itself; a preset given explicitly wins over its.

    Raises:
        MotorlabError: unknown preset, unreadable preset file; pydantic.ValidationError for bad fields.
    """
    _named(settings)
    from_file = read_preset_file(settings["preset_file"]) if settings.get("preset_file") else {}
    preset = settings.get("preset", from_file.get("preset"))
    merged: dict[str, Any] = {}
    if preset is not None:
        if preset not in PRESETS:
            raise MotorlabError(f"unknown preset {preset!r}{did_you_mean(preset, PRESETS)}; presets: {', '.join(PRESETS)}.")
        merged = fold_env(PRESETS[preset]) if "env" in PRESETS[preset] else dict(PRESETS[preset])
    if preset is not None or from_file:
        settings = fold_env(settings)  # a recipe's flat env fields (delay = 0.2) meet the preset's env
    for layer in (fold_env(from_file) if from_file else {}, settings):
        merged = _merged(merged, layer)
    return TrainConfig.model_validate(merged)


def _named(settings: dict[str, Any]) -> None:
    """The preset and the preset file are names, read before the model judges the rest: anything else
    (a number, a table) is refused here, in one line, before it is looked up."""
    for key, what in (("preset", f"a preset's name ({', '.join(PRESETS)})"), ("preset_file", "a TOML file's path")):
        value = settings.get(key)
        if value is not None and not isinstance(value, (str, Path)):
            raise MotorlabError(f"--{key.replace('_', '-')} {value!r}: give {what}.")


def read_preset_file(path: str | Path) -> dict[str, Any]:
    """A preset file's fields (TrainConfig fields; env fields flat or in an [env] table).

    Raises:
        MotorlabError: the file is missing or not TOML, or it names another preset file.
    """
    try:
        data = tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as e:
        raise MotorlabError(f"--preset-file {path}: not valid TOML: {e}.") from None
    except (OSError, ValueError) as e:  # ValueError: undecodable text, a NUL in the path
        raise MotorlabError(f"--preset-file {path}: cannot read it: {getattr(e, 'strerror', None) or e}.") from None
    if "preset_file" in data:
        raise MotorlabError(f"--preset-file {path} names another preset file; write its fields in {path} instead.")
    return data


def _merged(base: dict[str, Any], given: dict[str, Any]) -> dict[str, Any]:
    """`given` over `base`, nested dicts key by key (a preset's env kwargs under the recipe's)."""
    out = dict(base)
    for key, value in given.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out
