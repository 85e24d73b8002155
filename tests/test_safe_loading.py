"""Safe loading: nothing in a run folder is unpickled unless the user passes --trust;
`motorlab export` writes pickle-free policy folders from runs and from SB3 zips."""

from __future__ import annotations

import os
import pickle
import shutil
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli, run_here


def exploit(marker: Path) -> bytes:
    """A pickle that creates `marker` when unpickled (what a malicious file could do)."""

    class Exploit:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    return pickle.dumps(Exploit())


def test_run_folder_commands_never_unpickle_and_export_holds_no_pickle(ppo_run, tmp_path):
    """model.zip swapped for a pickle that runs code: evaluate, plot, report, export and an evaluation
    of the exported folder all work, and the pickle never runs. The exported folder holds no pickle
    and evaluates as the run does."""
    run = tmp_path / "run"
    shutil.copytree(ppo_run, run)
    marker = tmp_path / "pwned"
    (run / "model.zip").write_bytes(exploit(marker))
    (run / "vec_normalize.pkl").write_bytes(exploit(marker))
    assert_ok(run_cli("evaluate", run, "--episodes", "3", "--seed", "5", "--out", tmp_path / "eval"))
    assert_ok(run_cli("plot", run))
    assert_ok(run_cli("report", run, "--out", tmp_path / "report.html"))
    shared = tmp_path / "shared"
    assert_ok(run_cli("export", run, "--out", shared))
    assert_ok(run_cli("evaluate", shared, "--episodes", "3", "--seed", "5", "--out", tmp_path / "eval2"))
    assert not marker.exists()

    names = {p.relative_to(shared).as_posix() for p in shared.rglob("*") if p.is_file()}
    assert {"policy.json", "policy.safetensors", "config.toml", "summary.json", "metrics.csv"} <= names
    assert not any(n.endswith((".zip", ".pkl", ".pt", ".pth")) or n.startswith(("checkpoint", "tensorboard"))
                   for n in names), names
    assert (run / "plots").is_dir() and any(n.startswith("plots/") for n in names)
    assert read_summary(shared)["exported_from"] == str(run.resolve())
    a, b = read_summary(tmp_path / "eval"), read_summary(tmp_path / "eval2")
    assert a["episode_lengths"] == b["episode_lengths"] and a["return_mean"] == b["return_mean"]


@pytest.fixture(scope="module")
def notebook_sac(tmp_path_factory):
    """What a notebook leaves: SB3 SAC trained on normalized observations, saved with
    model.save and VecNormalize.save (both pickles)."""
    from stable_baselines3 import SAC
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    folder = tmp_path_factory.mktemp("notebook")
    venv = VecNormalize(make_vec_env("Pendulum-v1", n_envs=1, seed=0), norm_reward=False)
    model = SAC("MlpPolicy", venv, learning_starts=50, buffer_size=1000, seed=0,
                policy_kwargs={"net_arch": [32, 32]})
    model.learn(300)
    model.save(folder / "sac.zip")
    venv.save(folder / "vec_normalize.pkl")
    return folder, model, venv


def test_sb3_zip_export_acts_like_the_sb3_model(notebook_sac, tmp_path):
    """The exported policy gives SB3's own deterministic actions on SB3-normalized observations."""
    from motorlab.policies import load_run_policy

    folder, model, venv = notebook_sac
    out = tmp_path / "imported"
    assert_ok(run_cli("export", folder / "sac.zip", "--vecnormalize", folder / "vec_normalize.pkl", "--trust",
                      "--env", "Pendulum-v1", "--out", out))
    s = read_summary(out)
    assert (s["algo"], s["num_timesteps"], s["observation_normalized"]) == ("sac", 300, True)
    policy = load_run_policy(out)
    obs = np.stack([gym.make("Pendulum-v1").observation_space.sample() for _ in range(16)])
    expected, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(policy.act(obs), expected, atol=1e-6)
    # and the CLI evaluates it with no --env: the folder records Pendulum-v1
    assert_ok(run_cli("evaluate", out, "--episodes", "2", "--out", tmp_path / "eval"))
    assert read_summary(tmp_path / "eval")["env_id"] == "Pendulum-v1"


def test_sb3_zip_export_records_its_env_as_an_env_config(notebook_sac, tmp_path):
    """--env and what the policy needs of it (--env-arg, --history, --sar) are recorded as EnvConfig's
    settings in config.toml, which evaluate reads back."""
    import tomllib

    folder, _, _ = notebook_sac
    out = tmp_path / "imported"
    assert_ok(run_here("export", folder / "sac.zip", "--trust", "--env", "Pendulum-v1", "--env-arg", "g=9.81",
                       "--out", out))
    assert tomllib.loads((out / "config.toml").read_text())["env"] == {"id": "Pendulum-v1", "kwargs": {"g": 9.81}}
    assert read_summary(out)["env_id"] == "Pendulum-v1"


def test_sb3_zip_export_refuses_without_trust_and_runs_nothing(notebook_sac, tmp_path):
    """Without --trust: one line explaining why, nothing written, and a booby-trapped zip never runs."""
    folder, _, _ = notebook_sac
    marker = tmp_path / "pwned"
    trapped = tmp_path / "trapped.zip"
    with zipfile.ZipFile(folder / "sac.zip") as src, zipfile.ZipFile(trapped, "w") as dst:
        for item in src.namelist():
            dst.writestr(item, exploit(marker) if item == "policy.pth" else src.read(item))
    for source in (folder / "sac.zip", trapped):
        proc = run_cli("export", source, "--env", "Pendulum-v1", "--out", tmp_path / "out")
        assert_one_line_error(proc, "--trust", "unpickling")
        assert not (tmp_path / "out").exists() and not marker.exists()


@pytest.mark.parametrize("case, fragments", [
    ("missing", ("does not exist",)),
    ("not_a_zip", ("not an SB3 model zip",)),
    ("wrong_env", ("Reacher-v5 has observations of shape", "give the env it was trained on")),
    ("unknown_env", ("NoSuchEnv-v0",)),
    ("bad_vecnormalize", ("holds a", "not SB3's VecNormalize")),
    ("run_with_trust", ("is a run folder",)),
    ("history_without_env", ("--history describes the env", "--env ENV_ID")),
    ("stacked_env", ("Pendulum-v1, history 2 has observations of shape (6,), the policy (3,)", "--history")),
])
def test_export_mistakes_give_one_line(notebook_sac, ppo_run, tmp_path, case, fragments):
    folder, _, _ = notebook_sac
    zip_args = [folder / "sac.zip", "--trust"]
    (tmp_path / "notes.zip").write_text("not a zip")
    (tmp_path / "vn.pkl").write_bytes(pickle.dumps({"mean": 0}))
    args = {
        "missing": [tmp_path / "nope.zip", "--trust"],
        "not_a_zip": [tmp_path / "notes.zip", "--trust"],
        "wrong_env": [*zip_args, "--env", "Reacher-v5"],
        "unknown_env": [*zip_args, "--env", "NoSuchEnv-v0"],
        "bad_vecnormalize": [*zip_args, "--vecnormalize", tmp_path / "vn.pkl"],
        "run_with_trust": [ppo_run, "--trust"],
        "history_without_env": [*zip_args, "--history", "2"],
        "stacked_env": [*zip_args, "--env", "Pendulum-v1", "--history", "2"],
    }[case]
    proc = run_here("export", *args, "--out", tmp_path / "out")
    assert_one_line_error(proc, *fragments)
    assert not (tmp_path / "out").exists()
