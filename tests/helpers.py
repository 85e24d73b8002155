"""Helpers shared by the tests: run the CLI in a subprocess and check its outcome."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

ENV_ID = "InvertedPendulum-v5"

# The tiny PPO budget every SB3 test uses: two rollouts of 128 steps.
TINY_PPO = ["--algo", "ppo", "--timesteps", "256", "--set", "n_steps=128", "--set", "batch_size=64"]


USER_PACKAGES = str(Path(__file__).parent)  # tests/userpkg: a user's own env package (test_user_env.py)


@contextlib.contextmanager
def user_packages_importable():
    """tests/userpkg importable as an installed package is, in every process motorlab starts (the
    PYTHONPATH they inherit), for the block; PYTHONPATH is put back after."""
    before = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (USER_PACKAGES, before) if p)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = before


def ray_head(port: int) -> None:
    """Start a local Ray head (2 CPUs) at 127.0.0.1:`port`, as a user's `ray start --head` would;
    stop it with `ray_stop()` (in a finally)."""
    # the cluster can import the user's env package (as if installed on its nodes), but is never
    # told to: only motorlab's runtime_env passes the modules on (test_ray_workers_import_the_users_env_module)
    env = {k: v for k, v in os.environ.items() if k != "MOTORLAB_IMPORTS"}
    env.update(RAY_USAGE_STATS_ENABLED="0", PYTHONPATH=os.pathsep.join(
        p for p in (USER_PACKAGES, os.environ.get("PYTHONPATH")) if p))
    ray = str(Path(sys.executable).with_name("ray"))
    subprocess.run([ray, "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=2",
                    "--include-dashboard=false", "--disable-usage-stats"], check=True, capture_output=True,
                   env=env, timeout=120)


def ray_stop() -> None:
    subprocess.run([str(Path(sys.executable).with_name("ray")), "stop", "--force"], capture_output=True, timeout=120)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_cli(*args: str | os.PathLike, cwd: Path | None = None, timeout: float = 300,
            env: dict[str, str] | None = None, user_modules: bool = True,
            fresh: bool = False) -> subprocess.CompletedProcess:
    """`python -m motorlab ARGS` in a fresh process, as a user would run it (`env`: variables to add).
    The process is a fork of one that has already imported the libraries every command imports
    (tests/zygote.py: the same process after those imports, without their seconds of CPU), or with
    `fresh=True`, or an environment those imports would have read differently, a new interpreter.
    `user_modules=False`: without the user modules this process passes on ($MOTORLAB_IMPORTS), for a run that
    tests of other files share (a session fixture): a run records them, and a later file's process may not
    find a module the file that first asked for the fixture had imported."""
    from tests.zygote import zygote_for

    inherited = {k: v for k, v in os.environ.items() if user_modules or k != "MOTORLAB_IMPORTS"}
    full_env = {**inherited, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), **(env or {})}
    cmd = [sys.executable, "-m", "motorlab", *map(str, args)]
    # MOTORLAB_TESTS_FRESH=1: every command in a new interpreter (to compare, or to rule the zygote out)
    zygote = None if fresh or os.environ.get("MOTORLAB_TESTS_FRESH") == "1" else zygote_for(full_env)
    if zygote is not None:
        return zygote.run(cmd[3:], str(cwd or os.getcwd()), full_env, timeout, cmd)
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=timeout, env=full_env)


def run_here(*args: str | os.PathLike, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """`motorlab ARGS` run in this process through `motorlab.cli.main` (what `python -m motorlab`
    runs), for tests of what a command answers rather than of starting a process: milliseconds,
    not an interpreter start. As a process would: its output is what reached stdout and stderr,
    Python's and the C libraries' (file descriptors 1 and 2), warnings shown as a fresh interpreter
    shows them, an exception other than SystemExit is the traceback a user would see with exit
    status 1; argv, the working directory and the environment are restored afterwards."""
    import contextlib
    import io
    import tempfile
    import traceback
    import warnings

    from motorlab.cli import main

    argv = ["motorlab", *map(str, args)]
    saved_argv, saved_cwd, saved_env = sys.argv, os.getcwd(), dict(os.environ)
    text = {1: io.StringIO(), 2: io.StringIO()}
    code: int | str | None = 0
    with contextlib.ExitStack() as stack:
        raw = {}
        for fd in (1, 2):  # what C code writes to the descriptors themselves
            sys.stdout.flush(), sys.stderr.flush()
            raw[fd] = stack.enter_context(tempfile.TemporaryFile())
            kept = os.dup(fd)
            os.dup2(raw[fd].fileno(), fd)
            stack.callback(os.close, kept)
            stack.callback(os.dup2, kept, fd)
        stack.enter_context(contextlib.redirect_stdout(text[1]))
        stack.enter_context(contextlib.redirect_stderr(text[2]))
        stack.enter_context(warnings.catch_warnings())
        warnings.resetwarnings()  # Python's own defaults, not pytest's recording of warnings
        for category in (ResourceWarning, ImportWarning, PendingDeprecationWarning, DeprecationWarning):
            warnings.simplefilter("ignore", category)
        warnings.filterwarnings("default", category=DeprecationWarning, module="__main__")
        try:
            sys.argv = argv
            if cwd is not None:
                os.chdir(cwd)
            main()
        except SystemExit as e:
            code = e.code
        except BaseException:  # noqa: B036 - what the interpreter would print and exit with
            text[2].write(traceback.format_exc())
            code = 1
        finally:
            sys.argv = saved_argv
            os.chdir(saved_cwd)
            os.environ.clear()
            os.environ.update(saved_env)
        for fd in (1, 2):
            raw[fd].seek(0)
            text[fd].write(raw[fd].read().decode(errors="replace"))
    if code is None:
        code = 0
    elif not isinstance(code, int):  # sys.exit("message"): printed, exit status 1
        text[2].write(f"{code}\n")
        code = 1
    return subprocess.CompletedProcess(argv, code, text[1].getvalue(), text[2].getvalue())


def assert_ok(proc: subprocess.CompletedProcess) -> None:
    """The command succeeded; on failure show what it printed."""
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    """Exit code 2, stderr is one line starting with 'error:', no traceback anywhere,
    and the message contains every fragment. Returns the message."""
    shown = f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    assert proc.returncode == 2, shown
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout, shown
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, shown
    assert lines[0].startswith("error:"), shown
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in the message\n{shown}"
    return lines[0]


def run_kind(kind, out: Path, progress: bool = False, **fields) -> dict:
    """Run a step kind in this process, as the Python API does: its summary.json keys and run_dir."""
    summary = kind.run(kind.make(**fields), out, progress=progress)
    return {**summary.keys(), "run_dir": str(summary.run_dir)}


def read_summary(run_dir: Path) -> dict:
    return json.loads((Path(run_dir) / "summary.json").read_text())


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def assert_png(path: Path, min_side: int = 100) -> None:
    """`path` is a readable PNG image of a real figure (not an empty canvas)."""
    import matplotlib.image
    import numpy as np

    path = Path(path)
    assert path.is_file(), f"{path} was not written"
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert len(data) > 2000, f"{path} is suspiciously small ({len(data)} bytes)"
    image = matplotlib.image.imread(path)
    assert image.ndim == 3 and image.shape[2] in (3, 4), image.shape
    assert min(image.shape[:2]) >= min_side, image.shape
    assert np.ptp(image[..., :3]) > 0.5, f"{path} is blank"  # something was drawn


# ---- SAR workflow helpers ----------------------------------------------------------

HAND_ID = "myoHandReorient8-v0"
HAND_MUSCLES = 39
# Published MyoSuite SAR pickles: reference data beside the repo, never copied into it.
PUBLISHED_SAR = Path(__file__).resolve().parents[2] / "shared/data/myosuite_sar_pretrained"

# A tiny SAC "play" run on the MyoSuite hand: ~400 env steps, small nets, few updates.
TINY_HAND_SAC = ["--preset", "sar-sac", "--timesteps", "400", "--set", "learning_starts=100",
                 "--set", "gradient_steps=4", "--set", 'policy_kwargs={"net_arch":{"pi":[32,32],"qf":[32,32]}}']

# MuJoCo's C library prints this to stderr whenever MyoSuite builds a hand model; it is not
# motorlab's message (see test_myosuite.py::test_cli_error_for_a_myosuite_env_is_one_line).
MUJOCO_SPEC_WARNING = "WARNING: Attaching a spec with an empty prefix may prevent the model from being saved correctly."


def assert_cli_error(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    """As `assert_one_line_error`, but MuJoCo's own C-level spec warning (printed by
    MyoSuite model building, not by motorlab) and blank lines around it are ignored."""
    stderr = "\n".join(line for line in proc.stderr.splitlines()
                       if line.strip() and line.strip() != MUJOCO_SPEC_WARNING)
    cleaned = subprocess.CompletedProcess(proc.args, proc.returncode, proc.stdout, stderr + "\n")
    return assert_one_line_error(cleaned, *fragments)


def read_metrics_rows(run_dir: Path) -> tuple[list[str], list[dict[str, str]]]:
    """metrics.csv as (header, rows of strings)."""
    import csv

    with open(Path(run_dir) / "metrics.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    return list(reader.fieldnames or []), rows


def episode_rows(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """The training-episode rows of metrics.csv (evaluation rows have no episode_return)."""
    return [r for r in rows if r["episode_return"] != ""]

# What the shared collection asked for (tests/conftest.py::hand_activations).
COLLECT_EPISODES, COLLECT_PERCENTILE, COLLECT_PREVIEW, COLLECT_SEED = 4, 50.0, 4, 0
COLLECT_ARGS = ["--episodes", str(COLLECT_EPISODES), "--percentile", str(COLLECT_PERCENTILE),
                "--preview", str(COLLECT_PREVIEW), "--seed", str(COLLECT_SEED)]


# ---- bundled recipes at the tests' scale --------------------------------------------

# Bundled recipes at the tests' scale: what the tests check (every step runs and writes its
# files, numbers, findings and figures) does not depend on the budgets. recipe -> [(pattern,
# divisor or replacement)]: a divisor turns the number in the pattern's group 1 into
# max(1, n // divisor); a string replaces the match (re.sub).
# collect in-process: at this scale a pool of fresh interpreters costs more than it saves (pools: test_collect.py)
ONE_WORKER = (r'(kind = "collect"\n)', r"\1workers = 1\n")
# sar-sac-fast's 4 env processes: each training would start 4 MyoSuite interpreters (~5 s a training
# here); the trainings run the same code in one (the 4-process path: tests/rl/test_myosuite_presets.py).
ONE_ENV_PROCESS = (r'(preset = "sar-sac-fast"\n)', r"\1n_envs = 1\n")
# sar-ant-quick's 8 gradient steps per episode (most of a training's time at this scale) become 1.
ONE_GRADIENT_STEP = (r"gradient_steps = (\d+)", 8)
SCALED = {
    # ~3.5 min on 2 cores as bundled: collect 5 of 5 preview episodes, zero-shot 5 episodes per env
    "sar-hand-quick": [(r"timesteps = (\d+)", 10), (r"eval_every = (\d+)", 5), (r"episodes = (\d+)", 10),
                       (r"preview = (\d+)", 4), ONE_WORKER, ONE_ENV_PROCESS],
    # its collection (5000 episodes), fit (20 epochs) and MPC (10 episodes); the check keeps its 3 episodes
    "reacher-quick": [(r"episodes = (\d{2,})", 5), (r"epochs = (\d+)", 4)],
    # every step of the legs study: 1000 + 1000 env steps of SAC beside 2000, 4 episodes collected
    "sar-legs-quick": [(r"timesteps = (\d+)", 5), (r"eval_every = (\d+)", 5), (r"episodes = (\d+)", 5),
                       (r"preview = (\d+)", 5), ONE_WORKER],
    # ~2 min on 2 cores as bundled
    "sar-ant-quick": [(r"timesteps = (\d+)", 4), (r"eval_every = (\d+)", 4), ONE_WORKER, ONE_GRADIENT_STEP],
    # 2 seeds each: 2 rounds x 1 evaluation episode on a small planner and model; SAC 400 env steps (100
    # gradient steps), evaluated at 200 and 400 on 2 episodes; ~35 s on 2 idle cores
    "mbrl-cartpole": [(r"rounds = (\d+)", 7), (r"eval_episodes = (\d+)", 5), (r"parallel = (\d+)", 5),
                      (r"seeds = \[0, 1, 2, 3, 4\]", "seeds = [0, 1]"),  # both arms'
                      (r'(kind = "mbrl"\n)', r"\1horizon = 5\npopulation = 20\niterations = 2\nelites = 4\nepochs = 5\n"),
                      (r'(algo = "sac"\n)', r"\1solve_episodes = 2\nhyperparams = { learning_starts = 300 }\n"),
                      (r"timesteps = (\d+)", 75), (r"eval_every = (\d+)", 5)],
}


def scaled_recipe(name: str, folder: Path) -> Path:
    """The bundled recipe `name` changed as SCALED says, written to folder/<name>.toml."""
    import re

    from motorlab.recipes import find_recipe

    text = find_recipe(name).read_text()
    for pattern, how in SCALED[name]:
        def divided(m, d=how):
            return m.group(0).replace(m.group(1), str(max(1, int(m.group(1)) // d)))

        text, n = re.subn(pattern, how if isinstance(how, str) else divided, text)
        assert n, f"{name}: nothing matches {pattern!r}"  # the recipe changed: update SCALED
    path = Path(folder) / f"{name}.toml"
    path.write_text(text)
    return path


def snapshot(*roots: Path) -> dict[str, str]:
    """Every file under `roots` with the SHA-256 of its bytes: take one before a mistake and one
    after, and assert they are equal (no earlier file changed, none appeared or went away)."""
    import hashlib

    files = {}
    for root in map(Path, roots):
        paths = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for p in paths:
            files[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return files


def docs_hook(name: str):
    """docs/hooks/NAME.py, a MkDocs hook (not a package module), loaded by path; registered in
    sys.modules, where its dataclasses look their module up."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "docs" / "hooks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
