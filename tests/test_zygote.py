"""The tests' zygote (tests/zygote.py): a command forked from it is the process a fresh interpreter would be.

A user module (--import probe) writes what its process sees: working directory, environment, argv,
sys.path, pid and random draws.
"""

from __future__ import annotations

import json
import os
import signal
import string
import subprocess
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import assert_ok, run_cli
from tests.zygote import zygote_for

PROBE = """
import json, os, random, signal, sys, time
import numpy as np
out = os.environ["PROBE_OUT"]
with open(out, "w") as f:
    json.dump({"cwd": os.getcwd(), "env": {k: v for k, v in os.environ.items() if k.startswith("MLTEST_")},
               "argv": sys.argv, "path": sys.path, "pid": os.getpid(), "ppid": os.getppid(),
               "draws": [random.random(), float(np.random.random())], "stdin": sys.stdin.read()}, f)
if os.environ.get("PROBE_SLEEP"):
    time.sleep(float(os.environ["PROBE_SLEEP"]))
if os.environ.get("PROBE_SIGNAL"):
    os.kill(os.getpid(), int(os.environ["PROBE_SIGNAL"]))
"""


@pytest.fixture(scope="module")
def probe(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("probe")
    (folder / "probe.py").write_text(PROBE)
    return folder


def probed(probe: Path, out: Path, cwd: Path, fresh: bool = False, timeout: float = 120, **env: str):
    proc = run_cli("recipes", "--import", "probe", cwd=cwd, timeout=timeout, fresh=fresh,
                   env={"PYTHONPATH": str(probe), "PROBE_OUT": str(out), **env})
    return proc, (json.loads(out.read_text()) if out.is_file() else None)


def test_a_fork_sees_what_a_fresh_interpreter_sees(probe, tmp_path):
    forked, seen = probed(probe, tmp_path / "fork.json", tmp_path)
    fresh, seen_fresh = probed(probe, tmp_path / "fresh.json", tmp_path, fresh=True)
    assert_ok(forked), assert_ok(fresh)
    assert (forked.stdout, forked.stderr) == (fresh.stdout, fresh.stderr)
    for key in ("cwd", "env", "argv", "path", "stdin"):
        assert seen[key] == seen_fresh[key], key
    assert seen["path"][:2] == [str(tmp_path), str(probe)]
    assert seen["pid"] != os.getpid() and seen["draws"] != seen_fresh["draws"]


NAMES = st.text(string.ascii_uppercase + string.digits + "_", min_size=1, max_size=8).map(lambda s: "MLTEST_" + s)
VALUES = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=20)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(env=st.dictionaries(NAMES, VALUES, max_size=4), folder=st.text(string.ascii_letters, min_size=1, max_size=6))
def test_each_fork_gets_its_own_environment_folder_and_seeds(probe, tmp_path, env, folder):
    cwd = tmp_path / folder
    cwd.mkdir(exist_ok=True)
    runs = [probed(probe, cwd / f"seen{i}.json", cwd, **env) for i in range(2)]
    for proc, seen in runs:
        assert_ok(proc)
        assert seen["env"] == env and seen["cwd"] == str(cwd) and seen["path"][0] == str(cwd)
    assert runs[0][1]["pid"] != runs[1][1]["pid"]
    assert runs[0][1]["draws"][0] != runs[1][1]["draws"][0] and runs[0][1]["draws"][1] != runs[1][1]["draws"][1]


def test_a_fork_killed_by_a_signal_reports_it_as_subprocess_does(probe, tmp_path):
    forked, _ = probed(probe, tmp_path / "a.json", tmp_path, PROBE_SIGNAL=str(int(signal.SIGKILL)))
    fresh, _ = probed(probe, tmp_path / "b.json", tmp_path, fresh=True, PROBE_SIGNAL=str(int(signal.SIGKILL)))
    assert forked.returncode == fresh.returncode == -signal.SIGKILL


def test_a_fork_past_its_timeout_is_killed_and_raises_as_subprocess_does(probe, tmp_path):
    start = time.monotonic()
    with pytest.raises(subprocess.TimeoutExpired):
        probed(probe, tmp_path / "a.json", tmp_path, timeout=1.0, PROBE_SLEEP="60")
    assert time.monotonic() - start < 30
    pid = json.loads((tmp_path / "a.json").read_text())["pid"]
    for _ in range(100):  # the waiter reaps it as soon as it is killed
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        pytest.fail(f"the timed-out command {pid} still runs")


def test_an_environment_read_at_import_gets_a_fresh_interpreter():
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    assert zygote_for(env) is not None
    for changed in ({"OMP_NUM_THREADS": "7"}, {"MUJOCO_GL": "osmesa"}, {"PYTHONHASHSEED": "3"}, {"HOME": "/nowhere"}):
        assert zygote_for({**env, **changed}) is None, changed
    assert zygote_for({**env, "PYTHONPATH": "/somewhere", "MLTEST_X": "1"}) is not None
