"""Fuzzed inputs (hypothesis): recipe files, command-line arguments and the array files users
pass around (sar.npz, transitions.npz, model.json). Every input either works or gives one line
`error: ...` with exit status 2; no traceback reaches the user; and nothing outside the run
folder the command was given (--out) is created, changed or removed.

Commands run in this process through `motorlab.cli.main` (what `python -m motorlab` runs),
so each example costs milliseconds, not an interpreter start. Examples are derandomized:
the same inputs are tried on every run.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motorlab.cli import main
from motorlab.kinds import KINDS as REGISTRY
from tests.helpers import run_kind

# each fuzz test's examples: 30 in make test; make test-generated runs 200 (MOTORLAB_FUZZ_EXAMPLES)
FUZZ = settings(max_examples=int(os.environ.get("MOTORLAB_FUZZ_EXAMPLES", 30)), deadline=None, derandomize=True,
                database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                       HealthCheck.data_too_large])
REACHER = "Reacher-v5"


class Accepted(Exception):
    """Raised in place of the learning loop: the command got as far as training."""


def snapshot(root: Path, skip: Path) -> dict[str, tuple[int, int]]:
    """(size, mtime) of every file under `root` except under `skip`."""
    files = {}
    for dirpath, dirnames, filenames in os.walk(root):
        if Path(dirpath) == skip:
            dirnames.clear()
            continue
        for name in filenames:
            stat = (Path(dirpath) / name).stat()
            files[os.path.relpath(Path(dirpath) / name, root)] = (stat.st_size, stat.st_mtime_ns)
    return files


class Sandbox:
    """A folder holding the inputs (inputs/) and the working directory (cwd/); `run` calls the
    CLI with --out sandbox/out and checks the result and that nothing else changed."""

    def __init__(self, root: Path):
        self.root = root
        self.inputs = root / "inputs"
        self.cwd = root / "cwd"
        self.out = root / "out"
        for d in (self.inputs, self.cwd):
            d.mkdir(parents=True, exist_ok=True)

    def reset(self) -> None:
        shutil.rmtree(self.out, ignore_errors=True)

    def run(self, *args, out: bool = True) -> tuple[int, str, str]:
        argv = ["motorlab", *map(str, args)] + (["--out", str(self.out)] if out else [])
        before = snapshot(self.root, self.out)
        stdout, stderr = io.StringIO(), io.StringIO()
        old_argv, old_cwd = sys.argv, os.getcwd()
        code: int | str | None = 0
        try:
            sys.argv = argv
            os.chdir(self.cwd)
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                main()
        except SystemExit as e:
            code = e.code
        finally:
            sys.argv = old_argv
            os.chdir(old_cwd)
        # anything but SystemExit (Accepted included) propagates: a traceback would have reached the user
        out_text, err_text = stdout.getvalue(), stderr.getvalue()
        shown = f"argv: {argv}\nexit {code}\nstdout:\n{out_text}\nstderr:\n{err_text}"
        assert "Traceback" not in out_text + err_text, shown
        if code not in (0, None):
            lines = [line for line in err_text.splitlines() if line.strip()]
            assert code == 2, shown
            assert len(lines) == 1 and lines[0].startswith("error: "), shown
        assert snapshot(self.root, self.out) == before, f"files outside --out changed\n{shown}"
        return int(code or 0), out_text, err_text


@pytest.fixture
def sandbox(tmp_path):
    return Sandbox(tmp_path)


def accepted_or_error(box: Sandbox, *args) -> str:
    """Run a command whose learning loop raises Accepted: 'accepted', 'ok' or 'error'."""
    try:
        code, _, _ = box.run(*args)
    except Accepted:
        return "accepted"
    return "ok" if code == 0 else "error"


# ---- recipe files -----------------------------------------------------------------------

KINDS = [*REGISTRY, "trian", 3]  # every kind a recipe can name, and two it cannot
FIELD_NAMES = ["env", "algo", "timesteps", "seed", "seeds", "delay", "history", "policy", "episodes", "lr",
               "preset", "hyperparams", "runs", "model", "transitions", "epochs", "horizon", "population",
               "activations", "n", "vaf", "method", "sar", "phi", "envs", "run", "percentile", "reward",
               "until_solved", "name", "kind", "timestep", "bogus", "threshold", "groups", "title", "camera"]
SCALARS = st.one_of(
    st.sampled_from(["InvertedPendulum-v5", REACHER, "NoSuch-v0", "ppo", "sac", "lqr", "@a", "@b", "@s1", "",
                     "linear:1e-3", "pid", "fast", "pca-ica", "nmf", "quadratic", "1e-3", "-1"]),
    st.integers(-3, 3), st.sampled_from([10**30, 2**63, 100]),
    st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
)
VALUES = st.one_of(SCALARS, st.lists(SCALARS, max_size=3), st.dictionaries(st.sampled_from(["n_steps", "gamma", "x"]),
                                                                         SCALARS, max_size=2))
STEP = st.dictionaries(st.sampled_from(FIELD_NAMES), VALUES, max_size=5).flatmap(
    lambda fields: st.tuples(st.sampled_from(KINDS), st.sampled_from(["a", "b", "s1", "a"]), st.just(fields)))


def recipe_text(steps, top: dict) -> str:
    data = {**top, "steps": [{**fields, "kind": kind, "name": name} for kind, name, fields in steps]}
    try:
        return tomli_w.dumps(data)
    except (TypeError, ValueError):  # NaN in a key-less spot etc.: fall back to a hand-made near-TOML text
        return f"name = 'x'\n[[steps]]\nkind = {json.dumps(str(steps[0][0]) if steps else 'train')}\n"


@FUZZ
@given(steps=st.lists(STEP, max_size=4),
       top=st.dictionaries(st.sampled_from(["name", "description", "seeds", "defaults", "nonsense"]), VALUES,
                           max_size=3),
       cut=st.one_of(st.none(), st.integers(0, 400)))
def test_fuzzed_recipes_validate_or_fail_in_one_line(sandbox, steps, top, cut):
    """`motorlab run FILE --check` on generated recipes, some cut short mid-text."""
    text = recipe_text(steps, top)
    if cut is not None:
        text = text[:cut]
    path = sandbox.inputs / "recipe.toml"
    path.write_text(text)
    sandbox.reset()
    code, out, _ = sandbox.run("run", path, "--check", out=False)
    assert (code == 0) == ("valid" in out)
    assert not sandbox.out.exists()  # --check writes nothing


@FUZZ
@given(data=st.binary(max_size=300))
def test_fuzzed_recipe_bytes_fail_in_one_line(sandbox, data):
    path = sandbox.inputs / "recipe.toml"
    path.write_bytes(data)
    sandbox.run("run", path, "--check", out=False)


# ---- command-line arguments ------------------------------------------------------------

TRICKY = ["-1", "0", "nan", "inf", "-inf", "1e309", "abc", "", " ", "1.5", "99999999999999999999", "../x",
          "/dev/null", "ü", "@step", "1,2", "=", "a=b", "--", "-"]
COUNT = st.sampled_from(["1", "2", *TRICKY])  # valid counts stay small: valid examples run for real
REAL = st.sampled_from(["0", "0.2", "0.05", *TRICKY])


def options(**pools) -> st.SearchStrategy[list[str]]:
    """A list of `--name value` pairs drawn from the pools, in random order, some left out."""
    pairs = [st.one_of(st.none(), st.tuples(st.just(f"--{name.replace('_', '-')}"), pool))
             for name, pool in pools.items()]
    return st.tuples(*pairs).map(lambda ps: [x for p in ps if p for x in p]).flatmap(st.permutations)


@FUZZ
@given(policy=st.sampled_from(["pid", "zero", "random", "pidd", "pid:kp=[1,20,0,0]", "pid:kp=[", "/nope", ""]),
       env=st.sampled_from(["InvertedPendulum-v5", "NoSuch-v0", REACHER, "", "Pendulum-v1"]),
       opts=options(episodes=COUNT, delay=REAL, history=COUNT, seed=st.sampled_from(["0", "7", "4294967296", *TRICKY]),
                    delay_on=st.sampled_from(["both", "action", "sensor", ""]),
                    env_arg=st.sampled_from(["reset_noise_scale=0.1", "x", "=1", "frame_skip=0"])))
def test_fuzzed_evaluate_arguments(sandbox, policy, env, opts):
    sandbox.reset()
    code, _, _ = sandbox.run("evaluate", policy, "--env", env, *opts)
    if code == 0:
        assert (sandbox.out / "summary.json").is_file()


@pytest.fixture
def no_learning(monkeypatch):
    """Training stops where SB3's learning loop would start: everything before it (argument
    checks, env, hyperparameters, model, run folder) runs for real."""
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    def learn(self, *args, **kwargs):
        raise Accepted

    for cls in (OnPolicyAlgorithm, OffPolicyAlgorithm):
        monkeypatch.setattr(cls, "learn", learn)


@FUZZ
@given(env=st.sampled_from(["InvertedPendulum-v5", "NoSuch-v0", "Pendulum-v1", "", "inverted"]),
       opts=options(algo=st.sampled_from(["ppo", "sac", "td3", "a2c", ""]), timesteps=COUNT,
                    lr=st.sampled_from(["1e-3", "linear:1e-3", "linear:", "constant:x", *TRICKY]),
                    set=st.sampled_from(["n_steps=64", "n_steps", "gamma=2", "batch_size=-1", "x=[1,2", "tau=0.5",
                                         "policy_kwargs={}", "n_steps=abc"]),
                    preset=st.sampled_from(["sar-sac", "nope", ""]), delay=REAL, history=COUNT,
                    n_envs=st.sampled_from(["1", *TRICKY]),  # 2+ would start subprocesses: slow, same checks
                    seed=st.sampled_from(["0", "-1", "4294967296", "abc"]),
                    checkpoint_every=COUNT, reward=st.sampled_from(["quadratic", "nope", ""])))
def test_fuzzed_train_arguments(sandbox, no_learning, env, opts):
    sandbox.reset()
    accepted_or_error(sandbox, "train", env, "--no-progress", *opts)


@FUZZ
@given(grid=st.lists(st.sampled_from(["lr=1e-3,3e-4", "lr=", "=1", "lr", "x=1,2", "algo=ppo|sac", "lr=1e-3,1e-3",
                                      "seed=1,2", "delay=0.1,abc"]), max_size=3),
       seeds=COUNT, target=st.sampled_from(["train InvertedPendulum-v5 --timesteps 64", "train", "'", "nosuch",
                                            "evaluate pid --env InvertedPendulum-v5", "pendulum", "/nope.toml"]))
def test_fuzzed_sweep_arguments_fail_before_running(sandbox, grid, seeds, target, monkeypatch):
    """Sweeps check every trial's command line before starting any; trials themselves are not
    started here (the pool is replaced), so only the checks run."""
    from motorlab import launcher

    def no_trials(*args, **kwargs):
        raise Accepted

    for name in ("run_local", "run_ray"):
        monkeypatch.setattr(launcher, name, no_trials)
    sandbox.reset()
    args = ["sweep", target, "--seeds", seeds] + [x for g in grid for x in ("--grid", g)]
    accepted_or_error(sandbox, *args)


# ---- array files: sar.npz, transitions.npz, model.json -----------------------------------

def array_strategy(shape_hint: tuple[int, ...]) -> st.SearchStrategy:
    """Arrays near `shape_hint`: right or wrong shape, float or other dtypes, NaN/Inf sometimes."""
    dims = st.lists(st.integers(0, 4), min_size=0, max_size=3)
    shapes = st.one_of(st.just(shape_hint), dims.map(tuple))
    return st.tuples(shapes, st.sampled_from(["f8", "f4", "i8", "bool", "U3", "c16"]),
                     st.sampled_from([None, "nan", "inf"])).map(_make_array)


def _make_array(spec) -> np.ndarray:
    shape, dtype, poison = spec
    arr = np.linspace(-1.0, 1.0, int(np.prod(shape)) or 0).reshape(shape) if shape else np.array(0.5)
    if dtype == "U3":
        return arr.astype(str).astype("U3")
    out = arr.astype(dtype)
    if poison and out.size and out.dtype.kind in "fc":
        out.flat[0] = float(poison)
    return out


def mutated_npz(path: Path, base: dict[str, np.ndarray], data) -> None:
    """Write `base` with some keys dropped, replaced, added, or the file's bytes damaged."""
    arrays = dict(base)
    for key in data.draw(st.lists(st.sampled_from(sorted(base)), max_size=2, unique=True)):
        action = data.draw(st.sampled_from(["drop", "replace", "json"]))
        if action == "drop":
            arrays.pop(key)
        elif action == "replace":
            arrays[key] = data.draw(array_strategy(np.shape(base[key])))
        else:
            arrays[key] = np.array(data.draw(st.sampled_from(['{"x": 1}', "[1, 2]", "{", "null", '"s"'])))
    if data.draw(st.booleans()):
        arrays["extra"] = np.zeros(2)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    raw = buf.getvalue()
    damage = data.draw(st.sampled_from(["none", "none", "truncate", "flip", "object"]))
    if damage == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    elif damage == "flip":
        i = data.draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ 0xFF]) + raw[i + 1:]
    elif damage == "object":  # a pickled object array: must be refused, never loaded
        buf = io.BytesIO()
        np.savez(buf, **{**arrays, next(iter(arrays), "a"): np.array([{"a": 1}], dtype=object)})
        raw = buf.getvalue()
    path.write_bytes(raw)


@pytest.fixture(scope="module")
def reacher_files(tmp_path_factory):
    """A small real transitions.npz and a model fit on it (one epoch)."""
    from motorlab.kinds.dynamics import DYNAMICS_COLLECT, DYNAMICS_FIT

    root = tmp_path_factory.mktemp("reacher")
    run_kind(DYNAMICS_COLLECT, root / "data", env=REACHER, episodes=4, workers=1)
    run_kind(DYNAMICS_FIT, root / "model", transitions=str(root / "data"), epochs=1, hidden=[8], batch_size=50)
    with np.load(root / "data" / "transitions.npz", allow_pickle=False) as f:
        transitions = {k: f[k] for k in f.files}
    return root, transitions


@FUZZ
@given(data=st.data())
def test_fuzzed_transitions_files(sandbox, reacher_files, data):
    """`motorlab dynamics fit` on damaged transitions.npz files."""
    _, base = reacher_files
    path = sandbox.inputs / "transitions.npz"
    mutated_npz(path, base, data)
    sandbox.reset()
    code, _, _ = sandbox.run("dynamics", "fit", path, "--epochs", "1", "--hidden", "4", "--batch-size", "50")
    if code == 0:
        assert (sandbox.out / "model.json").is_file()


JSON_VALUES = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-2, 3), st.sampled_from([10**12, -10**12]),
                                     st.floats(allow_nan=False), st.text(max_size=4)),
                           lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner,
                                                                                       max_size=2), max_leaves=5)


def json_paths(value, prefix=()) -> list[tuple]:
    paths = [prefix] if prefix else []
    if isinstance(value, dict):
        for k, v in value.items():
            paths += json_paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            paths += json_paths(v, prefix + (i,))
    return paths


def mutate_json(doc, data):
    doc = json.loads(json.dumps(doc))
    for _ in range(data.draw(st.integers(1, 3))):
        paths = json_paths(doc)
        if not paths:
            break
        path = data.draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        if data.draw(st.booleans()):
            del parent[path[-1]]
        else:
            parent[path[-1]] = data.draw(JSON_VALUES)
    return doc


@FUZZ
@given(data=st.data())
def test_fuzzed_model_json(sandbox, reacher_files, data):
    """`motorlab dynamics check` and `motorlab mpc` on model folders whose model.json is damaged."""
    root, _ = reacher_files
    model = sandbox.inputs / "model"
    model.mkdir(exist_ok=True)
    shutil.copy(root / "model" / "model.safetensors", model / "model.safetensors")
    doc = json.loads((root / "model" / "model.json").read_text())
    text = json.dumps(mutate_json(doc, data))
    if data.draw(st.integers(0, 9)) == 0:
        text = text[: data.draw(st.integers(0, len(text)))]
    (model / "model.json").write_text(text)
    sandbox.reset()
    if data.draw(st.booleans()):
        sandbox.run("dynamics", "check", model, "--episodes", "1", "--steps", "3")
    else:
        sandbox.run("mpc", REACHER, "--model", model, "--episodes", "1", "--horizon", "2", "--population", "4",
                    "--iterations", "1", "--elites", "2")


@pytest.fixture(scope="module")
def reacher_sar(tmp_path_factory):
    """A 1-synergy SAR for Reacher's 2 actuators, as arrays."""
    from motorlab.synergies.sar import fit_sar, save_sar

    rng = np.random.default_rng(0)
    acts = np.clip(rng.normal(size=(200, 1)) @ np.array([[1.0, 0.5]]) * 0.3 + 0.5, 0, 1)
    path = save_sar(fit_sar(acts, 1), tmp_path_factory.mktemp("sar") / "sar.npz")
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


@FUZZ
@given(data=st.data())
def test_fuzzed_sar_files(sandbox, no_learning, reacher_sar, data):
    """`motorlab train Reacher-v5 --sar FILE` on damaged sar.npz files (up to where learning starts)."""
    path = sandbox.inputs / "sar.npz"
    mutated_npz(path, reacher_sar, data)
    phi = data.draw(st.sampled_from(["1", "0.66", "0", "2", "nan"]))
    sandbox.reset()
    accepted_or_error(sandbox, "train", REACHER, "--sar", path, "--phi", phi, "--algo", "ppo", "--timesteps", "64",
                      "--no-progress")


# ---- the harness itself: unmodified inputs work, so the properties above are not vacuous ----

def test_harness_runs_valid_inputs_for_real(sandbox, no_learning, reacher_files, reacher_sar):
    root, transitions = reacher_files
    np.savez(sandbox.inputs / "transitions.npz", **transitions)
    np.savez(sandbox.inputs / "sar.npz", **reacher_sar)
    assert sandbox.run("run", "reacher-quick", "--check", out=False)[0] == 0
    sandbox.reset()
    assert sandbox.run("evaluate", "pid", "--env", "InvertedPendulum-v5", "--episodes", "1")[0] == 0
    sandbox.reset()
    assert accepted_or_error(sandbox, "train", "InvertedPendulum-v5", "--no-progress") == "accepted"
    sandbox.reset()
    assert accepted_or_error(sandbox, "train", REACHER, "--sar", sandbox.inputs / "sar.npz", "--phi", "0.66",
                             "--no-progress") == "accepted"
    sandbox.reset()
    assert sandbox.run("dynamics", "fit", sandbox.inputs / "transitions.npz", "--epochs", "1")[0] == 0
    sandbox.reset()
    assert sandbox.run("dynamics", "check", root / "model", "--episodes", "1", "--steps", "3")[0] == 0
    sandbox.reset()
    assert sandbox.run("mpc", REACHER, "--model", root / "model", "--episodes", "1", "--horizon", "2",
                       "--population", "4", "--iterations", "1", "--elites", "2")[0] == 0
    # and a mistake is caught by the harness's checks: one line, exit 2
    assert sandbox.run("evaluate", "pid", "--env", "NoSuch-v0")[0] == 2
