"""Study steps that need nothing from each other run at the same time (parallel_steps):
dependencies are respected, at most K train steps run at once, results are the ones the
steps give one after another, and an interrupted study stops its background trainings."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from rich.console import Console

from motorlab.recipes import parse_recipe
from motorlab.runs import last_timesteps
from motorlab.studies.schedule import run_overlapped
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli, run_here

TINY = 'algo = "ppo"\nhyperparams = { n_steps = 128, batch_size = 64 }\n'
STUDY = f"""
name = "overlap"
[defaults]
env = "InvertedPendulum-v5"
{TINY}
[[steps]]
name = "a"
timesteps = 1024

[[steps]]
name = "a-eval"
kind = "evaluate"
policy = "@a"
episodes = 2

[[steps]]
name = "b"
timesteps = 1536
seed = 1

[[steps]]
name = "c"
timesteps = 512
seeds = 2
"""


def _recipe(tmp_path: Path, text: str = STUDY, parallel: int | None = 2) -> Path:
    path = tmp_path / "study.toml"
    path.write_text((f"parallel_steps = {parallel}\n" if parallel is not None else "") + text)
    return path


def test_step_inputs_name_the_steps_a_step_reads():
    recipe = parse_recipe("""
name = "refs"
[[steps]]
name = "play"
env = "myoHandReorient8-v0"
timesteps = 100
[[steps]]
name = "collect"
kind = "collect"
run = "@play"
[[steps]]
name = "fit"
kind = "fit"
activations = "@collect"
n_synergies = 3
[[steps]]
name = "sar-rl"
env = "myoHandReorient100-v0"
sar = "@fit"
timesteps = 100
[[steps]]
name = "e2e"
env = "myoHandReorient100-v0"
timesteps = 100
[[steps]]
name = "zeroshot"
kind = "zeroshot"
runs = ["@sar-rl", "@e2e"]
envs = ["myoHandReorientID-v0"]
[[steps]]
name = "curves"
kind = "compare"
groups = { "SAR" = ["@sar-rl"], "E2E" = ["@e2e"] }
""")
    assert {s.name: s.inputs() for s in recipe.steps} == {
        "play": [], "collect": ["play"], "fit": ["collect"], "sar-rl": ["fit"], "e2e": [],
        "zeroshot": ["sar-rl", "e2e"], "curves": ["sar-rl", "e2e"]}


def _fake_run(log: list, active: set, peak: list, fail: str | None = None, slow: str | None = None):
    """A step runner that records start/end order and how many train steps ran at once
    (train steps take 0.3 s, `slow` 10 s unless stopped)."""
    lock = threading.Lock()

    def run(step, detached, stop):
        with lock:
            log.append(("start", step.name, detached))
            if step.kind.trains:
                active.add(step.name)
                peak[0] = max(peak[0], len(active))
        deadline = time.monotonic() + (10 if step.name == slow else 0.3 if step.kind.trains else 0.05)
        while time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.01)
        with lock:
            active.discard(step.name)
            log.append(("end", step.name, stop.is_set()))
        if step.name == fail:
            raise RuntimeError(f"{step.name} broke")
        return {"name": step.name}
    return run


@pytest.mark.parametrize("limit", [1, 2, 3])
def test_schedule_respects_inputs_and_the_limit(tmp_path, limit):
    recipe = parse_recipe(STUDY)
    log, active, peak, finished = [], set(), [0], []
    results, overlaps = run_overlapped(
        recipe.steps, _fake_run(log, active, peak), limit, Console(file=open(os.devnull, "w")), lambda s: (0, 1),
        lambda s: s.name, lambda s: finished.append((s.name, threading.current_thread() is threading.main_thread())))
    assert set(results) == {"a", "a-eval", "b", "c"} and results["b"] == {"name": "b"}
    assert sorted(finished) == [("a", True), ("b", True), ("c", True)]  # figures: drawn by the study's own thread
    assert peak[0] == min(limit, 3)  # three train steps need nothing: as many at once as allowed
    order = [(what, name) for what, name, _ in log]
    assert order.index(("end", "a")) < order.index(("start", "a-eval"))  # an input is finished before it is read
    assert all(detached == (name != "a-eval") for what, name, detached in log if what == "start")
    if limit > 1:
        assert "b" in overlaps.beside["a"] and "a" in overlaps.beside["b"]


def test_a_failing_step_stops_the_others_and_is_raised():
    recipe = parse_recipe(STUDY)
    log, active, peak = [], set(), [0]
    with pytest.raises(RuntimeError, match="a-eval broke"):
        run_overlapped(recipe.steps, _fake_run(log, active, peak, fail="a-eval", slow="b"), 2,
                       Console(file=open(os.devnull, "w")), lambda s: (0, 1), lambda s: s.name)
    ends = {name: stopped for what, name, stopped in log if what == "end"}
    assert ends["a"] is False and ends["b"] is True  # b was still training: told to stop, and it did
    assert not active


def test_last_timesteps_reads_a_growing_metrics_file(tmp_path):
    assert last_timesteps(tmp_path) == 0
    metrics = tmp_path / "metrics.csv"
    metrics.write_text("timesteps,wall_seconds\r\n")
    assert last_timesteps(tmp_path) == 0
    metrics.write_text("timesteps,wall_seconds\r\n" + "".join(f"{i * 100},{i}\r\n" for i in range(1, 500))
                       + "50000,5")  # a row still being written
    assert last_timesteps(tmp_path) == 49900


def _timed(run_dir: Path) -> tuple[float, float]:
    """When a training started (its config.toml) and ended (its summary.json)."""
    return (run_dir / "config.toml").stat().st_mtime, (run_dir / "summary.json").stat().st_mtime


def test_parallel_study_equals_the_sequential_one(tmp_path):
    seq, par = tmp_path / "seq", tmp_path / "par"
    assert_ok(run_cli("run", _recipe(tmp_path, parallel=None), "--out", seq))
    proc = run_cli("run", _recipe(tmp_path), "--out", par)
    assert_ok(proc)
    s_seq, s_par = read_summary(seq), read_summary(par)
    assert s_seq["parallel_steps"] == 1 and s_par["parallel_steps"] == 2
    numbers = [k for k, v in s_seq.items() if k.split(".")[-1] in ("return_mean", "return_std", "timesteps",
                                                                      "success_rate", "return_iqm")]
    assert len(numbers) >= 10 and {k: s_par[k] for k in numbers} == {k: s_seq[k] for k in numbers}
    for run in ("a", "b", "c/seed0", "c/seed1"):  # the same networks, bit for bit
        assert (par / run / "policy.safetensors").read_bytes() == (seq / run / "policy.safetensors").read_bytes()
    (a0, a1), (b0, b1) = _timed(par / "a"), _timed(par / "b")
    assert a0 < b1 and b0 < a1  # a and b trained at the same time
    assert (par / "logs" / "a.log").is_file() and (par / "logs" / "b.log").is_file()
    for run in ("a", "b", "c/seed0", "c/seed1"):
        assert (par / run / "plots" / "learning_curve.png").stat().st_size > 1000
    table = (par / "table.txt").read_text()
    assert "ran beside" in table and "ran beside" not in (seq / "table.txt").read_text()
    assert "(in the background)" in proc.stdout
    again = run_cli("run", _recipe(tmp_path), "--out", par, "--resume")  # a finished study is kept, step by step
    assert_ok(again)
    assert again.stdout.count("already done with these settings; kept") == 5  # a, a-eval, b, c/seed0, c/seed1


def _motorlab_processes(marker: str) -> list[int]:
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError):
            continue
        if entry.name.isdigit() and "motorlab" in cmd and marker in cmd:
            pids.append(int(entry.name))
    return pids


def test_interrupting_a_parallel_study_stops_its_trainings(tmp_path):
    """SIGINT to the study process alone (not its process group): it must stop the background
    `motorlab train` processes itself, exit 130, and a re-run finishes what is left."""
    text = STUDY.replace("timesteps = 1536", "timesteps = 60000")  # b is still training when a is done
    text = text[:text.index('[[steps]]\nname = "c"')]  # c's two seeds would only add trainings to wait for
    out = tmp_path / "study"
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "run", str(_recipe(tmp_path, text)), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 180
    while not (out / "a" / "summary.json").exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert (out / "a" / "summary.json").exists(), proc.communicate()
    assert _motorlab_processes(str(out / "logs" / "b.job.json"))  # b trains in a process of its own (its job)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (stdout, stderr)
    assert "Traceback" not in stdout + stderr
    assert not _motorlab_processes(str(out / "logs" / "b.job.json")), "a background training outlived the study"
    assert not (out / "b" / "summary.json").exists() and not (out / "summary.json").exists()
    stamp = (out / "a" / "summary.json").stat().st_mtime_ns

    again = run_cli("run", _recipe(tmp_path, text.replace("timesteps = 60000", "timesteps = 1536")), "--out", out)
    assert_ok(again)
    assert (out / "a" / "summary.json").stat().st_mtime_ns == stamp  # kept, not trained again
    assert read_summary(out / "b")["timesteps"] == 1536


@pytest.mark.parametrize("args, fragment", [
    (["--parallel-steps", "0"], "--parallel-steps 0"),
    (["--parallel-steps", "2", "--backend", "ray"], "--parallel-steps 1"),
])
def test_bad_parallel_steps(tmp_path, args, fragment):
    proc = run_here("run", _recipe(tmp_path, parallel=None), "--out", tmp_path / "out", *args)
    assert_one_line_error(proc, fragment)
    assert not (tmp_path / "out").exists()


def test_bad_parallel_steps_in_a_recipe(tmp_path):
    proc = run_here("run", _recipe(tmp_path, parallel=0), "--check")
    assert_one_line_error(proc, "parallel_steps")


@pytest.mark.parametrize("name", ["sar-hand", "sar-hand-reference", "sar-hand-quick", "sar-legs", "sar-legs-reference",
                                  "sar-legs-quick"])
def test_sar_studies_train_their_two_chains_at_once(name):
    from motorlab.recipes import load_recipe

    recipe = load_recipe(name)
    inputs = {s.name: s.inputs() for s in recipe.steps}
    assert recipe.parallel_steps == 2
    assert inputs["rl-e2e"] == [] and inputs["play"] == []  # two chains: nothing joins them before the end
    chain, step = [], "sar-rl"
    while inputs[step]:
        step = inputs[step][0]
        chain.append(step)
    assert chain == ["fit", "collect", "play"]
