"""Reports of trained runs: zero-shot success on unseen envs, H.264 videos, and learning
curves of several settings across seeds (mean and t confidence band)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from motorlab.envs import EnvConfig
from motorlab.errors import MotorlabError
from motorlab.evaluation import evaluate
from motorlab.kinds.evaluate import ZEROSHOT
from motorlab.kinds.train import TRAIN
from motorlab.policies import load_run_policy
from motorlab.report.compare import mean_and_band
from motorlab.rl.config import TrainConfig
from tests.helpers import (
    ENV_ID,
    assert_cli_error,
    assert_ok,
    assert_one_line_error,
    assert_png,
    episode_rows,
    read_metrics_rows,
    read_summary,
    run_cli,
    run_here,
    run_kind,
)

UNSEEN = ["myoHandReorientID-v0", "myoHandReorientOOD-v0"]


# ---- zero-shot -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def zeroshot_dir(hand_play_run, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("zeroshot") / "zs"
    # `--envs A B`: B reaches the command as a run folder; it must still count as an env
    proc = run_cli("zeroshot", hand_play_run, "--envs", *UNSEEN, "--episodes", "4", "--out", out)
    assert_ok(proc)
    return out


def test_zeroshot_summary(zeroshot_dir, hand_play_run):
    s = read_summary(zeroshot_dir)
    name = hand_play_run.name
    assert s["runs"] == [name] and s["envs"] == UNSEEN and s["episodes"] == 4
    for env_id in UNSEEN:
        rate = s[f"{name}.{env_id}.success_rate"]
        assert 0.0 <= rate <= 1.0 and rate * 4 == pytest.approx(round(rate * 4))  # k of 4 episodes
        assert np.isfinite(s[f"{name}.{env_id}.return_mean"])
        assert s[f"{name}.{env_id}.numerical_faults"] >= 0
    assert_png(zeroshot_dir / "plots" / "zeroshot.png")


def test_zeroshot_is_evaluation_on_the_new_env(zeroshot_dir, hand_play_run):
    s = read_summary(zeroshot_dir)
    env_id = UNSEEN[0]
    r = evaluate(load_run_policy(hand_play_run), EnvConfig(id=env_id), 4, seed=s["seed"]).summary()
    assert s[f"{hand_play_run.name}.{env_id}.success_rate"] == pytest.approx(r["success_rate"])
    assert s[f"{hand_play_run.name}.{env_id}.return_mean"] == pytest.approx(r["return_mean"])


def test_zeroshot_unknown_env(hand_play_run, tmp_path):
    proc = run_cli("zeroshot", hand_play_run, "--envs", "myoHandReorientXD-v0", "--episodes", "2",
                   "--out", tmp_path / "out")
    assert_one_line_error(proc, "myoHandReorientXD-v0", "did you mean")
    assert not (tmp_path / "out").exists()


def test_zeroshot_needs_episodes(hand_play_run, tmp_path):
    with pytest.raises(MotorlabError, match="--episodes"):
        run_kind(ZEROSHOT, tmp_path / "out", runs=[str(hand_play_run)], envs=UNSEEN[:1], episodes=0)
    assert not (tmp_path / "out").exists()


# ---- video -----------------------------------------------------------------------------

def ffmpeg_info(path: Path) -> str:
    """What ffmpeg says about a media file (its stream description goes to stderr)."""
    import imageio_ffmpeg

    proc = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
                          capture_output=True, text=True)
    return proc.stderr


def test_video_is_h264(hand_play_run, tmp_path):
    import imageio_ffmpeg

    out = tmp_path / "videos"
    proc = run_cli("video", hand_play_run, "--episodes", "1", "--out", out, "--width", "160", "--height", "120")
    assert_ok(proc)
    mp4s = sorted(out.glob("*.mp4"))
    assert [p.name for p in mp4s] == ["episode_0.mp4"]
    info = ffmpeg_info(mp4s[0])
    assert "h264" in info and "160x120" in info, info
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(mp4s[0]))
    index = json.loads((out / "videos.json").read_text())
    assert frames > 1 and index["frames"] == [frames]
    assert seconds > 0 and index["fps"] > 0
    assert [p.name for p in out.glob(".*")] == [".motorlab-run"]  # its marker, and no temp file left behind


def test_video_unknown_camera_lists_the_cameras(hand_play_run, tmp_path):
    out = tmp_path / "videos"
    proc = run_cli("video", hand_play_run, "--episodes", "1", "--camera", "hand_sideways", "--out", out,
                   "--width", "160", "--height", "120")
    assert_cli_error(proc, "hand_sideways", "hand_side_inter", "hand_top")
    assert not out.exists() or not list(out.glob("*.mp4"))


# ---- compare ---------------------------------------------------------------------------

def test_mean_and_band_is_the_t_interval():
    curves = np.array([[1.0, 2.0, 4.0, 0.0], [2.0, 2.0, 5.0, 1.0], [6.0, 2.0, 9.0, 5.0]])
    mean, half = mean_and_band(curves)
    np.testing.assert_allclose(mean, curves.mean(axis=0))
    expected = stats.t.ppf(0.975, 2) * curves.std(axis=0, ddof=1) / np.sqrt(3)
    np.testing.assert_allclose(half, expected)
    assert half[1] == 0.0  # all seeds agree


def test_mean_and_band_with_missing_values_and_one_seed():
    curves = np.array([[1.0, np.nan], [3.0, 2.0], [5.0, 6.0]])
    mean, half = mean_and_band(curves)
    np.testing.assert_allclose(mean, [3.0, 4.0])
    # the second point has only two seeds: t with one degree of freedom
    np.testing.assert_allclose(half, [stats.t.ppf(0.975, 2) * 2.0 / np.sqrt(3),
                                      stats.t.ppf(0.975, 1) * np.std([2.0, 6.0], ddof=1) / np.sqrt(2)])
    mean1, half1 = mean_and_band(curves[:1])
    np.testing.assert_allclose(mean1[:1], [1.0])
    assert np.all(half1 == 0.0)


@pytest.fixture(scope="module")
def pendulum_runs(ppo_run, tmp_path_factory) -> list[Path]:
    """Three tiny PPO runs on InvertedPendulum (seeds 0, 1, 2)."""
    root = tmp_path_factory.mktemp("compare-runs")
    runs = [ppo_run]
    for seed in (1, 2):
        cfg = TrainConfig(env=EnvConfig(id=ENV_ID), algo="ppo", timesteps=256, seed=seed, progress=False,
                          solve_episodes=2, hyperparams={"n_steps": 128, "batch_size": 64})
        TRAIN.perform(cfg, root / f"ppo{seed}")
        runs.append(root / f"ppo{seed}")
    return runs


def test_compare_cli(pendulum_runs, tmp_path):
    r0, r1, r2 = pendulum_runs
    out = tmp_path / "cmp"
    proc = run_cli("compare", "--group", f"A={r0},{r1}", "--group", f"B={r2}", "--title", "tiny", "--out", out)
    assert_ok(proc)
    assert_png(out / "plots" / "learning_curves.png")
    s = read_summary(out)
    assert s["A.seeds"] == 2 and s["B.seeds"] == 1
    curves = ("seeds", "final_episode_return")  # no training success: the pendulum has no success flag
    # 2 and 1 seeds: each group's mean, no IQM (it would trim nothing) and no interval (too few seeds)
    stats = [f"{m}_mean" for m in ("final_return", "success_rate")]
    assert set(s) == ({f"{g}.{k}" for g in "AB" for k in (*curves, *stats)}
                      | {"A.final_return_p_better_than[B]", "A.success_rate_p_better_than[B]"})
    a = [read_summary(r)["eval_return_mean"] for r in (r0, r1)]
    assert s["A.final_return_mean"] == pytest.approx(np.mean(a))
    b = read_summary(r2)["eval_return_mean"]
    assert s["A.final_return_p_better_than[B]"] == pytest.approx(np.mean([(x > b) + 0.5 * (x == b) for x in a]))
    # the final value is a running mean of episode returns, so it lies within them
    returns = [float(r["episode_return"]) for r in episode_rows(read_metrics_rows(r2)[1])]
    assert min(returns) <= s["B.final_episode_return"] <= max(returns)


def _fake_run(folder: Path, summary: dict, csv_name: str, header: str, rows: list[str]) -> Path:
    """A finished run folder by hand: its summary.json and one CSV."""
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps(summary))
    (folder / csv_name).write_text("\n".join([header, *rows]) + "\n")
    return folder


@pytest.fixture
def eval_runs(tmp_path) -> dict[str, Path]:
    """A hand-made mbrl loop (curve.csv: evaluations 1, 3, 5 at 200, 400, 600 env steps, model/ inside) and a
    train run (metrics.csv: training episodes, evaluations 2 and 4 at 300 and 900 steps), and a train run
    that never evaluated."""
    loop = _fake_run(tmp_path / "loop", {"final_return_mean": 5.0}, "curve.csv",
                     "round,env_steps,episodes,eval_return_mean,eval_return_min",
                     ["1,200,1,1.0,0.5", "2,400,2,3.0,2.0", "3,600,3,5.0,4.0"])
    (loop / "model").mkdir()
    (loop / "model" / "model.json").write_text("{}")
    train = _fake_run(tmp_path / "sac", {"eval_return_mean": 4.0, "eval_success_rate": 0.0}, "metrics.csv",
                      "timesteps,episode_return,eval_return_mean,eval_return_min",
                      ["200,-1.0,,", "300,,2.0,1.5", "400,0.5,,", "900,,4.0,3.0"])
    silent = _fake_run(tmp_path / "silent", {"eval_return_mean": 1.0}, "metrics.csv",
                       "timesteps,episode_return,eval_return_mean,eval_return_min", ["200,-1.0,,", "400,0.5,,"])
    return {"loop": loop, "train": train, "silent": silent, "empty": _fake_run(tmp_path / "empty", {}, "x.csv", "a", [])}


def test_evaluation_curves_hold_each_runs_last_evaluation(eval_runs):
    from motorlab.report.compare import evaluations, held

    steps, values = evaluations(eval_runs["train"])  # the rows with an evaluation, against timesteps
    np.testing.assert_array_equal(steps, [300, 900])
    np.testing.assert_array_equal(values, [2.0, 4.0])
    steps, values = evaluations(eval_runs["loop"] / "model")  # a recipe's "@loop": the loop's curve.csv
    np.testing.assert_array_equal(steps, [200, 400, 600])
    grid = np.array([0, 199, 200, 399, 400, 600, 601, 900])
    np.testing.assert_array_equal(held(steps, values, grid), [np.nan, np.nan, 1, 1, 3, 5, np.nan, np.nan])


def test_compare_evaluation_curves_of_mixed_folders(eval_runs, tmp_path):
    loop, train = eval_runs["loop"], eval_runs["train"]
    out = tmp_path / "cmp"
    proc = run_here("compare", "--curve", "evaluation", "--group", f"PETS={loop / 'model'}", "--group",
                    f"SAC={train}", "--group", f"both={loop},{train}", "--out", out)
    assert_ok(proc)
    assert_png(out / "plots" / "learning_curves.png")
    s = read_summary(out)
    assert s["PETS.final_eval_return_mean"] == 5.0  # its last evaluation, at 600 steps
    assert s["SAC.final_eval_return_mean"] == 4.0
    assert s["both.seeds"] == 2 and s["both.final_eval_return_mean"] == 4.0  # past 600 only the train run is left
    assert s["PETS.final_return_mean"] == 5.0  # the loop's final return is its score
    assert s["PETS.final_return_p_better_than[SAC]"] == 1.0
    assert "final_episode_return" not in " ".join(s)


def test_compare_evaluation_curves_band_over_seeds(eval_runs, tmp_path):
    from motorlab.report.compare import compare_curves

    result = compare_curves({"two": [eval_runs["train"], eval_runs["train"]]}, tmp_path / "c.png", curve="evaluation")
    assert result == {"two": {"seeds": 2, "final_eval_return_mean": 4.0}}
    assert_png(tmp_path / "c.png")


@pytest.mark.parametrize("folder, curve, fragments", [
    ("loop", "training", ["model-based loop (mbrl)", "no training episodes", "--curve evaluation"]),
    ("silent", "evaluation", ["metrics.csv holds no evaluation", "--eval-every N", "--curve training"]),
    ("empty", "evaluation", ["neither metrics.csv (a train run) nor curve.csv (an mbrl run)"]),
])
def test_compare_wrong_folder_is_one_line(eval_runs, tmp_path, folder, curve, fragments):
    out = tmp_path / "cmp"
    proc = run_here("compare", "--curve", curve, "--group", f"A={eval_runs[folder]}", "--out", out)
    assert_one_line_error(proc, str(eval_runs[folder]), *fragments)
    assert not out.exists()  # refused before the run folder is made


@pytest.mark.parametrize("group", ["A", "A=", "=runs/x"])
def test_compare_bad_group_syntax(group, tmp_path):
    proc = run_here("compare", "--group", group, "--out", tmp_path / "cmp")
    assert_one_line_error(proc, "--group", "LABEL=RUN_DIR")
    assert not (tmp_path / "cmp").exists()
