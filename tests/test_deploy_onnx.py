"""`motorlab export RUN --onnx`: the ONNX graph acts as the torch policy does (normalization,
history stack, action bounds, SAR decode), examples/onnx_runner.py runs it without torch, and
an export that cannot be done is one clear line that leaves files already written alone.

The CLI test assumes this behaviour of `motorlab export` (motorlab/cli.py):

    motorlab export RUN --onnx --out DIR
        --onnx: "Write the run's policy as DIR/policy.onnx (observation normalization, history
                 stack and action bounds inside the graph) for onnxruntime on a robot, and its
                 interface as DIR/policy.onnx.json; checked against torch to 1e-5 first."
        calls motorlab.deploy_onnx.export_onnx(RUN, DIR), exits 0, and prints one line:
        "exported PPO policy to ONNX (history 3, max |onnxruntime - torch| 6e-08 on 456
         observations) -> DIR/policy.onnx, DIR/policy.onnx.json"
    its MotorlabErrors (PID/LQR runs, no policy, not a run folder) are one line, exit code 2.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from motorlab import deploy_onnx
from motorlab.controllers import save_controller
from motorlab.deploy_onnx import ONNX_FILE, SIDECAR, TOLERANCE, export_onnx
from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.policies import load_run_policy, save_sb3_policy
from motorlab.runs import write_config, write_summary
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, run_cli

RUNNER = Path(__file__).resolve().parents[1] / "examples" / "onnx_runner.py"
# Trained through the CLI: one run with a history of 3, one with observation normalization.
TRAINED = {
    "ppo-history3": [*TINY_PPO, "--history", "3"],
    "sac-normalize": ["--algo", "sac", "--timesteps", "300", "--set", "learning_starts=100", "--normalize"],
}


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> dict[str, Path]:
    """The TRAINED runs, trained side by side (each is one `motorlab train` process)."""
    root = tmp_path_factory.mktemp("onnx-runs")

    def train(name: str) -> Path:
        assert_ok(run_cli("train", ENV_ID, *TRAINED[name], "--seed", "0", "--no-progress", "--out", root / name))
        return root / name

    with ThreadPoolExecutor(len(TRAINED)) as pool:
        return dict(zip(TRAINED, pool.map(train, TRAINED)))


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory) -> dict[str, dict]:
    """export_onnx's summary for each trained run."""
    root = tmp_path_factory.mktemp("onnx-out")
    return {name: export_onnx(run, root / name) for name, run in trained.items()}


def env_of(run: Path) -> EnvConfig:
    return EnvConfig(**tomllib.loads((run / "config.toml").read_text())["env"])


def session_of(summary: dict):
    import onnxruntime as ort

    return ort.InferenceSession(summary["onnx"], providers=["CPUExecutionProvider"])


def torch_episode(run: Path, seed: int) -> tuple[float, int]:
    """The return and length of one episode of the run's torch policy in the run's env."""
    env, policy = make_env(env_of(run), shaped=False), load_run_policy(run)
    obs, _ = env.reset(seed=seed)
    total, steps, done = 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(policy.act(np.asarray(obs, np.float32)[None])[0])
        total, steps, done = total + float(reward), steps + 1, terminated or truncated
    env.close()
    return total, steps


# ---- the round trip ------------------------------------------------------------------

@pytest.mark.parametrize("name", TRAINED)
def test_onnx_acts_as_torch_on_env_steps(name, trained, exported):
    """Stepping the env, onnxruntime fed as a robot feeds it (its own next_obs_stack back) gives
    torch's action on the env's stacked observation to 1e-5, and the env's stack itself."""
    run, summary = trained[name], exported[name]
    cfg, policy, session = env_of(run), load_run_policy(run), session_of(summary)
    size, history = summary["observation_size"], summary["history"]
    env = make_env(cfg, shaped=False)
    worst, steps = 0.0, 0
    for seed in (1, 2, 3):
        stacked, _ = env.reset(seed=seed)
        stacked = np.asarray(stacked, np.float32)
        stack = np.tile(stacked[-size:], history)[None]
        done = False
        while not done and steps < 300:
            feed = {"obs": stacked[None, -size:]} | ({"obs_stack": stack} if history > 1 else {})
            action, *rest = session.run(None, feed)
            if history > 1:
                stack = rest[0]
                np.testing.assert_array_equal(stack[0], stacked)  # the graph's stack is the env's
            expected = policy.act(stacked[None])
            worst = max(worst, float(np.max(np.abs(action - expected))))
            stacked, _, terminated, truncated, _ = env.step(expected[0])
            stacked, done, steps = np.asarray(stacked, np.float32), terminated or truncated, steps + 1
    env.close()
    assert steps > 10
    assert worst <= TOLERANCE


def test_the_export_summary_and_sidecar_describe_the_graph(exported):
    for summary in exported.values():
        sidecar = json.loads(Path(summary["sidecar"]).read_text())
        assert summary["files"] == [summary["onnx"], summary["sidecar"]]
        assert Path(summary["onnx"]).name == ONNX_FILE and Path(summary["sidecar"]).name == SIDECAR
        assert 0.0 <= summary["max_abs_error"] <= TOLERANCE and summary["tolerance"] == TOLERANCE
        assert summary["checked_observations"] > summary["env_observations"] > 0
        assert summary["opset"] == 17 and summary["env_id"] == ENV_ID
        for key in ("inputs", "outputs", "max_abs_error", "history", "normalized", "algo"):
            assert sidecar[key] == summary[key], key
        session = session_of(summary)
        meta = session.get_modelmeta().custom_metadata_map
        assert json.loads(meta["interface"]) == {"inputs": sidecar["inputs"], "outputs": sidecar["outputs"]}
        assert int(meta["history"]) == summary["history"] and meta["env_id"] == ENV_ID
        # what onnxruntime reads from the graph is what the sidecar says
        for described, actual in ((sidecar["inputs"], session.get_inputs()), (sidecar["outputs"], session.get_outputs())):
            assert [(d["name"], d["shape"], "tensor(float)") for d in described] == \
                   [(a.name, a.shape, a.type) for a in actual]
        # the batch dimension is dynamic
        for batch in (1, 5):
            feed = {i.name: np.zeros((batch, i.shape[1]), np.float32) for i in session.get_inputs()}
            assert session.run(["action"], feed)[0].shape == (batch, 1)
    assert exported["ppo-history3"]["history"] == 3 and not exported["ppo-history3"]["normalized"]
    assert [i["shape"] for i in exported["ppo-history3"]["inputs"]] == [["batch", 4], ["batch", 12]]
    assert exported["sac-normalize"]["normalized"] and exported["sac-normalize"]["history"] == 1
    assert [o["name"] for o in exported["sac-normalize"]["outputs"]] == ["action"]


@pytest.mark.parametrize("name", TRAINED)
def test_the_runner_example_gets_the_torch_return(name, trained, exported):
    """examples/onnx_runner.py (numpy + onnxruntime + gymnasium, no torch) completes an episode
    with the return the torch policy gets on the same seed."""
    seed = 4
    # as on a robot: torch, SB3 and motorlab cannot be imported
    blocked = ("import runpy, sys; sys.modules.update(dict.fromkeys(['torch', 'stable_baselines3', 'motorlab'])); "
               f"sys.argv = sys.argv[1:]; runpy.run_path({str(RUNNER)!r}, run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", blocked, str(RUNNER), exported[name]["onnx"], "--seed", str(seed)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    expected, length = torch_episode(trained[name], seed)
    assert result["length"] == length
    assert result["return"] == pytest.approx(expected, abs=1e-6)


# ---- policies the CLI does not train cheaply: made in this process ------------------------

def handmade_run(folder: Path, algo: str, cfg: EnvConfig, **kwargs) -> Path:
    """A run folder with an untrained SB3 policy for `cfg`'s env, as `motorlab train` lays it out."""
    import stable_baselines3

    env = make_env(cfg)
    model = getattr(stable_baselines3, algo.upper())("MlpPolicy", env, device="cpu", seed=0,
                                                     policy_kwargs={"net_arch": [16, 16]}, **kwargs)
    env.close()
    save_sb3_policy(folder, model, algo)
    write_config(folder, {"algo": algo, "env": cfg.model_dump()})
    write_summary(folder, {"algo": algo, "env_id": cfg.id})
    return folder


def reacher_sar(folder: Path) -> Path:
    """A one-synergy SAR of Reacher-v5's two motor commands (signal "action": decoded, then clipped)."""
    from motorlab.synergies import fit_sar, save_sar

    rng = np.random.default_rng(0)
    source = rng.uniform(-1, 1, (300, 1))
    actions = np.clip(source @ np.array([[0.9, -0.6]]) + rng.normal(0, 0.02, (300, 2)), -1, 1)
    return save_sar(fit_sar(actions, n_synergies=1, method="pca", signal="action", bounds=(-1.0, 1.0)),
                    folder / "sar.npz")


@pytest.mark.parametrize("case", ["td3", "ppo-gsde", "ppo-sar-blend"])
def test_other_policies_export_within_tolerance(case, tmp_path):
    if case == "td3":
        run = handmade_run(tmp_path / case, "td3", EnvConfig(id=ENV_ID, history=2))
    elif case == "ppo-gsde":
        run = handmade_run(tmp_path / case, "ppo", EnvConfig(id=ENV_ID), use_sde=True)
    else:  # the policy acts in [synergy, raw] space; the graph decodes to Reacher's two commands
        cfg = EnvConfig(id="Reacher-v5", sar=str(reacher_sar(tmp_path)), phi=0.5)
        run = handmade_run(tmp_path / case, "ppo", cfg)
    summary = export_onnx(run, tmp_path / "out")
    assert summary["max_abs_error"] <= TOLERANCE
    if case == "ppo-sar-blend":
        assert summary["action_size"] == 2 and summary["sar"] and summary["phi"] == 0.5
        assert load_run_policy(run).policy.action_space.shape == (3,)  # 1 synergy + 2 raw commands


# ---- what cannot be exported ------------------------------------------------------------

def pid_run(folder: Path) -> Path:
    from motorlab.controllers.pid import make_pid

    save_controller(folder, make_pid("pid", ENV_ID, 4, 0.04, np.array([-3.0]), np.array([3.0])))
    write_summary(folder, {"algo": "pid"})
    return folder


def test_unsupported_exports_are_one_line_and_leave_files_alone(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / ONNX_FILE).write_bytes(b"an earlier export")
    no_policy = tmp_path / "evaluate-run"
    no_policy.mkdir()
    write_summary(no_policy, {"return_mean": 1.0})
    not_a_run = tmp_path / "folder"
    not_a_run.mkdir()
    cases = {pid_run(tmp_path / "pid-run"): "PID controller", no_policy: "holds no policy",
             not_a_run: "not a run folder", Path("pid"): "built-in controller", tmp_path / "nothing": "does not exist"}
    for source, fragment in cases.items():
        with pytest.raises(MotorlabError) as e:
            export_onnx(source, out)
        assert fragment in str(e.value) and "\n" not in str(e.value)
    assert (out / ONNX_FILE).read_bytes() == b"an earlier export"
    assert not (out / SIDECAR).exists()


def test_a_mismatch_with_torch_is_an_error(trained, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / ONNX_FILE).write_bytes(b"an earlier export")
    monkeypatch.setattr(deploy_onnx, "TOLERANCE", -1.0)  # no difference passes, not even zero
    with pytest.raises(MotorlabError, match="differ from torch's"):
        export_onnx(trained["ppo-history3"], out)
    assert (out / ONNX_FILE).read_bytes() == b"an earlier export"
    assert sorted(p.name for p in out.iterdir()) == [ONNX_FILE]  # no temp file left either


def test_missing_onnx_package_names_the_pip_line(trained, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)  # import onnx raises ImportError
    with pytest.raises(MotorlabError, match=r"pip install .*onnx==") as e:
        export_onnx(trained["ppo-history3"], tmp_path / "out")
    assert "\n" not in str(e.value)
    assert not (tmp_path / "out").exists()


# ---- the command line ----------------------------------------------------------------------

def test_cli_export_onnx_writes_the_graph_and_its_sidecar(trained, tmp_path):
    out = tmp_path / "deploy"
    proc = run_cli("export", trained["ppo-history3"], "--onnx", "--out", out)
    assert_ok(proc)
    assert (out / ONNX_FILE).is_file() and (out / SIDECAR).is_file()
    assert "ONNX" in proc.stdout  # the one line it prints (see the top of this file)
    sidecar = json.loads((out / SIDECAR).read_text())
    assert sidecar["history"] == 3 and sidecar["max_abs_error"] <= TOLERANCE
