"""A demanding user's adversarial tries (issue 35), each a test: the exit status, one line with no
traceback, and no file written before the mistake changed (checksums before and after).

Run folders: a finished run is never written into by accident, a step never writes into its
input's folder, a recipe writes nowhere outside its --out, an unwritable --out is one line, an
interrupted --overwrite loses nothing, and an interrupted recipe train step continues from its
checkpoint."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli, run_here, snapshot

LQR = ["--algo", "lqr", "--timesteps", "300", "--no-progress"]
UNWRITABLE = "/sys/motorlab-adversarial-out"  # a read-only file system, even for root (CI runs as root)


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished training run (the LQR learner: seconds)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    return out


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    """A finished `dynamics collect` run."""
    out = tmp_path_factory.mktemp("collected") / "data"
    assert_ok(run_here("dynamics", "collect", ENV_ID, "--episodes", "10", "--out", out))
    return out


# ---- a finished run is never overwritten by accident --------------------------------------

@pytest.mark.parametrize("command", [
    ["train", ENV_ID, *LQR],
    ["evaluate", "pid", "--env", ENV_ID, "--episodes", "1"],
    ["dynamics", "collect", ENV_ID, "--episodes", "2"],
    ["export", "{run}"],
], ids=["train", "evaluate", "dynamics-collect", "export"])
def test_writing_into_a_finished_run_is_refused(finished, tmp_path, command, request):
    from motorlab import claims

    target = tmp_path / "target"
    target.mkdir()
    claims.mark(target, request.node.callspec.id)  # a finished run of the command's own kind
    (target / "summary.json").write_text('{"finished": true}\n')
    (target / "policy.json").write_text('{"type": "precious"}\n')
    before = snapshot(target)
    proc = run_here(*[str(finished) if a == "{run}" else a for a in command], "--out", target)
    assert_one_line_error(proc, str(target), "finished run", "--overwrite")
    assert not proc.stdout.strip(), proc.stdout  # refused before any work (no episodes collected, no progress)
    assert snapshot(target) == before


def test_a_finished_out_is_refused_before_the_work(finished, collected, tmp_path, monkeypatch):
    """The steps whose work comes before their folder (episodes, a fit) refuse a finished --out once
    their inputs are checked, before that work starts: each one's work here fails the test if run."""
    from motorlab import claims
    from motorlab.api.running import run_kind
    from motorlab.dynamics import open_loop
    from motorlab.errors import MotorlabError
    from motorlab.evaluation import zeroshot
    from motorlab.kinds import KINDS
    from motorlab.kinds import evaluate as steps
    from motorlab.kinds import synergies as synergy_steps
    from motorlab.robustness_curves import curves
    from motorlab.synergy_runs import activations

    def work(*args, **kwargs):
        raise AssertionError("the work started before the finished --out was refused")

    activations_run = tmp_path / "activations"  # fit-sar's input: a synergies collect of the LQR run
    run_kind(KINDS["collect"], out=activations_run, progress=False, run=finished, episodes=2, preview=2,
             percentile=0, workers=1)
    model = tmp_path / "model"  # dynamics check's input
    run_kind(KINDS["dynamics-fit"], out=model, progress=False, transitions=collected, epochs=1)
    for module, name in [(steps, "evaluate"), (zeroshot, "evaluate"), (curves, "measure"),
                         (activations, "_episodes"), (synergy_steps, "fit_sar"), (open_loop, "open_loop")]:
        monkeypatch.setattr(module, name, work)
    target = tmp_path / "target"
    target.mkdir()
    (target / "summary.json").write_text('{"finished": true}\n')
    for kind, fields in [("evaluate", {"policy": "pid", "env": ENV_ID, "episodes": 1}),
                         ("zeroshot", {"runs": [finished], "envs": [ENV_ID], "episodes": 1}),
                         ("robustness", {"policies": [finished], "vary": ["delay=0,0.1"], "episodes": 1}),
                         ("collect", {"run": finished, "episodes": 2, "preview": 2}),
                         ("fit", {"activations": activations_run, "n_synergies": 1}),
                         ("dynamics-check", {"model": model, "episodes": 1})]:
        claims.mark(target, kind)  # a finished run of this very kind
        before = snapshot(target)
        with pytest.raises(MotorlabError, match="finished run"):
            run_kind(KINDS[kind], out=target, progress=False, **fields)
        assert snapshot(target) == before, kind


def test_overwrite_replaces_a_finished_run_whole(finished, tmp_path):
    out = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    stale = {p: p.read_bytes() for p in (out / "tensorboard").rglob("events.out.tfevents.*")}  # the old curves
    assert stale
    assert_ok(run_here("train", ENV_ID, "--algo", "lqr", "--timesteps", "400", "--no-progress", "--out", out,
                       "--overwrite"))
    assert read_summary(out)["timesteps"] == 400
    # TensorBoard events of two runs never mix (a new file may take an old name: same second, same process)
    assert not any(p.exists() and p.read_bytes() == data for p, data in stale.items())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing left aside


def _wait_for_the_new_run(out: Path) -> None:
    """Until --overwrite has moved the old run aside and the new one writes its folder."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if any(out.parent.glob(f".{out.name}.replaced-*")) and (out / "config.toml").is_file():
            assert not (out / "summary.json").exists()
            return
        time.sleep(0.05)
    raise AssertionError("the overwriting run never started")


def test_an_interrupted_overwrite_puts_the_old_run_back(finished, tmp_path):
    out = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    before = snapshot(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "train", ENV_ID, "--algo", "ppo", "--timesteps",
                             "100000", "--no-progress", "--out", str(out), "--overwrite"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_the_new_run(out)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert snapshot(tmp_path) == before  # the finished run is back, byte for byte


def test_a_killed_overwrite_is_undone_by_the_next_command(tmp_path):
    out = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    before = snapshot(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "train", ENV_ID, "--algo", "ppo", "--timesteps",
                             "100000", "--no-progress", "--out", str(out), "--overwrite"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait_for_the_new_run(out)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert_ok(run_here("evaluate", out, "--episodes", "1", "--out", tmp_path / "eval"))  # reading puts it back
    assert snapshot(out) == {k: v for k, v in before.items() if k.startswith(str(out))}


def test_a_run_with_a_damaged_summary_is_not_taken_as_finished(finished, tmp_path):
    run = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", run))
    (run / "summary.json").write_text('{"return_mean": 10')  # cut short, e.g. by a full disk
    before = snapshot(run)
    assert_one_line_error(run_here("evaluate", run, "--episodes", "1", "--out", tmp_path / "eval"),
                          "damaged summary.json", "did not finish")
    assert snapshot(run) == before
    assert not (tmp_path / "eval").exists()


# ---- a step never writes into its input's folder -----------------------------------------

@pytest.mark.parametrize("input_", ["{data}", "{data}/transitions.npz"])
def test_fit_into_its_own_input_folder_is_refused(collected, input_):
    before = snapshot(collected)
    proc = run_here("dynamics", "fit", input_.format(data=collected), "--epochs", "1", "--out", collected)
    assert_one_line_error(proc, str(collected), "input", "another --out")
    assert snapshot(collected) == before


def test_evaluate_into_the_run_it_evaluates_is_refused(tmp_path):
    run = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", run))
    (run / "summary.json").unlink()  # even an unfinished one: it is the input
    before = snapshot(run)
    proc = run_here("synergies", "collect", run, "--episodes", "2", "--out", run)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert snapshot(run) == before


# ---- recipes write nowhere outside --out ----------------------------------------------------

def _recipe(path: Path, step_name: str, episodes: int = 2) -> Path:
    path.write_text(textwrap.dedent(f"""\
        name = "victim-test"
        [[steps]]
        name = {json.dumps(step_name)}
        kind = "evaluate"
        policy = "pid"
        env = "{ENV_ID}"
        episodes = {episodes}
        """))
    return path


@pytest.mark.parametrize("name", ["../victim", "../../x", "/tmp/motorlab-adversarial", "a/b", "..", "plots", ""])
def test_a_recipe_step_name_cannot_write_outside_the_study(tmp_path, name):
    victim = tmp_path / "victim"
    assert_ok(run_here("evaluate", "pid", "--env", ENV_ID, "--episodes", "1", "--out", victim))
    recipe = _recipe(tmp_path / "r.toml", name)
    before = snapshot(tmp_path)
    proc = run_here("run", recipe, "--out", tmp_path / "study")
    assert_one_line_error(proc, "step name")
    after = snapshot(tmp_path)
    assert after == before
    assert not Path("/tmp/motorlab-adversarial").exists()


def test_run_check_refuses_a_bad_step_name_too(tmp_path):
    proc = run_here("run", _recipe(tmp_path / "r.toml", "../victim"), "--check")
    assert_one_line_error(proc, "'../victim'", "letters, digits")


def test_a_finished_study_needs_resume_and_a_changed_step_is_never_overwritten_silently(tmp_path):
    recipe, study = _recipe(tmp_path / "r.toml", "pid-eval"), tmp_path / "study"
    assert_ok(run_here("run", recipe, "--out", study))
    before = snapshot(study)
    assert_one_line_error(run_here("run", recipe, "--out", study), "finished run", "--resume", "--overwrite")
    assert snapshot(study) == before
    proc = run_here("run", recipe, "--out", study, "--resume")  # keeps the finished step
    assert_ok(proc)
    assert "already done with these settings; kept" in proc.stdout
    # an interrupted study (no summary.json) whose finished step's settings changed: refused, not redone
    (study / "summary.json").unlink()
    _recipe(recipe, "pid-eval", episodes=3)
    kept = snapshot(study / "pid-eval")
    proc = run_here("run", recipe, "--out", study)
    assert_one_line_error(proc, "pid-eval", "other settings", "--resume", "--overwrite")
    assert snapshot(study / "pid-eval") == kept
    proc = run_here("run", recipe, "--out", study, "--resume")  # asked for: the changed step is redone, said so
    assert_ok(proc)
    assert "settings or inputs changed; its earlier run is replaced" in proc.stdout
    assert read_summary(study / "pid-eval")["episodes"] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.toml", "study"]  # nothing left aside


def test_resume_of_a_finished_study_that_stops_early_leaves_it_finished(tmp_path):
    recipe, study = _recipe(tmp_path / "r.toml", "pid-eval"), tmp_path / "study"
    assert_ok(run_here("run", recipe, "--out", study))
    before = snapshot(study)
    bad = tmp_path / "bad.toml"  # same study, plus a step that fails before anything runs
    bad.write_text(recipe.read_text() + textwrap.dedent("""        [[steps]]
        name = "late"
        kind = "evaluate"
        policy = "/nonexistent/run"
        """))
    proc = run_here("run", bad, "--out", study, "--resume")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert read_summary(study)  # still a finished study
    # (its marker now names the late step's folder too: what an --overwrite of it would delete)
    assert {k: v for k, v in snapshot(study).items() if "/late" not in k and ".motorlab-run" not in k} == \
        {k: v for k, v in before.items() if ".motorlab-run" not in k}


def test_run_check_says_what_it_imports_before_importing(tmp_path):
    module = tmp_path / "sideeffect_mod.py"
    marker = tmp_path / "imported"
    module.write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    recipe = tmp_path / "r.toml"
    recipe.write_text(textwrap.dedent(f"""\
        name = "imports"
        imports = ["sideeffect_mod"]
        [[steps]]
        name = "eval"
        kind = "evaluate"
        policy = "pid"
        env = "{ENV_ID}"
        episodes = 1
        """))
    proc = run_cli("run", recipe, "--check", env={"PYTHONPATH": str(tmp_path)})
    assert_ok(proc)
    announced = proc.stdout.splitlines()[0]
    assert "imports (runs) this code: sideeffect_mod" in announced  # said first ...
    assert marker.read_text() == "ran"  # ... then done, as the docs' Safety section says


# ---- an unwritable --out ----------------------------------------------------------------------

@pytest.mark.parametrize("command", [
    ["train", ENV_ID, *LQR],
    ["evaluate", "pid", "--env", ENV_ID, "--episodes", "1"],
    ["run", "{recipe}"],
    ["tune", f"train {ENV_ID} --algo ppo --timesteps 256", "--space", "lr=loguniform:1e-4,1e-3",
     "--trials", "1", "--seeds", "1"],
    ["sweep", f"evaluate pid --env {ENV_ID} --episodes 1", "--seeds", "1"],
], ids=["train", "evaluate", "run", "tune", "sweep"])
def test_an_unwritable_out_is_one_line(tmp_path, command):
    recipe = _recipe(tmp_path / "r.toml", "eval")
    proc = run_here(*[str(recipe) if a == "{recipe}" else a for a in command], "--out", UNWRITABLE)
    assert_one_line_error(proc, UNWRITABLE)


# ---- a recipe's train step continues from its checkpoint -----------------------------------

def test_an_interrupted_recipe_train_step_resumes_from_its_checkpoint(tmp_path):
    recipe = tmp_path / "r.toml"
    recipe.write_text(textwrap.dedent(f"""\
        name = "resume-me"
        [[steps]]
        name = "ppo"
        env = "{ENV_ID}"
        algo = "ppo"
        timesteps = 6144
        checkpoint_every = 512
        hyperparams = {{n_steps = 256, batch_size = 64}}
        """))
    study = tmp_path / "study"
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "run", str(recipe), "--out", str(study)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    latest = study / "ppo" / "checkpoint" / "latest.json"
    deadline, steps = time.monotonic() + 180, 0
    while time.monotonic() < deadline and proc.poll() is None and steps < 1024:
        try:
            steps = json.loads(latest.read_text())["steps"]
        except (OSError, ValueError):
            time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc = run_cli("run", recipe, "--out", study)
    assert_ok(proc)
    assert "continuing the interrupted run from its last checkpoint" in proc.stdout
    summary = read_summary(study / "ppo")
    assert summary["resumed_from"] >= 1024 and summary["timesteps"] == 6144


def test_a_worker_started_with_ctrl_c_ignored_still_stops_on_it(tmp_path):
    """A background job of a shell without job control (`motorlab tune ... &` in a script) starts
    with SIGINT ignored, and its children inherit that: a trial's worker must still stop on the
    Ctrl-C its parent sends it (a pruned or stopped trial), not train to its budget."""
    from motorlab import jobs
    from motorlab.rl.config import resolve

    out = tmp_path / "run"
    settings = resolve({"env": {"id": ENV_ID}, "algo": "ppo", "timesteps": 100000, "progress": False})
    path = jobs.job("train", settings.config(), {"out": out}).write(tmp_path / "job.json")
    proc = subprocess.Popen(jobs.process(path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    deadline = time.monotonic() + 120
    while not (out / "config.toml").is_file() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert (out / "config.toml").is_file(), "the run never started"
    time.sleep(1.0)  # into training
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert not (out / "summary.json").exists()  # stopped, not finished


def test_what_motorlab_adds_to_a_finished_run_is_replaced_with_it_and_a_users_file_is_not(tmp_path):
    """`motorlab plot` and `motorlab report` write into a finished run's folder: its marker lists their files,
    so --overwrite replaces them with the run; a file of the user's in it is refused, as ever."""
    out = tmp_path / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    assert_ok(run_here("plot", out))
    assert_ok(run_here("report", out))
    assert (out / "report.html").is_file() and (out / "plots" / "observation_trace.png").is_file()
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out, "--overwrite"))
    (out / "plots" / "mine.png").write_bytes(b"the user's own figure")
    before = snapshot(out)
    proc = run_here("train", ENV_ID, *LQR, "--out", out, "--overwrite")
    assert_one_line_error(proc, "plots/mine.png, which its run did not write")
    assert snapshot(out) == before
