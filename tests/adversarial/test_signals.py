"""Signals: SIGTERM (what `timeout`, `kill`, Slurm and Ray send) and SIGHUP (a closed terminal) stop
a command as Ctrl-C does (motorlab/processes.py): its training processes stop with their checkpoints
kept, it exits with 128 + the signal in one line, no process it started outlives it, and the same
command (with --resume) finishes the work. A parent killed outright (SIGKILL) cannot clean up, but
its children still die with it (Linux's PR_SET_PDEATHSIG).

Each test starts a real `motorlab` process in a session of its own and signals it alone, once
both its training processes have written a checkpoint.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from tests.helpers import ENV_ID, assert_ok, read_summary, run_cli

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="signals and PR_SET_PDEATHSIG: Linux")

# a few seconds of PPO per seed, a checkpoint every rollout (128 steps): still training when the first is
# written; one evaluation, at the end
BUDGET = 1024
TRAIN = (f"train {ENV_ID} --algo ppo --timesteps {BUDGET} --set n_steps=128 --set batch_size=64 --checkpoint-every 128 "
         f"--eval-every {BUDGET}")
RECIPE = f"""name = "signalled"
description = "two seeds trained in processes of their own"

[[steps]]
name = "ppo"
kind = "train"
env = "{ENV_ID}"
algo = "ppo"
timesteps = {BUDGET}
checkpoint_every = 128
eval_every = {BUDGET}
hyperparams = {{ n_steps = 128, batch_size = 64 }}
seeds = 2
"""


def _start(*args: str) -> subprocess.Popen:
    """`motorlab ARGS` in a session of its own (a signal to it reaches it alone), with the default
    handling of every stop signal even if this test runner was started with some ignored (nohup)."""
    def defaults() -> None:
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, signal.SIG_DFL)

    return subprocess.Popen([sys.executable, "-m", "motorlab", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=defaults)


def _training(proc: subprocess.Popen, run_dirs: list[Path], timeout: float = 90) -> list[psutil.Process]:
    """Wait until every run folder holds a checkpoint; returns the command's descendants then, among
    them a training process (`motorlab.worker`) per folder."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if all((d / "checkpoint" / "latest.json").is_file() for d in run_dirs):
            descendants = psutil.Process(proc.pid).children(recursive=True)
            workers = [p for p in descendants if "motorlab.worker" in " ".join(_cmdline(p))]
            assert len(workers) == len(run_dirs), [_cmdline(p) for p in descendants]
            return descendants
        time.sleep(0.05)
    proc.kill()
    raise AssertionError(f"no checkpoints in {run_dirs}: {proc.communicate()}")


def _assert_stopped(proc: subprocess.Popen, signum: int, descendants: list[psutil.Process],
                    run_dirs: list[Path]) -> None:
    """Exit 128 + signum, one line on stderr, no process left, checkpoints kept, nothing finished."""
    stdout, stderr = proc.communicate(timeout=60)
    shown = f"exit {proc.returncode}\nstdout:\n{stdout}\nstderr:\n{stderr}"
    assert proc.returncode == 128 + signum, shown
    assert "Traceback" not in stdout + stderr, shown
    assert stderr.strip().splitlines() == [stderr.strip()] and "interrupted" in stderr, shown
    _, alive = psutil.wait_procs(descendants, timeout=5)
    assert not alive, f"outlived the command: {[_cmdline(p) for p in alive]}"
    for d in run_dirs:
        assert (d / "checkpoint" / "latest.json").is_file() and not (d / "summary.json").exists(), d


def _cmdline(p: psutil.Process) -> list[str]:
    try:
        return p.cmdline()
    except psutil.Error:
        return []


def test_sigterm_stops_a_sweep_that_resume_then_finishes(tmp_path):
    out = tmp_path / "sweep"
    args = ["sweep", TRAIN, "--seeds", "2", "--max-parallel", "2", "--out", str(out)]
    trials = [out / "default" / f"seed{k}" for k in range(2)]
    proc = _start(*args)
    descendants = _training(proc, trials)
    proc.send_signal(signal.SIGTERM)
    _assert_stopped(proc, signal.SIGTERM, descendants, trials)

    again = run_cli(*args, "--resume", timeout=240)
    assert_ok(again)
    assert read_summary(out)["finished"] == 2
    for trial in trials:  # each went on from its checkpoint, to the whole budget
        summary = read_summary(trial)
        assert summary["timesteps"] == BUDGET and summary["resumed_from"] >= 128, summary


def _study_training(tmp_path: Path) -> tuple[Path, Path, list[Path], subprocess.Popen, list[psutil.Process]]:
    """`motorlab run` of RECIPE, once both seeds' processes are training: (recipe, study, seed folders,
    the command, its descendants)."""
    recipe = tmp_path / "signalled.toml"
    recipe.write_text(RECIPE)
    out = tmp_path / "study"
    seeds = [out / "ppo" / f"seed{k}" for k in range(2)]
    proc = _start("run", str(recipe), "--out", str(out))
    return recipe, out, seeds, proc, _training(proc, seeds)


def test_sighup_stops_a_study_that_resume_then_finishes(tmp_path):
    recipe, out, seeds, proc, descendants = _study_training(tmp_path)
    proc.send_signal(signal.SIGHUP)
    _assert_stopped(proc, signal.SIGHUP, descendants, seeds)
    assert not (out / "summary.json").exists()

    again = run_cli("run", recipe, "--out", out, "--resume", timeout=240)
    assert_ok(again)
    assert (out / "summary.json").is_file()
    for seed in seeds:
        summary = read_summary(seed)
        assert summary["timesteps"] == BUDGET and summary["resumed_from"] >= 128, summary


def test_children_of_a_killed_command_die_with_it(tmp_path):
    """SIGKILL leaves the command no chance to stop its trainings: the kernel stops them (pdeathsig)."""
    _, _, seeds, proc, descendants = _study_training(tmp_path)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    # at once, or at worst when a cleanup that hung hits the worker's deadline (15 s)
    _, alive = psutil.wait_procs(descendants, timeout=20)
    assert not alive, f"outlived a killed command: {[_cmdline(p) for p in alive]}"
    for seed in seeds:  # each stopped as on SIGTERM: unfinished, its checkpoint kept
        assert (seed / "checkpoint" / "latest.json").is_file() and not (seed / "summary.json").exists()


HUNG_CLEANUP = """
import threading, time
from motorlab.processes import stopped_by_signals

def cleanup_that_never_finishes():
    threading.Event().wait()

with stopped_by_signals(grace=2.0):
    try:
        print("ready", flush=True)
        time.sleep(60)
    except KeyboardInterrupt:
        cleanup_that_never_finishes()
"""


def test_a_cleanup_that_hangs_past_its_grace_ends_and_says_where_it_waited():
    """After a stop signal a process has its grace to clean up; one whose cleanup never finishes is
    ended by the kernel (SIGALRM) and leaves, on stderr, the stack it hung in."""
    proc = subprocess.Popen([sys.executable, "-c", HUNG_CLEANUP], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signal.SIGINT)
    started = time.monotonic()
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGALRM and time.monotonic() - started < 10
    assert "cleanup_that_never_finishes" in stderr and "Timeout" in stderr
