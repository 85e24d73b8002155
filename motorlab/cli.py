"""The `motorlab` command: one sub-command per step kind, each building that kind's settings
from its flags and calling the kind's `run` (the same the recipes and the Python API call).

User mistakes (motorlab.errors.MotorlabError, invalid settings) print one line
and exit with status 2; an interrupted step exits with 130 and leaves its run
folder without summary.json, i.e. visibly unfinished.
"""

from __future__ import annotations

import functools
import inspect
import json
import os
import shlex
import sys
import tomllib
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, Literal, Optional, Union, get_args, get_origin, get_type_hints

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering works without a display

import gymnasium as gym  # noqa: E402
import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.markup import escape  # noqa: E402
from rich.table import Table  # noqa: E402
from typer.core import TyperGroup  # noqa: E402

from motorlab import trackers  # noqa: E402
from motorlab.control.steps import MBRL, MPC  # noqa: E402
from motorlab.dynamics.steps import (  # noqa: E402
    DYNAMICS_CHECK,
    DYNAMICS_COLLECT,
    DYNAMICS_FIT,
)
from motorlab.envs import DISTURBANCES, EnvConfig, describe_env, early_end_label, register_myosuite  # noqa: E402
from motorlab.errors import MotorlabError, mask_url  # noqa: E402
from motorlab.evaluation.steps import EVALUATE, ZEROSHOT, EvaluateSettings, ZeroshotSettings, settings_for  # noqa: E402
from motorlab.kinds import KINDS  # noqa: E402
from motorlab.recipes import bundled, fields_of, load_recipe, step_union  # noqa: E402
from motorlab.report.steps import COMPARE, VIDEO, CompareSettings  # noqa: E402
from motorlab.rl.config import TrainConfig  # noqa: E402
from motorlab.rl.steps import TRAIN  # noqa: E402
from motorlab.robustness.steps import ROBUSTNESS, RobustnessSettings  # noqa: E402
from motorlab.runs import folder_mode, is_complete, read_text_file, run_folders  # noqa: E402
from motorlab.settings import Settings, help_text  # noqa: E402
from motorlab.stepkind import StepKind  # noqa: E402
from motorlab.synergy.steps import COLLECT, FIT, VAF  # noqa: E402
from motorlab.user_modules import import_modules  # noqa: E402

app = typer.Typer(
    name="motorlab",
    help=(
        "Learn motor control of simulated bodies in MuJoCo.\n\n"
        "Each command is one step; it writes a run folder (--out, default runs/<step>-<time>) with "
        "config.toml, summary.json, metrics.csv, tensorboard/ and plots/.\n\n"
        "Start here:  motorlab run pendulum   (the robust-pendulum study, a few minutes)\n\n"
        "Your own env: any command takes Gymnasium's MODULE:ID form (motorlab train mypkg.envs:MyArm-v0), "
        "or --import MODULE (repeatable, anywhere on the line) for a module that registers several ids; "
        "run folders record the modules, so later commands on them import them again."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)
synergies = typer.Typer(help="Synergies of muscles or motor commands: collect, VAF, fit, import or export a SAR.",
                        no_args_is_help=True, rich_markup_mode="rich")
app.add_typer(synergies, name="synergies")
dynamics = typer.Typer(help="Forward models: collect transitions, fit a model, check it against the simulator.",
                       no_args_is_help=True, rich_markup_mode="rich")
app.add_typer(dynamics, name="dynamics")
GROUPS = {"": app, "synergies": synergies, "dynamics": dynamics}

err = Console(stderr=True)
# Wide enough for study tables when output goes to a file or CI log.
stdout = Console(width=None if sys.stdout.isatty() else 150)


def command(kind: StepKind, epilog: str = ""):
    """Register the decorated function as the CLI command that runs `kind` (its `command`); its
    help is the function's docstring, else the kind's."""
    *group, name = kind.command.split()

    def register(fn):
        return GROUPS[" ".join(group)].command(name, epilog=epilog, help=fn.__doc__ or _doc(kind))(fn)

    return register


def _doc(kind: StepKind) -> str:
    return (type(kind).__doc__ or "").strip()


def opt(model: type, *flags: str, **kw: Any) -> Any:
    """An option whose help (and default, shown in it) is that of the settings field its first flag
    names (--n-synergies: n_synergies; --normalize/--no-normalize: normalize)."""
    field = flags[0].split("/")[0].removeprefix("--").replace("-", "_")
    return typer.Option(*flags, help=help_text(model, field), **kw)


def arg(model: type, field: str) -> Any:
    return typer.Argument(help=help_text(model, field))


def kind_command(kind: StepKind, argument: str, epilog: str = "", flags: dict[str, tuple[str, ...]] | None = None,
                 out_help: str = "Run folder to write (default: runs/<step>-<timestamp>).", track: bool = False):
    """Register a command whose options are `kind`'s settings, one per field (`argument` is the
    positional one): their types, defaults and help come from the settings model, nothing is
    written twice. The decorated function reports the summary: `report(summary, settings)`.
    `track`: the command takes --track (experiment tracking)."""
    flags = flags or {}

    def register(report):
        params, convert = [], {}
        # the kind's own fields first, then those of the bases it shares with other kinds (a planner's, a model's)
        own = list(kind.settings.__dict__.get("__annotations__", {}))
        fields = sorted(kind.settings.model_fields.items(),
                        key=lambda item: own.index(item[0]) if item[0] in own else len(own))
        for name, info in fields:
            kind_of, convert[name] = _cli_type(info.annotation, "--" + name.replace("_", "-"))
            text = help_text(kind.settings, name)
            if name == argument:
                params.insert(0, inspect.Parameter(name, inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                                   annotation=Annotated[kind_of, typer.Argument(help=text)]))
                continue
            names = flags.get(name, ("--" + name.replace("_", "-"),))
            limits = {"min": 0} if name == "seed" else {}
            if kind_of is bool:  # a switch: absent is the field's default; one that is on by default can be turned off
                if info.default is True and len(names) == 1:
                    names = (f"{names[0]}/--no-{names[0].removeprefix('--')}",)
                default, annotation = info.default, Annotated[bool, typer.Option(*names, help=text)]
            elif info.is_required():
                default, annotation = inspect.Parameter.empty, Annotated[kind_of, typer.Option(*names, help=text)]
            else:
                default, annotation = None, Annotated[Optional[kind_of], typer.Option(*names, help=text, **limits)]
            params.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default,
                                            annotation=annotation))
        params.append(inspect.Parameter("out", inspect.Parameter.KEYWORD_ONLY, default=None, annotation=Annotated[
            Optional[Path], typer.Option("--out", help=out_help)]))
        params.append(inspect.Parameter("overwrite", inspect.Parameter.KEYWORD_ONLY, default=False,
                                        annotation=Overwrite))
        if track:
            params.append(inspect.Parameter("track", inspect.Parameter.KEYWORD_ONLY, default=None, annotation=Track))

        def run_command(**given: Any) -> None:
            out, tracked, overwrite = given.pop("out"), given.pop("track", None), given.pop("overwrite")
            settings = kind.make(**{k: convert[k](v) for k, v in given.items() if v is not None})
            trackers.enable(tracked)
            with run_folders("overwrite" if overwrite else "new"):
                summary = kind.run(settings, out)
            report(summary, settings)

        run_command.__signature__ = inspect.Signature(params)
        run_command.__annotations__ = {p.name: p.annotation for p in params}
        run_command.__name__, run_command.__doc__ = report.__name__, report.__doc__
        return command(kind, epilog)(run_command)

    return register


def _cli_type(annotation: Any, flag: str) -> tuple[type, Any]:
    """The type a command-line value of a settings field is read as, and how it becomes the field's
    value: numbers and text as they are, choices as text (the settings check them), lists of
    numbers as "64,64"."""
    args = [a for a in get_args(annotation) if a is not type(None)]
    base = args[0] if get_origin(annotation) in (Union, UnionType) and len(args) == 1 else annotation
    if get_origin(base) is Literal:
        return str, str
    if get_origin(base) is list and get_args(base)[0] in (int, float):
        item = get_args(base)[0]

        def numbers(text: str) -> list:
            try:
                return [item(x) for x in text.split(",") if x.strip()]
            except ValueError:
                raise MotorlabError(f"{flag} {text!r}: write numbers separated by commas, e.g. 64,64.") from None

        return str, numbers
    if get_origin(base) is list:
        return list[str], list
    return base, (lambda v: v)


Out = Annotated[Optional[Path], typer.Option("--out", help="Run folder to write (default: runs/<step>-<timestamp>).")]
Overwrite = Annotated[bool, typer.Option(
    "--overwrite", help="Replace the finished run in --out, whole (TensorBoard events too). Without it, a folder "
                        "holding a finished run is refused. The old run is deleted only once the new one finishes; "
                        "if the new one fails or is interrupted, the old one is put back.")]
Seed = Annotated[Optional[int], typer.Option("--seed", min=0, help="Random seed (default 0).")]
Track = Annotated[Optional[list[str]], typer.Option(
    "--track", help="Also log the run, live, to an experiment tracker (repeatable): mlflow (a SQLite store: "
                    "$MLFLOW_TRACKING_URI, else ./mlflow.db), mlflow=URI (sqlite:///PATH, file:///PATH, "
                    "http://HOST:PORT), wandb (Weights & Biases, offline without an API key: `wandb sync` uploads "
                    "it later) or wandb=PROJECT. Settings, TensorBoard's scalars, summary and plots; a sweep's, "
                    "study's or tune's runs nest under theirs. Needs pip install 'motorlab\\[mlflow]' or "
                    "'motorlab\\[wandb]'.")]
# where sweep's and tune's trials run (motorlab.sweeps.backends)
Backend = Annotated[str, typer.Option(
    help="local: a pool of processes on this machine; ray: Ray Tune on a cluster (--address) or a Ray "
         "instance started here.")]
RayAddress = Annotated[Optional[str], typer.Option(
    help="Ray cluster address HOST:PORT (from `ray start --head`); every node must see --out at the same path.")]
Delay = Annotated[Optional[str], opt(EnvConfig, "--delay")]
DelayOn = Annotated[Optional[str], opt(EnvConfig, "--delay-on")]
History = Annotated[Optional[int], opt(EnvConfig, "--history")]
Success = Annotated[Optional[str], opt(EnvConfig, "--success")]
EnvArgs = Annotated[Optional[list[str]], typer.Option(
    "--env-arg", help="Env keyword argument KEY=VALUE (VALUE as JSON), repeatable: --env-arg time_limit=5 "
                      "--env-arg 'init_rand={\"pitch\": 0.1}' (Upkie).")]


def _env_flags(env: str | None, delay, delay_on, history, reward=None, sar=None, phi=None,
               env_args: list[str] | None = None, success: str | None = None,
               disturbances: dict[str, Any] | None = None) -> dict:
    given = {"id": env, "delay": delay, "delay_on": delay_on, "history": history, "reward": reward,
             "sar": str(sar) if sar else None, "phi": phi, "success": success,
             "kwargs": _parse_sets(env_args, "--env-arg") if env_args else None, **(disturbances or {})}
    return {k: v for k, v in given.items() if v is not None}


def disturbance_options(fn):
    """Give a command one option per disturbance setting (--obs-noise, --latency, --push-body, ...;
    type, choices and help from EnvConfig, written once there). The command receives the given ones
    as `disturbances`, a dict."""
    signature = inspect.signature(fn)
    added = []
    for name in DISTURBANCES:  # as text: amounts may be ranges (0..0.02), the settings check and convert them
        added.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=Annotated[
            Optional[str], opt(EnvConfig, "--" + name.replace("_", "-"))]))
    hints = get_type_hints(fn, include_extras=True)  # the module's annotations are strings (__future__)
    params = [p.replace(annotation=hints.get(p.name, p.annotation)) for p in signature.parameters.values()
              if p.name != "disturbances"] + added

    @functools.wraps(fn)
    def command(**given: Any):
        disturbances = {k: v for k in DISTURBANCES if (v := given.pop(k)) is not None}
        return fn(**given, disturbances=disturbances)

    command.__signature__ = signature.replace(parameters=params)
    command.__annotations__ = {p.name: p.annotation for p in params}
    return command


def overwrite_option(fn):
    """Give a hand-written command --overwrite (see `Overwrite`): it runs inside
    `run_folders("overwrite")`, else `run_folders("new")`, which refuses to write into a finished run."""
    signature = inspect.signature(fn)
    hints = get_type_hints(fn, include_extras=True)
    params = [p.replace(annotation=hints.get(p.name, p.annotation)) for p in signature.parameters.values()]
    params.append(inspect.Parameter("overwrite", inspect.Parameter.KEYWORD_ONLY, default=False, annotation=Overwrite))

    @functools.wraps(fn)
    def command(**given: Any):
        with run_folders("overwrite" if given.pop("overwrite") else "new"):
            return fn(**given)

    command.__signature__ = signature.replace(parameters=params)
    command.__annotations__ = {p.name: p.annotation for p in params}
    return command


def _parse_sets(items: list[str], flag: str = "--set") -> dict:
    params = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            example = "time_limit=5" if flag == "--env-arg" else "n_steps=1024"
            raise MotorlabError(f"{flag} {item!r}: write KEY=VALUE, e.g. {flag} {example}.")
        try:
            params[key] = json.loads(value)
        except json.JSONDecodeError:
            params[key] = value
    return params


def _key_values(items: list[str], flag: str) -> dict[str, str]:
    """KEY=VALUE items as written (the recipe reads VALUE as TOML)."""
    given = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise MotorlabError(f"{flag} {item!r}: write KEY=VALUE, e.g. {flag} ppo.timesteps=50000.")
        given[key.strip()] = value
    return given


def _warn_faults(summary: Any) -> None:
    """One line when episodes ended on a numerical fault (they are counted and listed, not fatal). The
    planner's rejected candidates are warned about by the planning kinds themselves."""
    n = getattr(summary, "episode_faults", None)
    if n is None:
        n = getattr(summary, "numerical_faults", 0) or 0
    if n:
        err.print(f"[yellow]warning[/yellow]: {n} episode{'s' if n > 1 else ''} ended on a numerical fault "
                  f"(NaN/Inf or a diverging simulation); reasons in {summary.run_dir}/faults.log", soft_wrap=True)


# ---- train ------------------------------------------------------------------------------------

T = TrainConfig


@command(TRAIN, epilog="Examples:\n\n  motorlab train InvertedPendulum-v5 --until-solved --out runs/ppo\n\n"
                       "  motorlab train InvertedPendulum-v5 --preset fast --delay 0.2 --until-solved\n\n"
                       "  motorlab train InvertedPendulum-v5 --preset-file runs/tune/best.toml --seed 7\n\n"
                       "  motorlab train InvertedPendulum-v5 --algo ppo --lr linear:3e-4,0 --clip-range linear:0.3,0.1 "
                       "--history 10 --delay 0.2\n\n"
                       "  motorlab train Upkie-PyBullet-Pendulum --n-envs 2 --timesteps 150000 "
                       "--env-arg 'init_rand={\"pitch\": 0.1}'")
@overwrite_option
@disturbance_options
def train(
    env_id: Annotated[Optional[str], typer.Argument(
        help="Gymnasium env id, e.g. InvertedPendulum-v5 (may be left out with --config).")] = None,
    config: Annotated[Optional[Path], typer.Option(
        "--config", help="Start from a run's config.toml (repeat a run, or run one a sweep or study planned); "
                         "flags given here override it.")] = None,
    resume: Annotated[Optional[Path], typer.Option(
        "--resume", help="Continue the interrupted run in this folder from its last checkpoint, to the same "
                         "total budget, with its own settings.")] = None,
    checkpoint_every: Annotated[Optional[int], opt(T, "--checkpoint-every")] = None,
    algo: Annotated[Optional[str], opt(T, "--algo")] = None,
    preset: Annotated[Optional[str], typer.Option(
        help="Named settings: fast (motorlab's most sample-efficient for balancing), sb3-ppo, sb3-sac, "
             "sar-sac (the SAR study's reference SAC), sar-sac-synergy (the same, learning_starts 5000), "
             "sar-sac-fast (the reference SAC with 4 env processes and 1 gradient step per 25 env steps: "
             "~18x faster on 2 cores), upkie-balancer (Upkie's ppo_balancer: randomized action lag, "
             "action and observation noise, random initial state, history 10). Flags override it.")] = None,
    preset_file: Annotated[Optional[Path], typer.Option(
        "--preset-file", help="A TOML file of training settings (e.g. best.toml of motorlab tune), applied over "
                              "--preset and under the flags given here.")] = None,
    timesteps: Annotated[Optional[int], opt(T, "--timesteps")] = None,
    seed: Annotated[Optional[int], opt(T, "--seed", min=0)] = None,
    out: Out = None,
    delay: Delay = None,
    delay_on: DelayOn = None,
    history: History = None,
    reward: Annotated[Optional[str], opt(EnvConfig, "--reward")] = None,
    lr: Annotated[Optional[str], opt(T, "--lr")] = None,
    clip_range: Annotated[Optional[str], opt(T, "--clip-range")] = None,
    until_solved: Annotated[bool, opt(T, "--until-solved")] = False,
    her: Annotated[bool, opt(T, "--her")] = False,
    solve_episodes: Annotated[Optional[int], opt(T, "--solve-episodes")] = None,
    solve_return: Annotated[Optional[float], opt(T, "--solve-return")] = None,
    eval_every: Annotated[Optional[int], opt(T, "--eval-every")] = None,
    n_envs: Annotated[Optional[int], opt(T, "--n-envs")] = None,
    normalize: Annotated[Optional[bool], opt(T, "--normalize/--no-normalize")] = None,
    device: Annotated[Optional[str], opt(T, "--device")] = None,
    sar: Annotated[Optional[Path], opt(EnvConfig, "--sar")] = None,
    phi: Annotated[Optional[float], opt(EnvConfig, "--phi")] = None,
    hp: Annotated[Optional[list[str]], typer.Option(
        "--set", help="Extra SB3 hyperparameter KEY=VALUE (VALUE as JSON), repeatable: --set n_steps=1024.")] = None,
    env_arg: EnvArgs = None,
    success: Success = None,
    progress: Annotated[bool, opt(T, "--progress/--no-progress")] = True,
    track: Track = None,
    disturbances: dict[str, Any] | None = None,
):
    """Train a policy on ENV_ID and write a run folder.

    The folder holds config.toml, metrics.csv, tensorboard/, the policy (policy.json +
    policy.safetensors, pickle-free; SB3's model.zip for continuing training) and
    summary.json with steps_to_success (null if the budget ran out first) and wall_seconds.
    """
    settings = {
        "algo": algo, "preset": preset, "preset_file": str(preset_file.resolve()) if preset_file else None,
        "timesteps": timesteps, "seed": seed, "lr": lr, "clip_range": clip_range,
        "until_solved": until_solved or None, "her": her or None, "solve_episodes": solve_episodes, "solve_return": solve_return,
        "eval_every": eval_every, "n_envs": n_envs, "normalize": normalize, "device": device, "progress": progress,
        "checkpoint_every": checkpoint_every,
        "env": _env_flags(env_id, delay, delay_on, history, reward, sar, phi, env_arg, success, disturbances),
    }
    if hp:
        settings["hyperparams"] = _parse_sets(hp)
    settings = {k: v for k, v in settings.items() if v is not None}
    if resume is not None:
        _resume_run(resume, settings, config, out, track)
        return
    if config is not None:
        settings = _merge_config(config, settings)
    elif env_id is None:
        raise MotorlabError("give an env id (motorlab train InvertedPendulum-v5) or --config RUN/config.toml.")
    cfg = TRAIN.make(**settings)
    trackers.enable(track)
    s = TRAIN.run(cfg, out)
    sts = s.steps_to_success
    stdout.print(f"[green]done[/green] {s.run_dir}: "
                 f"return {s.eval_return_mean:.1f} (min {s.eval_return_min:.0f}) over "
                 f"{s.eval_episodes} episodes, {s.timesteps:,} steps, {s.wall_seconds:.1f} s"
                 + (f", steps_to_success {sts:,}" if sts is not None else (", not solved" if cfg.until_solved else "")))
    _warn_faults(s)


def _resume_run(run_dir: Path, settings: dict, config: Path | None, out: Path | None,
                track: list[str] | None = None) -> None:
    given = [k for k, v in settings.items() if k not in ("progress", "env") or (k == "env" and v)]
    if folder_mode() == "overwrite":
        raise MotorlabError(f"--resume continues {run_dir} and --overwrite replaces it; give one of them.")
    if given or config is not None or out is not None:
        raise MotorlabError(f"--resume continues {run_dir} with the settings in its config.toml; "
                            "drop the other settings (and --out, --config).")
    if not (run_dir / "config.toml").is_file():
        raise MotorlabError(f"{run_dir} is not a training run folder (no config.toml); give the --out of the "
                            "interrupted motorlab train.")
    if is_complete(run_dir):
        raise MotorlabError(f"{run_dir} finished already (it has summary.json); there is nothing to resume.")
    cfg = TRAIN.make(**{**_merge_config(run_dir / "config.toml", {}), "progress": settings.get("progress", True)})
    trackers.enable(track)
    s = TRAIN.run(cfg, run_dir, resume=True)
    start = s.resumed_from
    stdout.print(f"[green]done[/green] {s.run_dir}: "
                 + (f"resumed at {start:,} steps; " if start else "no checkpoint yet, started over; ")
                 + f"return {s.eval_return_mean:.1f} over {s.eval_episodes} episodes, {s.timesteps:,} steps")
    _warn_faults(s)


def _merge_config(path: Path, flags: dict) -> dict:
    """A config.toml's settings with the given flags on top (env settings merged key by key)."""
    base = read_text_file(path, tomllib.loads, "TOML", "give the config.toml of a motorlab train run.")
    merged = {**base, **{k: v for k, v in flags.items() if k != "env"}}
    merged["env"] = {**base.get("env", {}), **flags.get("env", {})}
    return merged


# ---- evaluate, zeroshot, video, compare -------------------------------------------------------

@command(EVALUATE, epilog="Examples:\n\n  motorlab evaluate runs/ppo --delay 0.2 --episodes 20\n\n"
                          "  motorlab evaluate pid --env InvertedPendulum-v5\n\n"
                          "  motorlab evaluate 'pid:kp=[1,20,0,0],kd=[1,3,0,0]' --env InvertedPendulum-v5")
@overwrite_option
@disturbance_options
def evaluate(
    policy: Annotated[str, arg(EvaluateSettings, "policy")],
    env: Annotated[Optional[str], typer.Option(help="Env id (default: the run's training env).")] = None,
    delay: Delay = None,
    delay_on: DelayOn = None,
    history: History = None,
    env_arg: EnvArgs = None,
    success: Success = None,
    episodes: Annotated[Optional[int], opt(EvaluateSettings, "--episodes")] = None,
    seed: Seed = None,
    workers: Annotated[Optional[int], opt(EvaluateSettings, "--workers", min=1)] = None,
    out: Out = None,
    disturbances: dict[str, Any] | None = None,
):
    """Evaluate a policy deterministically; print a table, write summary.json.

    summary.json: return_mean, return_std, return_min, return_max, success_rate,
    episode_lengths. Returns are the task's own (training-time reward shaping is not applied).
    """
    settings = settings_for(policy, _env_flags(env, delay, delay_on, history, env_args=env_arg, success=success,
                                               disturbances=disturbances), episodes, seed, workers)
    s = EVALUATE.run(settings, out)
    env_cfg = settings.env
    table = Table(title=f"{policy} on {describe_env(env_cfg)}")
    for col in ("episodes", "return mean ± std", "min", "max", "success", "mean length", early_end_label(env_cfg.id)):
        table.add_column(col, justify="right")
    table.add_row(str(s.episodes), f"{s.return_mean:.1f} ± {s.return_std:.1f}", f"{s.return_min:.1f}",
                  f"{s.return_max:.1f}", f"{s.success_rate:.0%}", f"{s.episode_length_mean:.0f}", str(s.falls))
    stdout.print(table)
    stdout.print(f"written: {s.run_dir}/summary.json")
    _warn_faults(s)


@command(ZEROSHOT, epilog="Example:\n\n  motorlab zeroshot runs/sar-rl runs/rl-e2e --envs myoHandReorientID-v0 "
                          "myoHandReorientOOD-v0 --episodes 500")
@overwrite_option
def zeroshot(
    run_dirs: Annotated[list[Path], arg(ZeroshotSettings, "runs")],
    envs: Annotated[list[str], opt(ZeroshotSettings, "--envs")],
    episodes: Annotated[Optional[int], opt(ZeroshotSettings, "--episodes")] = None,
    seed: Seed = None,
    workers: Annotated[Optional[int], opt(ZeroshotSettings, "--workers", min=1)] = None,
    out: Out = None,
):
    # `--envs A B`: click gives B to RUN_DIRS; an env id that is not a path belongs to --envs.
    register_myosuite()
    moved = [r for r in run_dirs if not r.exists() and str(r) in gym.registry]
    run_dirs = [r for r in run_dirs if r not in moved]
    envs = [e for item in [*envs, *map(str, moved)] for e in item.split(",") if e]
    if not run_dirs:
        raise MotorlabError("give at least one run folder and one env (--envs ID ...).")
    s = ZEROSHOT.run(ZEROSHOT.make(runs=[str(r) for r in run_dirs], envs=envs, episodes=episodes, seed=seed,
                                   workers=workers), out,
                     console=stdout)
    stdout.print(f"written: {s.run_dir}/summary.json, {s.run_dir}/plots/zeroshot.png")
    _warn_faults(s)


@command(ROBUSTNESS, epilog="Examples:\n\n"
                            "  motorlab robustness pid runs/ppo runs/ppo-history --vary delay=0:0.3:7 --episodes 20\n\n"
                            "  motorlab robustness runs/ppo --vary obs-noise=0:0.05:6 --vary latency=0:4:5\n\n"
                            "  motorlab robustness pid runs/ppo --vary push-force=0:40:5 --push-body pole "
                            "--push-direction x")
@overwrite_option
@disturbance_options
def robustness(
    policies: Annotated[list[str], arg(RobustnessSettings, "policies")],
    vary: Annotated[list[str], opt(RobustnessSettings, "--vary")],
    env: Annotated[Optional[str], typer.Option(
        help="Env id for built-in controllers (default: the first run's); with run folders, each acts in "
             "its own training env.")] = None,
    delay: Delay = None,
    delay_on: DelayOn = None,
    env_arg: EnvArgs = None,
    episodes: Annotated[Optional[int], opt(RobustnessSettings, "--episodes")] = None,
    seed: Seed = None,
    workers: Annotated[Optional[int], opt(RobustnessSettings, "--workers", min=1)] = None,
    out: Out = None,
    disturbances: dict[str, Any] | None = None,
):
    """How far each policy holds as a disturbance grows: evaluate every policy at every value of each
    --vary grid (one disturbance at a time, the others at the policy's own settings, the same reset
    seeds at every value); print a table, write curves.csv, summary.json and plots/robustness.png.

    Every policy meets the same env: the options given here (e.g. --push-body pole for --vary
    push-force, --delay-on action for --vary delay) plus the grid's disturbance. Run folders keep
    their own env id, arguments, history and synergies, not the noise or delay they trained with.
    """
    fixed = _env_flags(env, delay, delay_on, None, env_args=env_arg, disturbances=disturbances)
    s = ROBUSTNESS.run(ROBUSTNESS.make(policies=policies, vary=vary, episodes=episodes, seed=seed, workers=workers,
                                       env=fixed or None), out, console=stdout)
    stdout.print(f"written: {s.run_dir}/summary.json, curves.csv, plots/robustness.png")
    _warn_faults(s)


@kind_command(VIDEO, "run", out_help="Folder for the videos (default RUN_DIR/videos).",
              epilog="Example:\n\n  MUJOCO_GL=egl motorlab video runs/play --episodes 5 --camera hand_side_inter")
def video(s, settings) -> None:
    for path, ret in zip(s.videos, s.returns, strict=True):
        stdout.print(f"written: {path}  (return {ret:.1f})")


@command(COMPARE, epilog="Example:\n\n  motorlab compare --group SAR-RL=runs/sar-s0,runs/sar-s1 "
                         "--group RL-E2E=runs/e2e-s0,runs/e2e-s1")
@overwrite_option
def compare(
    group: Annotated[list[str], typer.Option("--group", help="LABEL=RUN_DIR[,RUN_DIR...]: one setting, its seeds.")],
    title: Annotated[Optional[str], opt(CompareSettings, "--title")] = None,
    out: Out = None,
):
    groups = {}
    for item in group:
        label, sep, runs = item.partition("=")
        if not sep or not label or not runs:
            raise MotorlabError(f"--group {item!r}: write LABEL=RUN_DIR[,RUN_DIR...], e.g. --group SAR-RL=runs/a,runs/b.")
        groups[label] = [r for r in runs.split(",") if r]
    s = COMPARE.run(COMPARE.make(groups=groups, title=title), out)
    stdout.print(f"written: {s.run_dir}/plots/learning_curves.png")


# ---- synergies --------------------------------------------------------------------------------

@kind_command(COLLECT, "run", flags={"deterministic": ("--deterministic/--stochastic",)},
              epilog="Example:\n\n  motorlab synergies collect runs/play --episodes 1000 --percentile 80 --preview 100")
def synergies_collect(s, settings) -> None:
    what = {"act": "muscle activations", "ctrl": "actuator controls", "action": "action elements"}[s.signal]
    stdout.print(f"kept {s.episodes_kept} episodes (return >= {s.threshold:.3g}), {s.samples:,} samples "
                 f"x {s.n_signals} {what} ({s.signal}) -> {s.run_dir}/activations.npz")
    _warn_faults(s)


@kind_command(VAF, "activations", epilog="Example:\n\n  motorlab synergies vaf runs/collect/activations.npz "
                                         "--threshold 0.8")
def synergies_vaf(s, settings) -> None:
    table = Table(title=f"VAF ({s.method}), {s.samples:,} samples x {s.n_muscles} muscles")
    table.add_column("N", justify="right")
    table.add_column("VAF", justify="right")
    for n, v in enumerate(s.vaf, 1):
        table.add_row(str(n), f"{v:.1%}" + (" <-" if n == s.n_for_threshold else ""))
    stdout.print(table)
    need = s.n_for_threshold
    stdout.print(f"smallest N with VAF >= {settings.threshold:.0%}: {need if need is not None else 'none'}; "
                 f"written: {s.run_dir}/vaf.png")


@kind_command(FIT, "activations", flags={"n_synergies": ("--n-synergies", "--n")},
              epilog="Examples:\n\n  motorlab synergies fit activations.npz --vaf 0.8\n\n"
                     "  motorlab synergies fit activations.npz --n 20 --method nmf")
def synergies_fit(s, settings) -> None:
    stdout.print(f"{s.n_synergies} synergies ({s.method}) for {s.n_muscles} muscles, VAF {s.vaf:.1%} -> {s.sar}")


@synergies.command("import-sklearn", help=(
    "Convert a published scikit-learn SAR (joblib pickles) to sar.npz, checked against sklearn's own inverse chain."
    "\n\nWhitening, the scaler's range and MyoSuite 3.0's scaler margin are kept exactly: the sar.npz decodes "
    "every synergy vector as pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z))) does. "
    "Nothing is unpickled without --trust."), epilog=(
    "Examples:\n\n  motorlab synergies import-sklearn published/manipulation --trust --out sar-hand.npz\n\n"
    "  motorlab synergies import-sklearn my_synergy_model --trust --out sar.npz  # MyoSuite 3.0"))
def synergies_import(
    folder: Annotated[Path, typer.Argument(help="A MyoSuite 2.x tutorial SAR (pca.pkl, ica.pkl, normalizer.pkl) or a "
                                                "MyoSuite 3.0 SynergyModel folder (pca.pkl, ica.pkl, scaler.pkl, "
                                                "metadata.npz); the layout is detected.")],
    out: Annotated[Path, typer.Option("--out", help="The sar.npz to write.")],
    trust: Annotated[bool, typer.Option("--trust", help="Allow unpickling these files (they can run code).")] = False,
):
    """Convert a published scikit-learn SAR (either MyoSuite layout) to sar.npz."""
    from motorlab.synergy.sklearn_import import import_sklearn

    sar = import_sklearn(folder, trust=trust, out=out)
    err_max = sar.metadata.get("import_check_max_abs_error")
    stdout.print(f"{sar.n_synergies} synergies x {sar.n_muscles} muscles -> {out}"
                 + (f" (decode matches scikit-learn, max abs error {err_max:.1e})" if err_max is not None else ""))


@synergies.command("export-sklearn", help=(
    "Write a SAR as a MyoSuite 3.0 SynergyModel folder, for MyoSuite's load_synergy_model."
    "\n\nThe folder holds fitted scikit-learn PCA, FastICA and MinMaxScaler (joblib) whose inverse chain equals "
    "motorlab's decode; it is checked on random synergy vectors before the folder appears. The scaler keeps the "
    "SAR's synergy range (-1 to 1 for `synergies fit`, 0 to 1 in MyoSuite's own fits)."
    "\n\npca-ica, pca and imported SARs export; nmf SARs cannot (NMF is not a PCA -> ICA chain). "
    "Needs MyoSuite: pip install 'motorlab\\[myosuite]'."), epilog=(
    "Example:\n\n  motorlab synergies export-sklearn runs/fit/sar.npz --out sar-myosuite\n\n"
    "  then in MyoSuite (sar_extraction): load_synergy_model('sar-myosuite')"))
def synergies_export(
    sar: Annotated[Path, typer.Argument(help="The sar.npz to export (from `synergies fit` or `import-sklearn`).")],
    out: Annotated[Path, typer.Option("--out", help="New folder for pca.pkl, ica.pkl, scaler.pkl, metadata.npz "
                                                    "(it must not exist, or be empty).")],
):
    """Write a SAR as a MyoSuite 3.0 SynergyModel folder (joblib pickles), checked against motorlab's decode."""
    from motorlab.synergy.sklearn_export import export_sklearn

    result = export_sklearn(sar, out)
    stdout.print(f"{result.n_synergies} synergies x {result.n_muscles} muscles -> {out} (MyoSuite's chain matches "
                 f"motorlab's decode, max abs error {result.max_abs_error:.1e})")


# ---- dynamics and MPC -------------------------------------------------------------------------

@kind_command(DYNAMICS_COLLECT, "env", epilog="Examples:\n\n  motorlab dynamics collect Reacher-v5 --episodes 20000 "
                                              "--out runs/reacher-data\n\n"
                                              "  motorlab dynamics collect InvertedPendulum-v5 --episodes 200 "
                                              "--policy runs/ppo")
def dynamics_collect(s, settings) -> None:
    stdout.print(f"{s.transitions:,} transitions ({s.state_size} state, {s.action_size} action entries) "
                 f"at {s.transitions_per_second:,.0f}/s via {s.simulator} -> {s.run_dir}/transitions.npz")
    _warn_faults(s)


@kind_command(DYNAMICS_FIT, "transitions", track=True, epilog="Examples:\n\n  motorlab dynamics fit runs/reacher-data "
                                                  "--out runs/reacher-model\n\n"
                                                  "  motorlab dynamics fit runs/reacher-data/transitions.npz "
                                                  "--hidden 128,128 --ensemble 5 --patience 5")
def dynamics_fit(s, settings) -> None:
    valid = f"valid_mse {s.valid_mse:.2e} (normalized)" if s.valid_mse is not None else "no validation"
    stdout.print(f"{valid} after {s.epochs_run} epochs, {s.wall_seconds:.1f} s -> {s.run_dir}/model.json, "
                 f"plots/loss.png")


@kind_command(DYNAMICS_CHECK, "model", epilog="Example:\n\n  motorlab dynamics check runs/reacher-model --episodes 5")
def dynamics_check(s, settings) -> None:
    keys = s.keys()
    tip = {k: v for k, v in keys.items() if k.startswith("tip_error_mean_h")}
    stdout.print("open-loop error: " + ", ".join(
        [f"{k.removeprefix('tip_error_mean_')} {v * 1000:.1f} mm" for k, v in tip.items()]
        or [f"{k.removeprefix('state_nrmse_')} {v:.3f}" for k, v in keys.items() if k.startswith("state_nrmse_h")]))
    stdout.print(f"worst entry: {s.worst_dimension} ({s.worst_dimension_nrmse:.3f} after {s.worst_dimension_horizon} "
                 f"steps); written: {s.run_dir}/error_by_dimension.csv, plots/error_vs_horizon.png, "
                 "error_by_dimension.png, traces.png")


@kind_command(MPC, "env", track=True, epilog="Examples:\n\n  motorlab mpc Reacher-v5 --model runs/reacher-model --episodes 50\n\n"
                                 "  motorlab mpc Reacher-v5 --model runs/reacher-model --optimizer evotorch --horizon 4 "
                                 "--population 250 --iterations 20 --episodes 5")
def mpc(s, settings) -> None:
    distance = f", final distance {s.final_distance_mean * 1000:.1f} mm (mean)" if s.final_distance_mean is not None else ""
    spread = f", ensemble disagreement {s.disagreement_mean:.3f}" if s.disagreement_mean is not None else ""
    stdout.print(f"return {s.return_mean:.2f} ± {s.return_std:.2f}{distance}, planning {s.plan_ms_median:.2f} ms/step "
                 f"(median){spread} over {s.episodes} episodes ({s.reward_source} reward) -> {s.run_dir}")
    _warn_faults(s)


@kind_command(MBRL, "env", track=True, epilog="Examples:\n\n  motorlab mbrl InvertedPendulum-v5 --rounds 5 --out runs/ip-mbrl\n\n"
                                  "  motorlab mbrl Pusher-v5 --rounds 20 --particles 20 --out runs/pusher-pets\n\n"
                                  "  motorlab mbrl Pusher-v5 --rounds 20 --no-probabilistic --propagation mean   "
                                  "# deterministic members\n\n"
                                  "  motorlab mbrl mypkg.envs:MyArm-v0 --reward mypkg.rewards:reach --rounds 10\n\n"
                                  "  motorlab mbrl Pusher-v5 --rounds 20 --out runs/pusher-pets --resume   # after a kill")
def mbrl(s, settings) -> None:
    """The model-based loop (PETS): collect with the planner, refit the ensemble on all data, evaluate; round by round."""
    final = f"return {s.final_return_mean:.2f}" if s.final_return_mean is not None else "no evaluation"
    resumed = (f" ({s.resumed_rounds} round{'s were' if s.resumed_rounds > 1 else ' was'} done before)"
               if s.resumed_rounds else "")
    stdout.print(f"{final} after {s.rounds} rounds, {s.env_steps:,} env steps{resumed}; planning "
                 f"{s.plan_ms_median or float('nan'):.1f} ms/step -> {s.run_dir}/curve.csv, plots/learning_curve.png")
    _warn_faults(s)


# ---- studies, sweeps, reports ------------------------------------------------------------------

@app.command(epilog="Examples:\n\n  motorlab report runs/pendulum            # -> runs/pendulum/report.html\n\n"
                    "  motorlab report runs/sar-rl runs/rl-e2e --out compare.html   # side by side")
def report(
    paths: Annotated[list[Path], typer.Argument(help="Run folders and/or study folders.")],
    out: Annotated[Optional[Path], typer.Option("--out", help="HTML file to write (default: report.html in the first PATH).")] = None,
):
    """Write one self-contained HTML report: headline tables, every plot and video, the runs
    side by side, settings, library versions and TensorBoard links. Opens offline."""
    from motorlab.report.html import build_report

    stdout.print(f"written: {build_report(paths, out)}")


@app.command(epilog="Example:\n\n  motorlab plot runs/ppo   # -> runs/ppo/plots/*.png")
def plot(run_dir: Annotated[Path, typer.Argument(help="A run folder from train or evaluate.")]):
    """Plot a run: learning curve (training runs) and the observation trace of one evaluation episode."""
    from motorlab.report.run import plot_run

    for path in plot_run(run_dir):
        stdout.print(f"written: {path}")


@app.command(epilog="Examples:\n\n  motorlab run pendulum --out runs/pendulum\n\n  motorlab run my_study.toml\n\n"
                    "Re-running an interrupted study into the same --out keeps the steps that finished with the "
                    "same settings (a train step continues from its checkpoint); a finished one needs --resume "
                    "(keep its finished steps, redo the rest) or --overwrite (replace it).")
@overwrite_option
def run(
    recipe: Annotated[str, typer.Argument(help="A bundled recipe name (pendulum) or a path to a TOML recipe.")],
    out: Out = None,
    backend: Annotated[str, typer.Option(
        help="Where the seeds of a train step with several seeds run: local (processes here) or ray.")] = "local",
    address: Annotated[Optional[str], typer.Option(help="Ray cluster HOST:PORT for --backend ray.")] = None,
    max_parallel: Annotated[Optional[int], typer.Option(
        help="Seeds trained at once (default: cores // n_envs locally).")] = None,
    parallel_steps: Annotated[Optional[int], typer.Option(
        help="Train steps that need nothing from each other (e.g. SAR-RL's chain and RL-E2E) run at once, "
             "each its own process, at most this many (default: the recipe's parallel_steps, else 1).")] = None,
    check: Annotated[bool, typer.Option("--check", help="Only validate the recipe and list its steps; run nothing. "
                                                       "Validating imports the recipe's `imports`, env modules and "
                                                       "reward files (it says which first).")] = False,
    resume: Annotated[bool, typer.Option("--resume", help="Run again into a finished study's --out: steps that "
                                                         "finished with the same settings are kept.")] = False,
    given: Annotated[Optional[list[str]], typer.Option(
        "--set", help="KEY=VALUE, repeatable: set a field of the recipe (VALUE as TOML reads it). KEY: FIELD (every "
                      "step that has it), STEP.FIELD (one step), or one of the recipe's [inputs] (--set sar=sar.npz).")
    ] = None,
    track: Track = None,
):
    """Run a study from a TOML recipe: its steps, a printed table, summary.json and plots.

    Recipe format: see `motorlab recipes` and motorlab/recipes/pendulum.toml. A recipe with
    `seeds = N` trains every train step for N seeds in parallel and reports IQMs with
    confidence intervals; `motorlab sweep RECIPE --seeds N` repeats the whole study instead.
    """
    from motorlab.studies import Execution, run_study

    mode = _resume_mode(resume)
    study = load_recipe(recipe, _key_values(given or [], "--set"), announce=_announce_imports if check else None)
    if check:
        stdout.print(f"{study.source}: valid, {len(study.steps)} steps: "
                     + ", ".join(f"{st.name} ({st.kind.name})" for st in study.steps))
        return
    trackers.enable(track)
    with run_folders(mode):
        summary = run_study(study, out, console=stdout,
                            execution=Execution(backend, address, max_parallel, parallel_steps))
    stdout.print(f"\n[bold]Results:[/bold] {summary['study_dir']}  (report.html, table.txt, summary.json, plots/*.png, "
                 "one folder per step)")


@app.command(epilog="Examples:\n\n"
                    "  motorlab sweep \"train InvertedPendulum-v5 --preset fast --until-solved\" --seeds 5\n\n"
                    "  motorlab sweep \"train InvertedPendulum-v5 --timesteps 20000\" --seeds 3 --grid lr=3e-4,1e-3 "
                    "--grid n_envs=1,2\n\n"
                    "  motorlab sweep pendulum --seeds 3 --grid ppo.timesteps=50000,100000   # a whole study per seed\n\n"
                    "  motorlab sweep \"train Reacher-v5 --algo sac\" --seeds 8 --backend ray --address 10.0.0.5:6379\n\n"
                    "Run the same command again (same --out) to resume: finished trials are kept.")
@overwrite_option
def sweep(
    target: Annotated[str, typer.Argument(
        help="A recipe (bundled name or .toml file: each trial runs the whole study) or a motorlab command line "
             "in quotes (train, evaluate, mpc, dynamics fit, ...); the sweep adds --seed and --out.")],
    seeds: Annotated[int, typer.Option("--seeds", help="Seeds per setting: 0..N-1.")] = 5,
    grid: Annotated[Optional[list[str]], typer.Option(
        "--grid", help="KEY=V1,V2 (repeatable; every combination runs). Commands: KEY is an option (lr, n_envs, "
                       "delay, normalize=true,false). Recipes: FIELD for every step that has it, or STEP.FIELD. "
                       "Values holding commas: separate them with |, e.g. lr='linear:1e-3,0|3e-4'.")] = None,
    backend: Backend = "local",
    address: RayAddress = None,
    max_parallel: Annotated[Optional[int], typer.Option(
        help="Trials at once (default: one per core locally; as many as the cluster's CPUs fit with ray).")] = None,
    out: Out = None,
    resume: Annotated[bool, typer.Option("--resume", help="Run again into a finished sweep's --out (e.g. with "
                                                         "more seeds): its finished trials are kept.")] = False,
    track: Track = None,
):
    """Run a command or a study for several seeds (and settings), then aggregate across seeds.

    Aggregates with rliable: interquartile mean (IQM) and 95% stratified-bootstrap confidence
    intervals of final return, success rate and steps-to-success; probability of improvement
    between settings; performance profiles. Writes summary.json, aggregate.json, table.txt,
    plots/ and report.html in the sweep folder, and one run folder per trial (<setting>/seed<k>/).
    """
    from motorlab.sweeps.sweep import run_sweep

    trackers.enable(track)
    with run_folders(_resume_mode(resume)):
        summary = run_sweep(target, seeds, grid, backend, address, max_parallel, out, console=stdout,
                            commands=app_commands())
    stdout.print(f"\n[bold]Results:[/bold] {summary['sweep_dir']}  (report.html, table.txt, summary.json, "
                 "aggregate.json, plots/*.png, <setting>/seed<k>/)")


@app.command(epilog="Examples:\n\n"
                    "  motorlab tune \"train InvertedPendulum-v5 --algo ppo --timesteps 50000 --until-solved\" "
                    "--space lr=loguniform:1e-5,1e-2 --space n_steps=choice:256,512,1024 --trials 40 --seeds 3 "
                    "--objective steps_to_success --out runs/tune-ppo\n\n"
                    "  motorlab tune pendulum --space ppo.timesteps=int:20000,100000 --trials 10 --seeds 2 "
                    "--objective ppo.final_return   # a whole study per seed\n\n"
                    "  motorlab train InvertedPendulum-v5 --preset-file runs/tune-ppo/best.toml --seed 7\n\n"
                    "  motorlab tune \"train Reacher-v5 --algo sac --timesteps 100000\" --space lr=loguniform:1e-4,1e-3 "
                    "--trials 50 --seeds 3 --objective final_return --backend ray --address 10.0.0.5:6379   "
                    "# Ray Tune: OptunaSearch and ASHA\n\n"
                    "Run the same command again (same --out) to resume; several processes with the same --out "
                    "(or --storage) share one search.")
@overwrite_option
def tune(
    target: Annotated[str, typer.Argument(
        help="A motorlab command line in quotes (train ...) or a recipe; each trial adds --seed and --out.")],
    space: Annotated[Optional[list[str]], typer.Option(
        "--space", help="KEY=DIST, repeatable: loguniform:LOW,HIGH, uniform:LOW,HIGH, int:LOW,HIGH or choice:A,B,C. "
                        "KEY: an option (lr, n_envs, delay), a recipe FIELD or STEP.FIELD, or an SB3 "
                        "hyperparameter (set.KEY, or any KEY that is not an option: --set KEY=VALUE).")] = None,
    trials: Annotated[int, typer.Option("--trials", help="Trials in all (COMPLETE and PRUNED), over every "
                                                         "process sharing the study.")] = 20,
    seeds: Annotated[int, typer.Option("--seeds", help="Seeds per trial (0..K-1); its value is their IQM.")] = 3,
    objective: Annotated[str, typer.Option(
        "--objective", help="steps_to_success (unsolved counts as the budget), final_return, success_rate, or "
                            "any number in the runs' summary.json (a study's: STEP.METRIC).")] = "steps_to_success",
    direction: Annotated[Optional[str], typer.Option(
        help="max or min (default: min for steps_to_success, else max).")] = None,
    storage: Annotated[Optional[str], typer.Option(
        help="Database URL of the study (default sqlite:///OUT/study.db); any URL Optuna accepts.")] = None,
    study_name: Annotated[Optional[str], typer.Option(
        help="Study name in the database (default: derived from the target, space, objective and seeds).")] = None,
    sampler: Annotated[str, typer.Option(help="tpe | random | cmaes")] = "tpe",
    sampler_seed: Annotated[Optional[int], typer.Option(
        help="Seed of the sampler: the same command samples the same settings (a resumed search goes on from "
             "where it was). Several processes sharing one search: leave it out or give each its own.")] = None,
    pruner: Annotated[str, typer.Option(
        help="median | hyperband | none (with --backend ray, Tune's schedulers: ASHA, ASHA with 3 brackets, "
             "none).")] = "median",
    prune_startup: Annotated[int, typer.Option(
        help="Finished trials before the median pruner prunes.")] = 5,
    report_every: Annotated[int, typer.Option(
        help="Env steps between the intermediate numbers reported to the pruner.")] = 1000,
    fresh_seeds: Annotated[Optional[int], typer.Option(
        help="Seeds the best settings are re-run on after the search (default: --seeds; 0: none).")] = None,
    max_parallel: Annotated[Optional[int], typer.Option(
        help="Seed processes at once (default: one per core; with ray, as many as the cluster's CPUs fit).")] = None,
    backend: Backend = "local",
    address: RayAddress = None,
    out: Out = None,
    resume: Annotated[bool, typer.Option("--resume", help="Go on with a finished search in --out (e.g. with more "
                                                         "--trials): its trials are kept.")] = False,
    track: Track = None,
):
    """Search settings with Optuna, judging each trial by the IQM of its objective over several seeds.

    Writes study.db, trials.csv, table.txt, best.toml (a preset file for train --preset-file),
    plots/, summary.json (with the best settings' numbers on fresh seeds) and report.html in the folder, and
    each trial's run folders under trials/<number>/seed<k>/.
    """
    from motorlab.tuning.tune import make_spec, run_tune

    spec = make_spec(target, space, trials, seeds, objective, direction, out, storage, study_name, sampler, pruner,
                     prune_startup, report_every, max_parallel, fresh_seeds, backend=backend,
                     address=address, sampler_seed=sampler_seed)
    trackers.enable(track)
    with run_folders(_resume_mode(resume)):
        summary = run_tune(spec, console=stdout, commands=app_commands())
    stdout.print(f"\n[bold]Results:[/bold] {summary['tune_dir']}  (best.toml, trials.csv, table.txt, summary.json, "
                 "plots/*.png, report.html, study.db)")
    shown = mask_url(spec.storage)
    stdout.print(f"The study in a browser: optuna-dashboard {shlex.quote(shown)}"
                 + (" (with the password in place of ***)" if shown != spec.storage else ""))


@app.command(epilog="Examples:\n\n  motorlab export runs/ppo --out share/ppo          # only the files safe to send\n\n"
                    "  motorlab export ppo_pendulum.zip --trust --env InvertedPendulum-v5 --out runs/imported\n\n"
                    "  motorlab export sac.zip --vecnormalize vec_normalize.pkl --trust --env Hopper-v5 --out runs/sac\n\n"
                    "  motorlab export runs/ppo --onnx --out deploy/ppo     # policy.onnx for a robot "
                    "(docs/deployment.md)")
@overwrite_option
def export(
    source: Annotated[Path, typer.Argument(help="A run folder, or an SB3 zip written by model.save.")],
    out: Annotated[Path, typer.Option("--out", help="The folder to write.")],
    trust: Annotated[bool, typer.Option("--trust", help="Allow unpickling an SB3 zip / VecNormalize file "
                                                       "(they can run code); needed for a zip only.")] = False,
    env: Annotated[Optional[str], typer.Option(help="Env id an SB3 zip's policy acts in (checked, and recorded "
                                                   "so that evaluate needs no --env).")] = None,
    vecnormalize: Annotated[Optional[Path], typer.Option(
        help="VecNormalize.save's file, if the zip's policy saw normalized observations.")] = None,
    algo: Annotated[Optional[str], typer.Option(help="ppo (also A2C), sac or td3 (default: read from the zip).")] = None,
    onnx: Annotated[bool, typer.Option(
        "--onnx", help="Write the run's policy as OUT/policy.onnx for onnxruntime on a robot (observation "
                       "normalization, history stack and action bounds inside the graph; checked against torch "
                       "to 1e-5 first) and its interface as OUT/policy.onnx.json.")] = False,
):
    """Write a policy folder that is safe to share: no pickle in it.

    From a run folder: copies policy.json, policy.safetensors, config.toml, summary.json, metrics.csv,
    plots and videos, and leaves out model.zip (a pickle), checkpoint/ and tensorboard/.
    From an SB3 zip (with --trust): loads it once and writes policy.json + policy.safetensors,
    which `motorlab evaluate`, `video` and `synergies collect` read without unpickling.
    """
    from motorlab.export import export_run, export_sb3_zip

    if onnx:
        if env or vecnormalize or algo or trust:
            raise MotorlabError("--onnx exports a run folder's policy; --trust, --env, --vecnormalize and --algo are "
                                "for SB3 zips (export the zip to a folder first, then that folder with --onnx).")
        from motorlab.deploy_onnx import export_onnx

        s = export_onnx(source, out)
        stdout.print(f"exported {s['algo'].upper()} policy to ONNX (history {s['history']}, max |onnxruntime - "
                     f"torch| {s['max_abs_error']:.1g} on {s['checked_observations']} observations) -> {s['onnx']}, "
                     f"{s['sidecar']}", highlight=False)
        return
    if source.is_dir():
        if env or vecnormalize or algo or trust:
            raise MotorlabError(f"{source} is a run folder: it is exported as it is, without --trust, --env, "
                                "--vecnormalize or --algo (those are for SB3 zips).")
        s = export_run(source, out)
        stdout.print(f"exported {len(s['exported_files'])} files (no pickle) -> {s['run_dir']}")
    else:
        s = export_sb3_zip(source, out, trust, env, vecnormalize, algo)
        stdout.print(f"{s['algo'].upper()} policy ({s['num_timesteps']:,} steps"
                     + (", normalized observations" if s["observation_normalized"] else "")
                     + f") -> {s['run_dir']}/policy.json, policy.safetensors"
                     + ("" if env else "; evaluate it with --env ENV_ID"))


@app.command()
def recipes(
    kinds: Annotated[bool, typer.Option("--kinds", help="List the step kinds a recipe can use, with their "
                                                       "fields and defaults.")] = False,
    schema: Annotated[bool, typer.Option("--schema", help="Print the JSON Schema of a recipe's [[steps]] "
                                                         "(for editors that check TOML against a schema).")] = False,
):
    """List the bundled recipes (or, with --kinds, the step kinds and their fields)."""
    if schema:
        print(json.dumps(step_union().json_schema(), indent=2))
        return
    if kinds:
        for k in KINDS.values():
            stdout.print(f"[bold]{k.name}[/bold]: {_doc(k).splitlines()[0]}")
            stdout.print("    " + ", ".join(_field_line(k.settings, f) for f in sorted(fields_of(k))),
                         highlight=False)
        return
    for name in sorted(bundled()):
        r = load_recipe(name)
        stdout.print(f"[bold]{name}[/bold]: {r.description} ({len(r.steps)} steps)")


def _resume_mode(resume: bool):
    """The run-folder mode of a command with --resume and --overwrite (`overwrite_option`)."""
    if resume and folder_mode() == "overwrite":
        raise MotorlabError("--resume keeps what finished in --out and --overwrite replaces it; give one of them.")
    return "resume" if resume else folder_mode()


def _announce_imports(code: list[str]) -> None:
    """What validating a recipe runs, said before it runs (docs: Safety)."""
    if code:
        stdout.print("validating imports (runs) this code: " + ", ".join(code), highlight=False, soft_wrap=True)


def _field_line(model: type[Settings], name: str) -> str:
    info = model.model_fields.get(name)
    if info is None:
        return name  # the flat env settings (env, delay, history, ...) and seeds
    default = info.get_default(call_default_factory=True)
    return f"{name} = {default!r}" if not info.is_required() else f"{name} (required)"


def app_commands() -> TyperGroup:
    """The command group, as sweeps and searches check their command-line targets against it."""
    return typer.main.get_command(app)


def main() -> None:
    """Entry point: run the app, turning user mistakes into one-line errors.

    Click's own mistakes (unknown option, a value of the wrong type, a missing argument) are
    caught here too, instead of in Click's standalone mode, which prints them in a box under
    the usage text: every mistake reads the same, `error: ...` on one line, exit status 2."""
    try:
        import_modules(_take_imports(sys.argv), "given with --import")
        code = app(standalone_mode=False, prog_name="motorlab")
    except typer.TyperException as e:  # Click's exceptions (typer vendors Click; this is their public base)
        if type(e).__name__ == "NoArgsIsHelpError":
            sys.exit(2)  # a command group given no command: its help was printed
        if hasattr(e, "ctx"):  # a usage error: point to the command's help
            where = e.ctx.command_path if e.ctx is not None else "motorlab"
            _error(f"{e.format_message()} (see `{where} --help`)")
        _error(e.format_message(), e.exit_code)
    except MotorlabError as e:
        _error(str(e))
    except PermissionError as e:  # a folder or file this user may not write (or read), wherever it was met
        _error(f"permission denied: {e.filename or e}; check its permissions, or choose an --out folder you can "
               "write to.")
    except KeyboardInterrupt:
        _interrupted()
    if code == 130:  # typer turns Ctrl-C into exit code 130
        _interrupted()
    sys.exit(code if isinstance(code, int) else 0)


def _take_imports(argv: list[str]) -> list[str]:
    """Remove every `--import MODULE` (or `--import=MODULE`) from argv, wherever it stands, and return the
    modules: `--import` works the same before or after any command (see the app's help)."""
    modules, rest, i = [], [argv[0]], 1
    while i < len(argv):
        a = argv[i]
        if a == "--":
            rest += argv[i:]
            break
        if a == "--import":
            if i + 1 == len(argv):
                raise MotorlabError("--import needs a module name, e.g. --import mypkg.envs.")
            modules.append(argv[i + 1])
            i += 2
            continue
        if a.startswith("--import="):
            modules.append(a.split("=", 1)[1])
        else:
            rest.append(a)
        i += 1
    argv[:] = rest
    return modules


def _error(message: str, code: int = 2) -> None:
    err.print(f"[red]error:[/red] {escape(message)}", highlight=False, soft_wrap=True)
    sys.exit(code)


def _interrupted() -> None:
    err.print("[yellow]interrupted[/yellow]: the run folder has no summary.json, so it stays marked unfinished.")
    sys.exit(130)


if __name__ == "__main__":
    main()
