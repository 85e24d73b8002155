"""Recipes: a study as a TOML file of steps, validated before anything runs.

    name = "pendulum"
    description = "..."
    imports = ["mypkg.envs"]   # optional: your modules that register env ids (or env = "mypkg.envs:MyArm-v0")
    parallel_steps = 2         # optional: training steps that need nothing from each other run at once,
                               # each its own process, at most 2 (default 1: one step after another)
    demo = "tiny budgets, 2 seeds per arm: it shows the pipeline"
                               # optional: why its budgets or seeds are small on purpose, shown with its findings

    [defaults]                 # fields every step gets unless it sets them (where its kind has them)
    env = "InvertedPendulum-v5"

    [[steps]]
    name = "ppo"               # the step's run folder: <study>/<name>/ (<name>/seed<k>/ with several seeds)
    kind = "train"
    algo = "ppo"
    timesteps = 100000
    seeds = 3                  # optional: one run per seed (0, 1, 2; or a list), run in parallel;
                               # `seeds = N` at the top of the file applies to every training step
    until_solved = true

    [[steps]]
    name = "ppo-on-delay"
    kind = "evaluate"
    policy = "@ppo"            # the policy trained by an earlier step (or pid, pid:kp=..., a folder)
    delay = 0.2

    [[findings]]               # optional: the numbers the study is about, first in its report
    step = "ppo"               # (default: each step's own, e.g. a training's steps to success)
    key = "steps_to_success"   # a key of the step in the study's summary.json ("ppo.steps_to_success")
    label = "PPO: env steps until solved"

A step's fields are its kind's settings (`motorlab recipes --kinds` lists them, with their
defaults); "@step" names an earlier step's output. Bundled recipes live in motorlab/recipes/
and are addressed by name.

Any field can be set from the command line, `motorlab run RECIPE --set KEY=VALUE` (VALUE as TOML
reads it, else a string): KEY is FIELD (every step whose kind has it) or STEP.FIELD (one step). A
recipe that needs something only its user has (a file) names it in `[inputs]` and uses it as
"${NAME}" in its values; `--set NAME=VALUE` gives it, and the recipe does not run without it:

    [inputs]
    sar = "the SAR to train in: a sar.npz (motorlab synergies import-sklearn FOLDER --trust --out sar.npz)"

    [[steps]]
    name = "sar-rl"
    sar = "${sar}"

An input given as a table may have a default (then --set is optional) and named choices, each
standing for the value that fills "${NAME}" (`--set terrain=hilly` below):

    [inputs]
    terrain = { help = "the terrain", default = "rough", choices = { rough = "myoLegRoughTerrainWalk-v0", hilly = "myoLegHillyTerrainWalk-v0" } }
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, create_model

from motorlab.envs import ENV_KEYS, EnvConfig
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.kinds import DEFAULT_KIND, KINDS, kind, providers
from motorlab.settings import Settings, UserCode, check_user_code
from motorlab.stepkind import StepKind
from motorlab.user_modules import import_modules

SEEDS = "seeds"  # a training step's field: run it once per seed
INPUT = re.compile(r"\$\{([A-Za-z_][\w-]*)\}")  # "${NAME}": a recipe input, given with --set NAME=VALUE


@dataclass
class Step:
    """One validated step. `fields` are its recipe fields with "@step" references as written;
    `settings` are those fields validated (references still as "@step")."""

    name: str
    kind: StepKind
    fields: dict[str, Any]
    settings: Settings
    seeds: list[int] | None = None

    def inputs(self) -> list[str]:
        """Names of the earlier steps this step reads."""
        return [name for ref in self.kind.refs for name in refs_in(self.fields.get(ref.field))]


@dataclass
class Recipe:
    name: str
    steps: list[Step]
    description: str = ""
    source: str = ""
    parallel_steps: int = 1
    findings: list[FindingSpec] = field(default_factory=list)
    demo: str | None = None  # why its budgets or seeds are small on purpose (see _RecipeFile.demo)


class FindingSpec(BaseModel):
    """One number a study is about (`[[findings]]` in a recipe): a headline key of one step."""

    model_config = ConfigDict(extra="forbid")

    step: str = Field(description="The step's name")
    key: str = Field(description="Its headline key, as in the study's summary.json after \"<step>.\"")
    label: str | None = Field(None, description="What the report calls it (default: the step and the number's label)")


class RecipeInput(BaseModel):
    """One of a recipe's `[inputs]` given as a table: `--set NAME=VALUE` fills its "${NAME}"
    (an input given as a plain string is its help, and required)."""

    model_config = ConfigDict(extra="forbid")

    help: str = Field(description="What to give, and where to get it")
    default: Any = Field(None, description="Used when no --set gives it (none: the recipe needs --set NAME=VALUE)")
    choices: dict[str, Any] | None = Field(None, description="The names --set NAME=... accepts, each with the value "
                                           "that fills \"${NAME}\" (a table: rough = \"myoLegRoughTerrainWalk-v0\")")


class _RecipeFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str
    description: str = ""
    seeds: int | list[int] | None = None  # every training step that sets none: seeds 0..N-1 (or this list)
    parallel_steps: int = Field(1, ge=1)  # training steps that need nothing from each other, run at once
    imports: list[str] = Field(default_factory=list)  # the user's modules that register its envs
    inputs: dict[str, str | RecipeInput] = Field(default_factory=dict)  # NAME -> what --set NAME=VALUE gives
    defaults: dict[str, Any] = Field(default_factory=dict)
    steps: list[dict[str, Any]] = Field(min_length=1)
    findings: list[FindingSpec] = Field(default_factory=list)  # default: each step's own (see StepKind.findings)
    demo: str | None = Field(None, min_length=1, description=(
        "A quick or demo recipe whose budgets or seeds per arm are small on purpose says why, in a line (\"tiny "
        "budgets, 2 seeds per arm: it shows the pipeline\"); the study shows it with its findings "
        "(results.json, report.html, the printed summary, the Python API's Study). A full comparison sets none and "
        "runs at least 5 seeds per arm"))


def fields_of(step_kind: StepKind) -> set[str]:
    """The fields a recipe step of this kind may set."""
    return step_kind.settings.fields() | ({SEEDS} if step_kind.trains else set())


def step_union() -> TypeAdapter:
    """A recipe's [[steps]] table as one type, built from the registry: a union of every kind's
    settings told apart by `kind` (a discriminated union). Its JSON Schema (`motorlab recipes
    --schema`) lets an editor check a recipe as it is written."""
    env_fields = {key: (EnvConfig.model_fields[field].annotation, EnvConfig.model_fields[field])
                  for key, field in ENV_KEYS.items() if key != "env"}
    models = []
    for k in KINDS.values():
        fields: dict[str, Any] = {"kind": (Literal[k.name], ...), "name": (str, ...)}
        fields.update({f: (info.annotation, info) for f, info in k.settings.model_fields.items()})
        for alias in k.settings.aliases:  # the flat env settings: env = "id", delay, history, ...
            fields[alias] = (str | None, Field(None, description="Gymnasium env id")) if alias == "env" else env_fields[alias]
        if k.trains:
            fields[SEEDS] = (int | list[int] | None, Field(None, description="Run once per seed: a count or a list"))
        models.append(create_model(f"{type(k).__name__.removesuffix('Kind')}Step", __doc__=type(k).__doc__,
                                   __config__=ConfigDict(extra="forbid"), **fields))
    return TypeAdapter(Annotated[Union[tuple(models)], Field(discriminator="kind")])


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


def refs_in(value: Any) -> list[str]:
    """Step names referenced ("@name") in a field value (a string, a list, or a dict of lists)."""
    items = value if isinstance(value, list) else list(value.values()) if isinstance(value, dict) else [value]
    flat = [x for item in items for x in (item if isinstance(item, list) else [item])]
    return [x[1:] for x in flat if isinstance(x, str) and x.startswith("@")]


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


def _check_refs(step_kind: StepKind, fields: dict, steps: list[Step], where: str) -> dict[str, Settings]:
    """Every "@step" names an earlier step providing what the field needs; returns the settings of
    the step each single-valued reference names, by field."""
    referenced = {}
    for ref in step_kind.refs:
        if ref.field not in fields:
            continue
        wanted = providers(ref.accepts)
        for name in refs_in(fields[ref.field]):
            target = next((s for s in steps if s.name == name), None)
            if target is None or target.kind.name not in wanted:
                names = ", ".join(s.name for s in steps if s.kind.name in wanted) or "none"
                label = " or ".join(wanted)
                raise MotorlabError(f"{where}: {ref.field} '@{name}' names no earlier {label} step; "
                                    f"{label} steps so far: {names}.")
            if isinstance(fields[ref.field], str):
                referenced[ref.field] = target.settings
    return referenced


def _seeds(value: Any) -> list[int] | None:
    if isinstance(value, int) and not isinstance(value, bool) and value > 0:
        return list(range(value))  # seeds = N: 0..N-1
    if value is not None and (not isinstance(value, list) or not value or len(set(value)) != len(value)
                              or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in value)):
        raise MotorlabError("seeds must be a count (seeds = 5: seeds 0..4) or a list of distinct "
                            "non-negative integers (seeds = [0, 1, 2]).")
    return value


def _without_refs(step_kind: StepKind, fields: dict[str, Any]) -> dict[str, Any]:
    """The fields with optional references left out: what can be checked before the study runs
    (a SAR a fit step will write does not exist yet)."""
    out = dict(fields)
    for ref in step_kind.refs:
        info = step_kind.settings.model_fields.get(ref.field)
        if refs_in(out.get(ref.field)) and (info is None or not info.is_required()):
            out.pop(ref.field)
    return out


Announce = Callable[[list[str]], None]  # told what validating a recipe will import

# A step's name is its run folder's name inside the study: a slug, never a path
STEP_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
RESERVED_NAMES = ("plots", "logs")  # folders the study itself writes


def check_step_name(name: str, where: str) -> None:
    """A step name is a safe folder name: letters, digits, '-', '_' and '.', not a study folder's own."""
    if not STEP_NAME.fullmatch(name) or name in RESERVED_NAMES or len(name) > 100:
        why = (f"{name!r} is a folder the study writes itself" if name in RESERVED_NAMES
               else f"{name!r} is not a plain folder name")
        raise MotorlabError(f"{where}: step name {why}; name steps with letters, digits, '-', '_' and '.' "
                            "(e.g. name = \"ppo-delay\"), not 'plots' or 'logs'.")


def code_it_imports(data: dict[str, Any]) -> list[str]:
    """The Python code validating a recipe runs (see docs/concepts.md, Safety): its `imports`, and
    the modules (or .py files) of every field that names the user's code (UserCode: env ids written
    MODULE:ID, reward functions, a planner's reward and termination, zero-shot envs)."""
    every = set().union(*map(code_fields, KINDS.values()))
    steps = [(data.get("defaults") or {}, every),
             *((s, code_fields(k) if (k := KINDS.get(str(s.get("kind", DEFAULT_KIND)))) else every)
               for s in data.get("steps") or [] if isinstance(s, dict))]
    found = [str(m) for m in data.get("imports") or []]
    for fields, names in steps:
        for name in names & set(fields):
            values = fields[name] if isinstance(fields[name], list) else [fields[name]]
            found += [v.rsplit(":", 1)[0] for v in values if isinstance(v, str) and ":" in v and not v.startswith("@")]
    return list(dict.fromkeys(found))


def code_fields(step_kind: StepKind) -> set[str]:
    """A kind's recipe fields that name the user's code (marked UserCode; its flat env settings' too),
    and env and reward, which name it written MODULE:NAME."""
    def marked(info: Any) -> bool:
        return any(isinstance(m, UserCode) for m in info.metadata)

    model = step_kind.settings
    own = {name for name, info in model.model_fields.items() if marked(info)}
    flat = {key for key, field in ENV_KEYS.items() if key in model.aliases and marked(EnvConfig.model_fields[field])}
    return own | flat | ({"env", "reward"} & model.fields())


def parse_recipe(text: str, source: str = "<recipe>", announce: Announce | None = None) -> Recipe:
    """Validate a recipe's text; every step is checked before any runs.

    Args:
        announce: called with the modules and files validating imports (its `imports`, env
            modules, reward functions), before any is imported (`motorlab run --check` prints them).

    Raises:
        MotorlabError: TOML syntax, unknown or mistyped field (named with file and step),
            reference to an unknown or later step, a step name that is not a plain folder name.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise MotorlabError(f"{source}: not valid TOML ({e}).") from None
    try:
        raw = _RecipeFile.model_validate(data)
    except ValidationError as e:
        raise MotorlabError(_explain(e, source, set(_RecipeFile.model_fields))) from None
    defaults = {name: input_value(name, spec, spec.default, source) for name, spec in raw.inputs.items()
                if isinstance(spec, RecipeInput) and spec.default is not None}
    if defaults:  # the inputs no --set gave: their defaults fill the values read again
        for name, value in defaults.items():
            data = _fill(data, name, value)
        raw = _RecipeFile.model_validate(data)
    _missing_inputs({"defaults": raw.defaults, "steps": raw.steps}, raw.inputs, source)
    for i, given in enumerate(raw.steps):  # names first: they become folders
        check_step_name(str(given.get("name", f"step{i + 1}")), f"{source}: steps[{i}]")
    if announce is not None:
        announce(code_it_imports({"imports": raw.imports, "defaults": raw.defaults, "steps": raw.steps}))
    import_modules(raw.imports, f"{source}: imports")  # before the steps are checked: they register the envs
    all_fields = set().union(*(fields_of(k) for k in KINDS.values()))
    unknown_defaults = [k for k in raw.defaults if k not in all_fields]
    if unknown_defaults:
        k = unknown_defaults[0]
        raise MotorlabError(f"{source}: [defaults]: unknown field {k!r}{did_you_mean(k, all_fields)}")
    steps: list[Step] = []
    for i, given in enumerate(raw.steps):
        name = str(given.get("name", f"step{i + 1}"))
        where = f"{source}: steps[{i}] ({name})"
        try:
            step_kind = kind(str(given.get("kind", DEFAULT_KIND)))
        except MotorlabError as e:
            raise MotorlabError(f"{where}: {e}") from None
        known = fields_of(step_kind)
        fields = {**({SEEDS: raw.seeds} if step_kind.trains and raw.seeds is not None else {}),
                  **{k: v for k, v in raw.defaults.items() if k in known},
                  **{k: v for k, v in given.items() if k not in ("name", "kind")}}
        if any(s.name == name for s in steps):
            raise MotorlabError(f"{where}: another step is already named {name!r}; step names must be unique.")
        unknown = [k for k in fields if k not in known]
        if unknown:
            raise MotorlabError(f"{where}: unknown field {unknown[0]!r}{did_you_mean(unknown[0], known)}")
        referenced = _check_refs(step_kind, fields, steps, where)
        try:
            seeds = _seeds(fields.pop(SEEDS, None))
            fields = step_kind.prepare(fields, referenced)
            settings = step_kind.validate(fields)
            checked = step_kind.validate(_without_refs(step_kind, fields))
            check_user_code(checked)  # every field naming the user's code, of any kind: its module and name
            step_kind.check(checked)
        except ValidationError as e:
            raise MotorlabError(_explain(e, where, known)) from None
        except MotorlabError as e:
            raise MotorlabError(f"{where}: {e}") from None
        steps.append(Step(name, step_kind, fields, settings, seeds))
    for i, f in enumerate(raw.findings):
        if not any(s.name == f.step for s in steps):
            names = [s.name for s in steps]
            raise MotorlabError(f"{source}: findings[{i}]: no step named {f.step!r}{did_you_mean(f.step, names)}")
    return Recipe(name=raw.name, description=raw.description, source=source, parallel_steps=raw.parallel_steps,
                  steps=steps, findings=raw.findings, demo=raw.demo)


def load_recipe(name_or_path: str, given: dict[str, Any] | None = None, announce: Announce | None = None) -> Recipe:
    """Load a bundled recipe by name, or a recipe file by path, with the fields and inputs
    `given` on the command line (`--set KEY=VALUE`) set (`announce`: see `parse_recipe`)."""
    path = find_recipe(name_or_path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise MotorlabError(f"cannot read recipe {path}: {e}") from None
    if given:
        import tomli_w

        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise MotorlabError(f"{path}: not valid TOML ({e}).") from None
        text = tomli_w.dumps(set_fields(data, given, str(path)))
    return parse_recipe(text, str(path), announce)


def toml_value(text: Any) -> Any:
    """A value given on the command line as TOML reads it (numbers, booleans, arrays, inline
    tables), else the plain string; a value that is no string (from Python) as it is."""
    if not isinstance(text, str):
        return text
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_fields(data: dict[str, Any], given: dict[str, Any], source: str, flag: str = "--set") -> dict[str, Any]:
    """A recipe's TOML data with `given` set: each KEY is one of the recipe's [inputs] (its
    "${KEY}" in values become VALUE), FIELD (every step whose kind has it) or STEP.FIELD.

    Raises:
        MotorlabError: a step name or field the recipe does not have (with close matches).
    """
    data = {**data, "steps": [dict(s) for s in data.get("steps", [])]}
    inputs = data.get("inputs", {}) if isinstance(data.get("inputs"), dict) else {}
    steps = data["steps"]
    names = [str(s.get("name", f"step{i + 1}")) for i, s in enumerate(steps)]
    for key, text in given.items():
        if key in inputs:
            spec = inputs[key]
            if isinstance(spec, dict):  # a table: its choices (and a default, which --set replaces)
                try:
                    spec = RecipeInput.model_validate(spec)
                except ValidationError as e:
                    raise MotorlabError(_explain(e, f"{source}: [inputs] {key}", set(RecipeInput.model_fields))) from None
                text = input_value(key, spec, text, source, flag)
            data = _fill(data, key, text)  # its default (if any) then fills nothing
            steps = data["steps"]
            continue
        step_name, dot, field_name = key.rpartition(".")
        value = toml_value(text)
        targets = [i for i, n in enumerate(names) if n == step_name] if dot else range(len(steps))
        if dot and not targets:
            raise MotorlabError(f"{flag} {key}: {source} has no step {step_name!r}{did_you_mean(step_name, names)}; "
                                f"steps: {', '.join(names)}.")
        hit = [i for i in targets if field_name in step_fields(steps[i])]
        if not hit:
            close = did_you_mean(field_name, set().union(*map(fields_of, KINDS.values())) | set(inputs))
            if dot:
                raise MotorlabError(f"{flag} {key}: step {step_name!r} of {source} has no field {field_name!r}{close}.")
            raise MotorlabError(f"{flag} {key}: no step of {source} has a field {field_name!r}"
                                f"{', nor is it one of its [inputs]' if inputs else ''}{close}.")
        for i in hit:
            steps[i][field_name] = value
    return data


def input_value(name: str, spec: RecipeInput, text: Any, source: str, flag: str = "--set") -> Any:
    """What fills "${name}" when `text` is given for it: the value of that choice (or `text` itself
    for an input without choices).

    Raises:
        MotorlabError: `text` is none of the input's choices.
    """
    if spec.choices is None:
        return text
    picked = str(text)
    if picked not in spec.choices:
        raise MotorlabError(f"{flag} {name}={picked}: {source} takes {name} = {' | '.join(spec.choices)}"
                            f"{did_you_mean(picked, spec.choices)}.")
    return spec.choices[picked]


def _fill(value: Any, name: str, text: Any) -> Any:
    """`value` with "${name}" replaced by `text` in every string, however deep (a whole "${name}"
    becomes the value as TOML reads it)."""
    if isinstance(value, str):
        if value == f"${{{name}}}":
            return toml_value(text)
        return value.replace(f"${{{name}}}", str(text))
    if isinstance(value, list):
        return [_fill(v, name, text) for v in value]
    if isinstance(value, dict):
        return {k: (v if k == "inputs" else _fill(v, name, text)) for k, v in value.items()}
    return value


def step_fields(step: dict[str, Any]) -> set[str]:
    """The fields of a recipe step's kind (none for a kind the recipe check will refuse)."""
    try:
        return fields_of(kind(str(step.get("kind", DEFAULT_KIND))))
    except MotorlabError:
        return set()


def _missing_inputs(data: Any, inputs: dict[str, str | RecipeInput], source: str) -> None:
    """One line for the first "${NAME}" no --set gave."""
    found = INPUT.findall(repr(data))
    if not found:
        return
    name = found[0]
    if name not in inputs:
        raise MotorlabError(f"{source}: \"${{{name}}}\" is not one of its [inputs]"
                            f"{did_you_mean(name, inputs)}; declare it there, or write the value itself.")
    spec = inputs[name]
    what = spec.help if isinstance(spec, RecipeInput) else spec
    raise MotorlabError(f"{source} needs --set {name}=VALUE: {what}.")
