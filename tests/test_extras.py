"""The optional stacks (MyoSuite, Upkie, Ray Tune, EvoTorch) are pip extras: the core works
without them, and each place that needs one says, in one line, how to install it.

A missing stack is simulated with `sys.modules[name] = None`, which makes `import name`
raise ImportError as on a machine without it. Checks that depend on Gymnasium's registry
(MyoSuite and Upkie register their ids on import) run in a fresh interpreter.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from motorlab.errors import MotorlabError
from motorlab.extras import EXTRAS, install_hint, require
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, read_summary

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

ROOT = Path(__file__).resolve().parents[1]
STACKS = ("myosuite", "upkie", "pybullet", "ray", "evotorch", "gymnasium_robotics")  # the top-level modules of the extras
BLOCK = f"import sys\nfor _m in {STACKS!r}:\n    sys.modules[_m] = None\n"

MYOSUITE_HINT = "pip install 'motorlab[myosuite]' (or: pip install myosuite==3.0.0)"
UPKIE_HINT = "pip install 'motorlab[upkie]' (or: pip install upkie==13.1.0 pybullet==3.2.7)"
RAY_HINT = "pip install 'motorlab[ray]' (or: pip install 'ray[tune]==2.60.0')"
EVOTORCH_HINT = "pip install 'motorlab[evotorch]' (or: pip install evotorch==0.6.1)"


def python(code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """`python -c CODE` in a fresh interpreter, from the repo root."""
    return subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, cwd=ROOT,
                          timeout=timeout, env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})


def cli(*args: str | os.PathLike, blocked: tuple[str, ...] = STACKS) -> subprocess.CompletedProcess:
    """The CLI in a fresh interpreter where the `blocked` modules cannot be imported."""
    argv = ["motorlab", *map(str, args)]
    code = (f"import sys\nfor _m in {blocked!r}:\n    sys.modules[_m] = None\n"
            f"from motorlab.cli import main\nsys.argv = {argv!r}\nmain()\n")
    return python(code)


def error_line(code: str) -> str:
    """Run CODE (which must raise MotorlabError) in a fresh interpreter; return the message it printed."""
    proc = python(BLOCK + "from motorlab.errors import MotorlabError\ntry:\n" + textwrap.indent(code, "    ")
                  + "\nexcept MotorlabError as e:\n    print('MOTORLAB_ERROR', e)\nelse:\n    print('NO_ERROR')\n")
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.startswith(("MOTORLAB_ERROR", "NO_ERROR"))]
    assert lines and lines[-1].startswith("MOTORLAB_ERROR "), proc.stdout + proc.stderr
    return lines[-1].removeprefix("MOTORLAB_ERROR ")


# ---- packaging --------------------------------------------------------------------------

def _pins(reqs: list[str]) -> dict[str, str]:
    out = {}
    for r in map(Requirement, reqs):
        if canonicalize_name(r.name) == "motorlab":
            continue
        (spec,) = r.specifier
        assert spec.operator == "==", f"{r} is not pinned exactly"
        out[canonicalize_name(r.name)] = spec.version
    return out


def test_extras_table_matches_pyproject_and_the_lock_covers_every_pin():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    optional = project["optional-dependencies"]
    # motorlab.extras names exactly what pyproject installs for each stack
    for extra, reqs in EXTRAS.items():
        assert tuple(optional[extra]) == reqs, extra
    assert optional["all"] == [f"motorlab[{','.join(EXTRAS)}]"]
    assert {"ruff==0.17.5", "import-linter==2.16"} <= set(optional["test"])
    # the core does not pull in any stack
    core = _pins(project["dependencies"])
    stacks = {canonicalize_name(Requirement(r).name) for reqs in EXTRAS.values() for r in reqs}
    assert not core.keys() & stacks
    assert core["rich"] == "14.3.4"  # MyoSuite (via viser) needs rich<15
    # requirements.lock pins every direct requirement at the same version
    lock = {}
    for line in (ROOT / "requirements.lock").read_text().split():
        name, version = line.split("==")
        lock[canonicalize_name(name)] = version.split("+")[0]  # torch==2.13.0+cpu
    pins = {**core, **{k: v for reqs in optional.values() for k, v in _pins(reqs).items()}}
    assert {"grimp", "ruff", "import-linter"} <= lock.keys()
    for name, version in pins.items():
        assert lock.get(name) == version, f"{name}=={version}: requirements.lock has {lock.get(name)}"


def test_setup_installs_all_extras():
    setup = (ROOT / "scripts/setup.sh").read_text()
    assert '-c requirements.lock -e ".[all,test,docs]"' in setup  # docs: make docs, run by make test


# ---- the helper -------------------------------------------------------------------------

def test_require_returns_the_module():
    import motorlab.errors

    assert require("motorlab.errors", "ray", "x needs y") is motorlab.errors


def test_require_gives_one_line_with_the_pip_command(monkeypatch):
    # block the submodule too: an earlier test may have imported it into this process already
    monkeypatch.setitem(sys.modules, "evotorch", None)
    monkeypatch.setitem(sys.modules, "evotorch.algorithms", None)
    with pytest.raises(MotorlabError) as e:
        require("evotorch.algorithms", "evotorch", "the thing needs EvoTorch")
    assert str(e.value) == f"the thing needs EvoTorch, which is not installed: {EVOTORCH_HINT}"
    assert e.value.__cause__ is None and e.value.__suppress_context__  # `from None`: no chained traceback


def test_require_tells_a_broken_install_from_a_missing_one(tmp_path, monkeypatch):
    # installed, but a dependency of it is missing: name that, and still give the pip command
    (tmp_path / "halfstack.py").write_text("import not_a_module_motorlab_knows\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(MotorlabError) as e:
        require("halfstack", "ray", "the sweep needs Ray Tune")
    message = str(e.value)
    assert "\n" not in message
    assert "importing halfstack failed (No module named 'not_a_module_motorlab_knows')" in message
    assert message.endswith(RAY_HINT)


def test_install_hints_quote_brackets_for_the_shell():
    assert install_hint("ray") == RAY_HINT
    assert install_hint("upkie") == UPKIE_HINT
    with pytest.raises(KeyError, match="myosuite, upkie, ray, evotorch"):
        install_hint("cuda")


# ---- each stack, where it is needed -------------------------------------------------------

def test_missing_myosuite():
    message = error_line("from motorlab.envs import check_env_id\ncheck_env_id('myoHandReorient8-v0')")
    assert message == f"myoHandReorient8-v0 needs MyoSuite, which is not installed: {MYOSUITE_HINT}"


def test_missing_myosuite_in_the_cli(tmp_path):
    proc = cli("train", "myoHandReorient8-v0", "--no-progress", "--out", tmp_path / "out")
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == f"error: myoHandReorient8-v0 needs MyoSuite, which is not installed: {MYOSUITE_HINT}"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("blocked, message", [
    (("upkie",), f"Upkie envs need the upkie package, which is not installed: {UPKIE_HINT}"),
    (("pybullet",), f"Upkie's PyBullet backend needs pybullet, which is not installed: {UPKIE_HINT}"),
])
def test_missing_upkie(blocked, message):
    code = (f"import sys\nfor _m in {blocked!r}:\n    sys.modules[_m] = None\n"
            "from motorlab.envs import check_env_id\n"
            "from motorlab.errors import MotorlabError\n"
            "try:\n    check_env_id('Upkie-PyBullet-Pendulum')\n"
            "except MotorlabError as e:\n    print('MOTORLAB_ERROR', e)\n")
    proc = python(code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == f"MOTORLAB_ERROR {message}"


def test_missing_ray(monkeypatch, tmp_path):
    from motorlab.launcher import run_ray

    for var in ("RAY_USAGE_STATS_ENABLED", "TUNE_DISABLE_AUTO_CALLBACK_LOGGERS", "RAY_AIR_NEW_OUTPUT"):
        monkeypatch.setenv(var, os.environ.get(var, "0"))  # run_ray sets them; keep them out of later tests
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(MotorlabError) as e:
        run_ray([{"args": []}], None, None, 1.0, tmp_path / "storage", on_done=None)
    assert str(e.value) == f"the ray backend needs Ray Tune, which is not installed: {RAY_HINT}"
    assert not (tmp_path / "storage").exists()


def test_missing_evotorch(monkeypatch):
    from motorlab.planning.planners import make_planner

    def score(states, actions, goals):
        return -actions.square().sum((1, 2))

    monkeypatch.setitem(sys.modules, "evotorch", None)
    with pytest.raises(MotorlabError) as e:
        make_planner("evotorch", score, -np.ones(2), np.ones(2))
    assert str(e.value) == f"--optimizer evotorch needs EvoTorch, which is not installed: {EVOTORCH_HINT}"
    # the built-in CEM needs no extra
    planner = make_planner("cem", score, -np.ones(2), np.ones(2), horizon=3, population=16, elites=4)
    planner.reset(1)
    assert planner.plan(torch.zeros(1, 3), torch.zeros(1, 0)).shape == (1, 2)


# ---- the core without any stack -------------------------------------------------------------

def test_every_module_but_the_ray_callback_imports_without_the_stacks():
    code = BLOCK + textwrap.dedent("""
        import importlib, json, pkgutil
        import motorlab
        failed = {}
        for m in pkgutil.walk_packages(motorlab.__path__, "motorlab."):
            if m.name == "motorlab.__main__":  # runs the CLI
                continue
            try:
                importlib.import_module(m.name)
            except ImportError as e:
                failed[m.name] = str(e)
        print(json.dumps(failed))
    """)
    proc = python(code)
    assert proc.returncode == 0, proc.stderr
    failed = json.loads(proc.stdout.strip().splitlines()[-1])
    # Ray Tune's classes, imported only after launcher.init_ray's check: the sweep's callback
    # (ray_progress), tune's searcher and scheduler (ray_study) and trainable (ray_trial)
    assert set(failed) == {"motorlab.sweeps.ray_progress", "motorlab.tuning.ray_study", "motorlab.tuning.ray_trial"}, failed


def test_pendulum_trains_without_the_stacks(tmp_path):
    out = tmp_path / "ppo"
    proc = cli("train", ENV_ID, *TINY_PPO, "--no-progress", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["env_id"] == ENV_ID and s["algo"] == "ppo" and s["timesteps"] == 256
    assert (out / "policy.json").is_file() and (out / "policy.safetensors").is_file()


def test_extras_sits_on_the_ground_floor():
    # motorlab.extras may import motorlab.errors and nothing else of motorlab's
    import ast

    tree = ast.parse((ROOT / "motorlab/extras.py").read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert {m for m in imported if m.split(".")[0] == "motorlab"} == {"motorlab.errors"}
