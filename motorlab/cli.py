"""The `motorlab` command: one sub-command per step, each calling one library function.

User mistakes (motorlab.errors.MotorlabError, invalid settings) print one line
and exit with status 2; an interrupted step exits with 130 and leaves its run
folder without summary.json, i.e. visibly unfinished.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Annotated, Optional

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering works without a display

import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.markup import escape  # noqa: E402

from motorlab.errors import MotorlabError  # noqa: E402

app = typer.Typer(
    name="motorlab",
    help=(
        "Learn motor control of simulated bodies in MuJoCo.\n\n"
        "Each command is one step; it writes a run folder (--out, default runs/<step>-<time>) with "
        "config.toml, summary.json, metrics.csv, tensorboard/ and plots/.\n\n"
        "Start here:  motorlab run pendulum   (the robust-pendulum study, a few minutes)"
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)
err = Console(stderr=True)
# Wide enough for study tables when output goes to a file or CI log.
stdout = Console(width=None if sys.stdout.isatty() else 150)

Out = Annotated[Optional[Path], typer.Option("--out", help="Run folder to write (default: runs/<step>-<timestamp>).")]
Seed = Annotated[int, typer.Option("--seed", min=0, help="Random seed (training, env resets, evaluation).")]
Delay = Annotated[Optional[float], typer.Option(
    "--delay", help="Low-pass delay time constant TAU in seconds (alpha = dt/TAU must be in (0, 1)); e.g. 0.2.")]
DelayOn = Annotated[Optional[str], typer.Option(
    "--delay-on", help="What the delay filters: both (default: actuation and perception), action or observation.")]
History = Annotated[Optional[int], typer.Option("--history", help="Stack the last K observations (K=1: none).")]
Success = Annotated[Optional[str], typer.Option(
    "--success", help="When an episode counts as a success, from the env's per-step flag (MyoSuite: "
                      "info['solved']): any (solved at any step), final (solved at its last step), or auto "
                      "(default: final for MyoSuite's walking tasks, any otherwise).")]
EnvArgs = Annotated[Optional[list[str]], typer.Option(
    "--env-arg", help="Env keyword argument KEY=VALUE (VALUE as JSON), repeatable: --env-arg time_limit=5 "
                      "--env-arg 'init_rand={\"pitch\": 0.1}' (Upkie).")]


def _env_overrides(env: str | None, delay, delay_on, history, reward=None, sar=None, phi=None,
                   env_args: list[str] | None = None, success: str | None = None) -> dict:
    given = {"id": env, "delay": delay, "delay_on": delay_on, "history": history, "reward": reward,
             "sar": str(sar) if sar else None, "phi": phi, "success": success,
             "kwargs": _parse_sets(env_args, "--env-arg") if env_args else None}
    return {k: v for k, v in given.items() if v is not None}


def _validation_message(e, flags: bool = True) -> str:
    """One line from a pydantic ValidationError, naming the option."""
    first = e.errors()[0]
    loc = [str(x) for x in first["loc"]]
    name = loc[-1] if loc else "?"
    if name == "id":
        name = "env"
    label = f"--{name.replace('_', '-')}" if flags else ".".join(loc)
    if first["type"] == "extra_forbidden":
        return f"unknown setting {label}"
    return f"{label}: {first['msg']}"


@app.command(epilog="Examples:\n\n  motorlab train InvertedPendulum-v5 --until-solved --out runs/ppo\n\n"
                    "  motorlab train InvertedPendulum-v5 --preset fast --delay 0.2 --until-solved\n\n"
                    "  motorlab train InvertedPendulum-v5 --algo ppo --lr linear:3e-4,0 --clip-range linear:0.3,0.1 "
                    "--history 10 --delay 0.2\n\n"
                    "  motorlab train Upkie-PyBullet-Pendulum --n-envs 2 --timesteps 150000 "
                    "--env-arg 'init_rand={\"pitch\": 0.1}'")
def train(
    env_id: Annotated[Optional[str], typer.Argument(
        help="Gymnasium env id, e.g. InvertedPendulum-v5 (may be left out with --config).")] = None,
    config: Annotated[Optional[Path], typer.Option(
        "--config", help="Start from a run's config.toml (repeat a run, or run one a sweep or study planned); "
                         "flags given here override it.")] = None,
    resume: Annotated[Optional[Path], typer.Option(
        "--resume", help="Continue the interrupted run in this folder from its last checkpoint, to the same "
                         "total budget, with its own settings.")] = None,
    checkpoint_every: Annotated[Optional[int], typer.Option(
        help="Env steps between checkpoints for --resume (default: a tenth of the budget; 0: none).")] = None,
    algo: Annotated[Optional[str], typer.Option(
        help="ppo | sac | td3 (Stable-Baselines3) | lqr (model-based: linear model + LQR).")] = None,
    preset: Annotated[Optional[str], typer.Option(
        help="Named settings: fast (motorlab's most sample-efficient for balancing), sb3-ppo, sb3-sac, "
             "sar-sac (the SAR study's reference SAC), sar-sac-synergy (the same, learning_starts 5000), "
             "sar-sac-fast (the reference SAC with 4 env processes and 1 gradient step per 25 env steps: "
             "~18x faster on 2 cores). Flags override it.")] = None,
    timesteps: Annotated[Optional[int], typer.Option(help="Env-step budget (default 100000).")] = None,
    seed: Annotated[Optional[int], typer.Option(
        "--seed", min=0, help="Random seed (training, env resets, evaluation); default 0.")] = None,
    out: Out = None,
    delay: Delay = None,
    delay_on: DelayOn = None,
    history: History = None,
    reward: Annotated[Optional[str], typer.Option(
        help="Reward shaping: task, alive, quadratic, action-penalty, or module:function "
             "(fn(next_obs, action, reward, terminated, info) -> float).")] = None,
    lr: Annotated[Optional[str], typer.Option(
        help="Learning-rate schedule: 3e-4 (constant) or linear:START,END (over the budget).")] = None,
    clip_range: Annotated[Optional[str], typer.Option(help="PPO clip-range schedule, e.g. linear:0.3,0.1.")] = None,
    until_solved: Annotated[bool, typer.Option(
        "--until-solved", help="Stop once --solve-episodes deterministic episodes all reach the maximum return; "
                               "summary.json gets steps_to_success.")] = False,
    solve_episodes: Annotated[Optional[int], typer.Option(help="Episodes that must all succeed (default 10).")] = None,
    solve_return: Annotated[Optional[float], typer.Option(
        help="Return that counts as solved (default: the env's maximum, 1000 for InvertedPendulum).")] = None,
    eval_every: Annotated[Optional[int], typer.Option(
        help="Env steps between evaluations (default: every PPO rollout, 1000 for SAC/TD3, each LQR refit).")] = None,
    n_envs: Annotated[Optional[int], typer.Option(help="Parallel envs (subprocesses when > 1).")] = None,
    normalize: Annotated[Optional[bool], typer.Option(
        "--normalize/--no-normalize", help="Normalize observations with running statistics.")] = None,
    device: Annotated[Optional[str], typer.Option(help="auto (CUDA when present) | cpu | cuda.")] = None,
    sar: Annotated[Optional[Path], typer.Option(
        help="Act in synergy space: a sar.npz from `motorlab synergies fit` or `import-sklearn`.")] = None,
    phi: Annotated[Optional[float], typer.Option(
        help="With --sar: 1 = synergies only; <1 = action is [synergies, raw muscles] blended "
             "phi*decode(syn) + (1-phi)*raw (the reference used 0.66).")] = None,
    hp: Annotated[Optional[list[str]], typer.Option(
        "--set", help="Extra SB3 hyperparameter KEY=VALUE (VALUE as JSON), repeatable: --set n_steps=1024.")] = None,
    env_arg: EnvArgs = None,
    success: Success = None,
    progress: Annotated[bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")] = True,
):
    """Train a policy on ENV_ID and write a run folder.

    The folder holds config.toml, metrics.csv, tensorboard/, the policy (policy.json +
    policy.safetensors, pickle-free; SB3's model.zip for continuing training) and
    summary.json with steps_to_success (null if the budget ran out first) and wall_seconds.
    """
    from pydantic import ValidationError

    from motorlab.rl.config import resolve
    from motorlab.rl.train import train as run_train

    settings = {
        "algo": algo, "preset": preset, "timesteps": timesteps, "seed": seed, "lr": lr, "clip_range": clip_range,
        "until_solved": until_solved or None, "solve_episodes": solve_episodes, "solve_return": solve_return,
        "eval_every": eval_every, "n_envs": n_envs, "normalize": normalize, "device": device, "progress": progress,
        "checkpoint_every": checkpoint_every,
        "env": _env_overrides(env_id, delay, delay_on, history, reward, sar, phi, env_arg, success),
    }
    if hp:
        settings["hyperparams"] = _parse_sets(hp)
    settings = {k: v for k, v in settings.items() if v is not None}
    if resume is not None:
        _resume_run(resume, settings, config, out)
        return
    if config is not None:
        settings = _merge_config(config, settings)
    elif env_id is None:
        raise MotorlabError("give an env id (motorlab train InvertedPendulum-v5) or --config RUN/config.toml.")
    try:
        cfg = resolve(settings)
    except ValidationError as e:
        raise MotorlabError(_validation_message(e)) from None
    summary = run_train(cfg, out)
    sts = summary["steps_to_success"]
    stdout.print(f"[green]done[/green] {summary['run_dir']}: "
              f"return {summary['eval_return_mean']:.1f} (min {summary['eval_return_min']:.0f}) over "
              f"{summary['eval_episodes']} episodes, {summary['timesteps']:,} steps, {summary['wall_seconds']:.1f} s"
              + (f", steps_to_success {sts:,}" if sts is not None else (", not solved" if cfg.until_solved else "")))
    _warn_faults(summary)


def _warn_faults(summary: dict) -> None:
    """One line when episodes ended on a numerical fault (they are counted and listed, not fatal)."""
    n = summary.get("numerical_faults") or 0
    if n:
        err.print(f"[yellow]warning[/yellow]: {n} episode{'s' if n > 1 else ''} ended on a numerical fault "
                  f"(NaN/Inf or a diverging simulation); reasons in {summary['run_dir']}/faults.log", soft_wrap=True)


def _resume_run(run_dir: Path, settings: dict, config: Path | None, out: Path | None) -> None:
    from motorlab.rl.config import resolve
    from motorlab.rl.train import train as run_train
    from motorlab.runs import is_complete

    given = [k for k, v in settings.items() if k not in ("progress", "env") or (k == "env" and v)]
    if given or config is not None or out is not None:
        raise MotorlabError(f"--resume continues {run_dir} with the settings in its config.toml; "
                            "drop the other settings (and --out, --config).")
    if not (run_dir / "config.toml").is_file():
        raise MotorlabError(f"{run_dir} is not a training run folder (no config.toml); give the --out of the "
                            "interrupted motorlab train.")
    if is_complete(run_dir):
        raise MotorlabError(f"{run_dir} finished already (it has summary.json); there is nothing to resume.")
    cfg = resolve({**_merge_config(run_dir / "config.toml", {}), "progress": settings.get("progress", True)})
    summary = run_train(cfg, run_dir, resume=True)
    start = summary["resumed_from"]
    stdout.print(f"[green]done[/green] {summary['run_dir']}: "
                 + (f"resumed at {start:,} steps; " if start else "no checkpoint yet, started over; ")
                 + f"return {summary['eval_return_mean']:.1f} over {summary['eval_episodes']} episodes, "
                 f"{summary['timesteps']:,} steps")
    _warn_faults(summary)


def _merge_config(path: Path, flags: dict) -> dict:
    """A config.toml's settings with the given flags on top (env settings merged key by key)."""
    import tomllib

    from motorlab.runs import _read_text_file

    base = _read_text_file(path, tomllib.loads, "TOML", "give the config.toml of a motorlab train run.")
    merged = {**base, **{k: v for k, v in flags.items() if k != "env"}}
    merged["env"] = {**base.get("env", {}), **flags.get("env", {})}
    return merged


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


@app.command(epilog="Examples:\n\n  motorlab evaluate runs/ppo --delay 0.2 --episodes 20\n\n"
                    "  motorlab evaluate pid --env InvertedPendulum-v5\n\n"
                    "  motorlab evaluate 'pid:kp=[1,20,0,0],kd=[1,3,0,0]' --env InvertedPendulum-v5")
def evaluate(
    policy: Annotated[str, typer.Argument(
        help="A run folder, or a built-in controller: pid, pid:kp=[..],ki=[..],kd=[..], zero, random.")],
    env: Annotated[Optional[str], typer.Option(help="Env id (default: the run's training env).")] = None,
    delay: Delay = None,
    delay_on: DelayOn = None,
    history: History = None,
    env_arg: EnvArgs = None,
    success: Success = None,
    episodes: Annotated[int, typer.Option(help="Evaluation episodes.")] = 10,
    seed: Seed = 0,
    out: Out = None,
):
    """Evaluate a policy deterministically; print a table, write summary.json.

    summary.json: return_mean, return_std, return_min, return_max, success_rate,
    episode_lengths. Returns are the task's own (training-time reward shaping is not applied).
    """
    from pydantic import ValidationError
    from rich.table import Table

    from motorlab.evaluate import evaluate_step, resolve_env

    try:
        env_cfg = resolve_env(policy, _env_overrides(env, delay, delay_on, history, env_args=env_arg,
                                                           success=success))
    except ValidationError as e:
        raise MotorlabError(_validation_message(e)) from None
    s = evaluate_step(policy, env_cfg, episodes, seed, out)
    table = Table(title=f"{policy} on {env_cfg.id}" + (f", delay {env_cfg.delay} s" if env_cfg.delay else "")
                  + (f", history {env_cfg.history}" if env_cfg.history > 1 else ""))
    for col in ("episodes", "return mean ± std", "min", "max", "success", "mean length", "falls"):
        table.add_column(col, justify="right")
    table.add_row(str(s["episodes"]), f"{s['return_mean']:.1f} ± {s['return_std']:.1f}", f"{s['return_min']:.1f}",
                  f"{s['return_max']:.1f}", f"{s['success_rate']:.0%}", f"{s['episode_length_mean']:.0f}",
                  str(s["falls"]))
    stdout.print(table)
    stdout.print(f"written: {s['run_dir']}/summary.json")
    _warn_faults(s)


@app.command(epilog="Examples:\n\n  motorlab report runs/pendulum            # -> runs/pendulum/report.html\n\n"
                    "  motorlab report runs/sar-rl runs/rl-e2e --out compare.html   # side by side")
def report(
    paths: Annotated[list[Path], typer.Argument(help="Run folders and/or study folders.")],
    out: Annotated[Optional[Path], typer.Option("--out", help="HTML file to write (default: report.html in the first PATH).")] = None,
):
    """Write one self-contained HTML report: headline tables, every plot and video, the runs
    side by side, settings, library versions and TensorBoard links. Opens offline."""
    from motorlab.report.html import build_report

    path = build_report(paths, out)
    stdout.print(f"written: {path}")


@app.command(epilog="Example:\n\n  motorlab plot runs/ppo   # -> runs/ppo/plots/*.png")
def plot(run_dir: Annotated[Path, typer.Argument(help="A run folder from train or evaluate.")]):
    """Plot a run: learning curve (training runs) and the observation trace of one evaluation episode."""
    from motorlab.report.run import plot_run

    for path in plot_run(run_dir):
        stdout.print(f"written: {path}")


@app.command(epilog="Examples:\n\n  motorlab run pendulum --out runs/pendulum\n\n  motorlab run my_study.toml\n\n"
                    "Re-running into the same --out keeps steps that already finished with the same settings.")
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
    check: Annotated[bool, typer.Option("--check", help="Only validate the recipe and list its steps; run nothing.")] = False,
):
    """Run a study from a TOML recipe: its steps, a printed table, summary.json and plots.

    Recipe format: see `motorlab recipes` and motorlab/recipes/pendulum.toml. A recipe with
    `seeds = N` trains every train step for N seeds in parallel and reports IQMs with
    confidence intervals; `motorlab sweep RECIPE --seeds N` repeats the whole study instead.
    """
    from motorlab.recipes import load_recipe
    from motorlab.studies import Execution, run_study

    study = load_recipe(recipe)
    if check:
        stdout.print(f"{study.source}: valid, {len(study.steps)} steps: "
                     + ", ".join(f"{st.name} ({st.kind})" for st in study.steps))
        return
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
def sweep(
    target: Annotated[str, typer.Argument(
        help="A recipe (bundled name or .toml file: each trial runs the whole study) or a motorlab command line "
             "in quotes (train, evaluate, mpc, dynamics fit, ...); the sweep adds --seed and --out.")],
    seeds: Annotated[int, typer.Option("--seeds", help="Seeds per setting: 0..N-1.")] = 5,
    grid: Annotated[Optional[list[str]], typer.Option(
        "--grid", help="KEY=V1,V2 (repeatable; every combination runs). Commands: KEY is an option (lr, n_envs, "
                       "delay, normalize=true,false). Recipes: FIELD for every step that has it, or STEP.FIELD. "
                       "Values holding commas: separate them with |, e.g. lr='linear:1e-3,0|3e-4'.")] = None,
    backend: Annotated[str, typer.Option(
        help="local: a pool of processes on this machine; ray: Ray Tune on a cluster (--address) or a Ray "
             "instance started here.")] = "local",
    address: Annotated[Optional[str], typer.Option(
        help="Ray cluster address HOST:PORT (from `ray start --head`); every node must see --out at the same path.")] = None,
    max_parallel: Annotated[Optional[int], typer.Option(
        help="Trials at once (default: one per core locally; as many as the cluster's CPUs fit with ray).")] = None,
    out: Out = None,
):
    """Run a command or a study for several seeds (and settings), then aggregate across seeds.

    Aggregates with rliable: interquartile mean (IQM) and 95% stratified-bootstrap confidence
    intervals of final return, success rate and steps-to-success; probability of improvement
    between settings; performance profiles. Writes summary.json, aggregate.json, table.txt,
    plots/ and report.html in the sweep folder, and one run folder per trial (<setting>/seed<k>/).
    """
    from motorlab.sweeps.sweep import run_sweep

    summary = run_sweep(target, seeds, grid, backend, address, max_parallel, out, console=stdout)
    stdout.print(f"\n[bold]Results:[/bold] {summary['sweep_dir']}  (report.html, table.txt, summary.json, "
                 "aggregate.json, plots/*.png, <setting>/seed<k>/)")


@app.command(epilog="Examples:\n\n  motorlab export runs/ppo --out share/ppo          # only the files safe to send\n\n"
                    "  motorlab export ppo_pendulum.zip --trust --env InvertedPendulum-v5 --out runs/imported\n\n"
                    "  motorlab export sac.zip --vecnormalize vec_normalize.pkl --trust --env Hopper-v5 --out runs/sac")
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
):
    """Write a policy folder that is safe to share: no pickle in it.

    From a run folder: copies policy.json, policy.safetensors, config.toml, summary.json, metrics.csv,
    plots and videos, and leaves out model.zip (a pickle), checkpoint/ and tensorboard/.
    From an SB3 zip (with --trust): loads it once and writes policy.json + policy.safetensors,
    which `motorlab evaluate`, `video` and `synergies collect` read without unpickling.
    """
    from motorlab.export import export_run, export_sb3_zip

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
                     + ("" if env else f"; evaluate it with --env ENV_ID"))


@app.command(epilog="Example:\n\n  motorlab zeroshot runs/sar-rl runs/rl-e2e --envs myoHandReorientID-v0 myoHandReorientOOD-v0 --episodes 500")
def zeroshot(
    run_dirs: Annotated[list[Path], typer.Argument(help="Training run folders to compare.")],
    envs: Annotated[list[str], typer.Option("--envs", help="Env ids the policies never trained on (repeat or list).")],
    episodes: Annotated[int, typer.Option(help="Episodes per run and env.")] = 500,
    seed: Seed = 0,
    out: Out = None,
):
    """Zero-shot success of trained policies on unseen envs; table, summary.json, grouped bar chart."""
    from motorlab.envs import register_myosuite
    from motorlab.zeroshot import zeroshot as run_zeroshot

    # `--envs A B`: click gives B to RUN_DIRS; an env id that is not a path belongs to --envs.
    import gymnasium as gym

    register_myosuite()
    moved = [r for r in run_dirs if not r.exists() and str(r) in gym.registry]
    run_dirs = [r for r in run_dirs if r not in moved]
    envs = [e for item in [*envs, *map(str, moved)] for e in item.split(",") if e]
    s = run_zeroshot(run_dirs, envs, episodes, seed, out, console=stdout)
    stdout.print(f"written: {s['run_dir']}/summary.json, {s['run_dir']}/plots/zeroshot.png")
    _warn_faults(s)


@app.command(epilog="Example:\n\n  MUJOCO_GL=egl motorlab video runs/play --episodes 5 --camera hand_side_inter")
def video(
    run_dir: Annotated[Path, typer.Argument(help="A training run folder.")],
    episodes: Annotated[int, typer.Option(help="Episodes to render, one MP4 each.")] = 5,
    camera: Annotated[Optional[str], typer.Option(help="Camera name or index (default: the model's first; -1: free camera).")] = None,
    width: Annotated[int, typer.Option(min=16, max=4096)] = 640,
    height: Annotated[int, typer.Option(min=16, max=4096)] = 480,
    seed: Seed = 0,
    out: Annotated[Optional[Path], typer.Option("--out", help="Folder for the videos (default RUN_DIR/videos).")] = None,
):
    """Render episodes of a run's policy offscreen to H.264 MP4 (MUJOCO_GL=egl works without a display)."""
    from motorlab.report.video import render_video

    s = render_video(run_dir, episodes, seed, camera, width, height, out)
    for path, ret in zip(s["videos"], s["returns"]):
        stdout.print(f"written: {path}  (return {ret:.1f})")


@app.command(epilog="Example:\n\n  motorlab compare --group SAR-RL=runs/sar-s0,runs/sar-s1 --group RL-E2E=runs/e2e-s0,runs/e2e-s1")
def compare(
    group: Annotated[list[str], typer.Option("--group", help="LABEL=RUN_DIR[,RUN_DIR...]: one setting, its seeds.")],
    title: Annotated[str, typer.Option(help="Figure title.")] = "Learning curves",
    out: Out = None,
):
    """Learning curves (return and success vs env steps) of settings across seeds: mean and 95% band, PNG."""
    from motorlab.report.compare import compare_curves, group_statistics
    from motorlab.runs import prepare_run_dir, write_config, write_summary

    groups = {}
    for item in group:
        label, sep, runs = item.partition("=")
        if not sep or not label or not runs:
            raise MotorlabError(f"--group {item!r}: write LABEL=RUN_DIR[,RUN_DIR...], e.g. --group SAR-RL=runs/a,runs/b.")
        groups[label] = [Path(r) for r in runs.split(",") if r]
    run_dir = prepare_run_dir(out, "compare")
    result = compare_curves(groups, run_dir / "plots" / "learning_curves.png", title)
    write_config(run_dir, {"groups": {k: [str(r) for r in v] for k, v in groups.items()}, "title": title})
    write_summary(run_dir, {**{f"{label}.{k}": v for label, r in result.items() for k, v in r.items()},
                            **group_statistics(groups)})
    stdout.print(f"written: {run_dir}/plots/learning_curves.png")


synergies = typer.Typer(help="Muscle synergies: collect activations, VAF, fit or import a SAR.",
                        no_args_is_help=True, rich_markup_mode="rich")
app.add_typer(synergies, name="synergies")


@synergies.command("collect", epilog="Example:\n\n  motorlab synergies collect runs/play --episodes 1000 --percentile 80 --preview 100")
def synergies_collect(
    run_dir: Annotated[Path, typer.Argument(help="A training run folder (the play policy).")],
    episodes: Annotated[int, typer.Option(help="Episodes to keep (those at or above the threshold).")] = 100,
    percentile: Annotated[float, typer.Option(help="Return threshold: this percentile of the preview returns.")] = 80.0,
    preview: Annotated[int, typer.Option(help="Preview episodes that set the threshold.")] = 50,
    deterministic: Annotated[bool, typer.Option("--deterministic/--stochastic", help="Policy mean or samples (default).")] = False,
    workers: Annotated[Optional[int], typer.Option(help="Processes (default: all cores).")] = None,
    seed: Seed = 0,
    out: Out = None,
):
    """Record muscle activations (MuJoCo data.act) of a policy's good episodes to activations.npz."""
    from motorlab.synergy.collect import collect

    s = collect(run_dir, episodes, percentile, preview, seed, deterministic, workers, out=out)
    stdout.print(f"kept {s['episodes_kept']} episodes (return >= {s['threshold']:.3g}), {s['samples']:,} samples "
                 f"x {s['n_muscles']} muscles -> {s['run_dir']}/activations.npz")
    _warn_faults(s)


@synergies.command("vaf", epilog="Example:\n\n  motorlab synergies vaf runs/collect/activations.npz --threshold 0.8")
def synergies_vaf(
    activations: Annotated[Path, typer.Argument(help="activations.npz (or its folder).")],
    threshold: Annotated[float, typer.Option(help="Report the smallest N whose VAF reaches this.")] = 0.8,
    method: Annotated[str, typer.Option(help="pca (also pca-ica: same VAF) or nmf (classic, uncentered).")] = "pca",
    max_n: Annotated[Optional[int], typer.Option(help="Largest N (saves time with nmf).")] = None,
    out: Out = None,
):
    """Variance accounted for by N = 1..n_muscles synergies: table, vaf.png, smallest N reaching --threshold."""
    from rich.table import Table

    from motorlab.synergy.steps import vaf_step

    s = vaf_step(activations, threshold, method, max_n, out)
    table = Table(title=f"VAF ({method}), {s['samples']:,} samples x {s['n_muscles']} muscles")
    table.add_column("N", justify="right")
    table.add_column("VAF", justify="right")
    for n, v in enumerate(s["vaf"], 1):
        table.add_row(str(n), f"{v:.1%}" + (" <-" if n == s["n_for_threshold"] else ""))
    stdout.print(table)
    need = s["n_for_threshold"]
    stdout.print(f"smallest N with VAF >= {threshold:.0%}: {need if need is not None else 'none'}; "
                 f"written: {s['run_dir']}/vaf.png")


@synergies.command("fit", epilog="Examples:\n\n  motorlab synergies fit activations.npz --vaf 0.8\n\n"
                                 "  motorlab synergies fit activations.npz --n 20 --method nmf")
def synergies_fit(
    activations: Annotated[Path, typer.Argument(help="activations.npz (or its folder).")],
    n: Annotated[Optional[int], typer.Option("--n", "--n-synergies", help="Number of synergies N.")] = None,
    vaf: Annotated[Optional[float], typer.Option(help="Or: the smallest N whose VAF reaches this, e.g. 0.8.")] = None,
    method: Annotated[str, typer.Option(
        help="pca-ica (PCA -> FastICA -> scale to [-1,1], the reference), pca, or nmf.")] = "pca-ica",
    seed: Seed = 0,
    out: Out = None,
):
    """Fit a Synergistic Action Representation; writes sar.npz (plain arrays + JSON metadata, no pickle)."""
    from motorlab.synergy.steps import fit_step

    s = fit_step(activations, n, vaf, method, seed, out)
    stdout.print(f"{s['n_synergies']} synergies ({method}) for {s['n_muscles']} muscles, VAF {s['vaf']:.1%} "
                 f"-> {s['sar']}")


@synergies.command("import-sklearn", epilog="Example:\n\n  motorlab synergies import-sklearn "
                                            "published/manipulation --trust --out sar-hand.npz")
def synergies_import(
    folder: Annotated[Path, typer.Argument(help="Folder with pca.pkl, ica.pkl, normalizer.pkl (joblib).")],
    out: Annotated[Path, typer.Option("--out", help="The sar.npz to write.")],
    trust: Annotated[bool, typer.Option("--trust", help="Allow unpickling these files (they can run code).")] = False,
):
    """Convert a published scikit-learn SAR (joblib pickles) to sar.npz, checked against sklearn's own inverse chain."""
    from motorlab.synergy.sklearn_import import import_sklearn

    sar = import_sklearn(folder, trust=trust, out=out)
    err_max = sar.metadata.get("import_check_max_abs_error")
    stdout.print(f"{sar.n_synergies} synergies x {sar.n_muscles} muscles -> {out}"
                 + (f" (decode matches scikit-learn, max abs error {err_max:.1e})" if err_max is not None else ""))


dynamics = typer.Typer(help="Forward models: collect transitions, fit a model, check it against the simulator.",
                        no_args_is_help=True, rich_markup_mode="rich")
app.add_typer(dynamics, name="dynamics")


def _hidden(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(h) for h in text.split(",") if h.strip())
    except ValueError:
        raise MotorlabError(f"--hidden {text!r}: write layer widths separated by commas, e.g. 64,64.") from None


@dynamics.command("collect", epilog="Examples:\n\n  motorlab dynamics collect Reacher-v5 --episodes 20000 --out runs/reacher-data\n\n"
                                    "  motorlab dynamics collect InvertedPendulum-v5 --episodes 200 --policy runs/ppo")
def dynamics_collect(
    env_id: Annotated[str, typer.Argument(help="Gymnasium env id, e.g. Reacher-v5.")],
    episodes: Annotated[int, typer.Option(help="Episodes to run, each to its end.")] = 1000,
    policy: Annotated[str, typer.Option(help="random (uniform actions) or a run folder from `motorlab train`.")] = "random",
    workers: Annotated[Optional[int], typer.Option(help="Processes or threads (default: all cores).")] = None,
    state: Annotated[str, typer.Option(
        help="State layout: auto (Reacher: cos, sin, joint velocities, fingertip x-y; else the observation), "
             "reacher, observation.")] = "auto",
    simulator: Annotated[str, typer.Option(
        help="auto (Reacher with random actions: closed-form where the arm's closed-form dynamics reproduce "
             "MuJoCo's, else mujoco; any other env or policy: gymnasium); closed-form (the arm's equations of "
             "motion in NumPy, all episodes at once, equal to MuJoCo's to its solver tolerance); mujoco "
             "(mujoco.rollout in C on every core, bit for bit Gymnasium's joints); gymnasium (the env itself, "
             "in a process pool).")] = "auto",
    seed: Seed = 0,
    out: Out = None,
):
    """Record transitions (state, action, next state, reward, done) to transitions.npz."""
    from motorlab.dynamics.collect import collect_step

    s = collect_step(env_id, episodes, policy, workers, seed, state, simulator, out)
    stdout.print(f"{s['transitions']:,} transitions ({s['state_size']} state, {s['action_size']} action entries) "
                 f"at {s['transitions_per_second']:,.0f}/s via {s['simulator']} -> {s['run_dir']}/transitions.npz")
    _warn_faults(s)


@dynamics.command("fit", epilog="Examples:\n\n  motorlab dynamics fit runs/reacher-data --out runs/reacher-model\n\n"
                                "  motorlab dynamics fit runs/reacher-data/transitions.npz --hidden 128,128 --ensemble 5 --patience 5")
def dynamics_fit(
    transitions: Annotated[Path, typer.Argument(help="transitions.npz (or its folder) from `dynamics collect`.")],
    epochs: Annotated[int, typer.Option(help="Passes over the training data (the most, with --patience).")] = 50,
    hidden: Annotated[str, typer.Option(help="Hidden layer widths (Tanh + LayerNorm each).")] = "64,64",
    ensemble: Annotated[int, typer.Option(help="Members K, trained together as one batched net.")] = 1,
    lr: Annotated[float, typer.Option(help="Adam's learning rate, cosine-decayed to 0.")] = 2e-3,
    batch_size: Annotated[int, typer.Option(help="Rows per gradient step.")] = 2000,
    valid_fraction: Annotated[float, typer.Option(help="Share of episodes held out for valid_mse.")] = 0.1,
    patience: Annotated[Optional[int], typer.Option(help="Early stopping: epochs without a better valid_mse.")] = None,
    seed: Seed = 0,
    out: Out = None,
):
    """Fit a forward model predicting the normalized state delta; writes model.safetensors + model.json."""
    from motorlab.dynamics.train import fit_step

    s = fit_step(transitions, epochs, _hidden(hidden), ensemble, lr, batch_size, valid_fraction, patience, seed, out)
    valid = f"valid_mse {s['valid_mse']:.2e} (normalized)" if s["valid_mse"] is not None else "no validation"
    stdout.print(f"{valid} after {s['epochs_run']} epochs, {s['wall_seconds']:.1f} s -> {s['run_dir']}/model.json, "
                 f"plots/loss.png")


@dynamics.command("check", epilog="Example:\n\n  motorlab dynamics check runs/reacher-model --episodes 5")
def dynamics_check(
    model: Annotated[Path, typer.Argument(help="A model folder from `dynamics fit`.")],
    episodes: Annotated[int, typer.Option(help="Open-loop episodes (random actions).")] = 5,
    steps: Annotated[Optional[int], typer.Option(help="Steps per episode (default: the env's time limit).")] = None,
    seed: Seed = 0,
    out: Out = None,
):
    """Model vs simulator under the same actions, open loop: error vs horizon, x-y traces, summary numbers."""
    from motorlab.dynamics.check import check_step

    s = check_step(model, episodes, seed, steps, out)
    tip = {k: v for k, v in s.items() if k.startswith("tip_error_mean_h")}
    stdout.print("open-loop error: " + ", ".join(
        [f"{k.removeprefix('tip_error_mean_')} {v * 1000:.1f} mm" for k, v in tip.items()]
        or [f"{k.removeprefix('state_nrmse_')} {v:.3f}" for k, v in s.items() if k.startswith("state_nrmse_h")]))
    stdout.print(f"written: {s['run_dir']}/plots/error_vs_horizon.png, traces.png")


@app.command(epilog="Examples:\n\n  motorlab mpc Reacher-v5 --model runs/reacher-model --episodes 50\n\n"
                    "  motorlab mpc Reacher-v5 --model runs/reacher-model --optimizer evotorch --horizon 4 "
                    "--population 250 --iterations 20 --episodes 5")
def mpc(
    env_id: Annotated[str, typer.Argument(help="Env id the model was fit on, e.g. Reacher-v5.")],
    model: Annotated[Path, typer.Option("--model", help="A model folder from `motorlab dynamics fit`.")],
    episodes: Annotated[int, typer.Option(help="Episodes to control.")] = 50,
    horizon: Annotated[Optional[int], typer.Option(help="Planning horizon in control steps (default 15).")] = None,
    population: Annotated[Optional[int], typer.Option(help="Action sequences per CEM iteration (default 100).")] = None,
    iterations: Annotated[Optional[int], typer.Option(help="CEM iterations per control step (default 5).")] = None,
    elites: Annotated[Optional[int], typer.Option(help="Best sequences the Gaussian is refit to (default 10).")] = None,
    optimizer: Annotated[str, typer.Option(help="cem (motorlab's, batched) or evotorch (EvoTorch's CEM).")] = "cem",
    parallel: Annotated[int, typer.Option(help="Episodes run side by side, planned in one batched call.")] = 1,
    video: Annotated[bool, typer.Option("--video", help="Also render the first episode to videos/episode_0.mp4.")] = False,
    seed: Seed = 0,
    out: Out = None,
):
    """Model-predictive control: CEM on a learned forward model, maximizing the env's own reward.

    summary.json: return_mean, return_std, final_distance_mean (metres), plan_ms_median (per env per control step).
    """
    from motorlab.control.mpc_step import mpc_step

    s = mpc_step(env_id, model, episodes, horizon, population, iterations, elites, optimizer, parallel, seed, video, out)
    stdout.print(f"return {s['return_mean']:.2f} ± {s['return_std']:.2f}, final distance "
                 f"{s['final_distance_mean'] * 1000:.1f} mm (mean), planning {s['plan_ms_median']:.2f} ms/step "
                 f"(median) over {s['episodes']} episodes -> {s['run_dir']}")
    _warn_faults(s)


@app.command()
def recipes():
    """List the bundled recipes."""
    from motorlab.recipes import bundled, load_recipe

    for name in sorted(bundled()):
        r = load_recipe(name)
        stdout.print(f"[bold]{name}[/bold]: {r.description} ({len(r.steps)} steps)")


def main() -> None:
    """Entry point: run the app, turning user mistakes into one-line errors.

    Click's own mistakes (unknown option, a value of the wrong type, a missing argument) are
    caught here too, instead of in Click's standalone mode, which prints them in a box under
    the usage text: every mistake reads the same, `error: ...` on one line, exit status 2."""
    from typer._click import exceptions as click_errors  # typer vendors its click

    try:
        code = app(standalone_mode=False, prog_name="motorlab")
    except click_errors.NoArgsIsHelpError:
        sys.exit(2)  # a command group given no command: its help was printed
    except click_errors.UsageError as e:
        where = e.ctx.command_path if e.ctx is not None else "motorlab"
        _error(f"{e.format_message()} (see `{where} --help`)")
    except click_errors.ClickException as e:
        _error(e.format_message(), e.exit_code)
    except MotorlabError as e:
        _error(str(e))
    except KeyboardInterrupt:
        _interrupted()
    if code == 130:  # typer turns Ctrl-C into exit code 130
        _interrupted()
    sys.exit(code if isinstance(code, int) else 0)


def _error(message: str, code: int = 2) -> None:
    err.print(f"[red]error:[/red] {escape(message)}", highlight=False, soft_wrap=True)
    sys.exit(code)


def _interrupted() -> None:
    err.print("[yellow]interrupted[/yellow]: the run folder has no summary.json, so it stays marked unfinished.")
    sys.exit(130)


if __name__ == "__main__":
    main()
