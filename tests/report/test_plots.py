"""`motorlab plot` and the figure helpers write real PNG figures."""

from __future__ import annotations

import shutil

import matplotlib.image
import numpy as np
import pytest

from motorlab.envs import EnvConfig
from motorlab.kinds.evaluate import EVALUATE
from motorlab.media.figures import plot_run
from motorlab.report.plots import comparison_bars, obs_labels, observation_trace
from tests.helpers import ENV_ID, assert_ok, assert_png, run_cli, run_kind

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_plot_cli_on_training_run(ppo_run, tmp_path):
    run = tmp_path / "ppo"
    shutil.copytree(ppo_run, run)
    proc = run_cli("plot", run)
    assert_ok(proc)
    for name in ("learning_curve.png", "observation_trace.png"):
        assert_png(run / "plots" / name)
        assert name in proc.stdout  # the written files are listed


def test_plot_run_on_lqr_run(fast_run, tmp_path):
    run = tmp_path / "fast"
    shutil.copytree(fast_run, run)
    written = plot_run(run)
    assert sorted(p.name for p in written) == ["learning_curve.png", "observation_trace.png"]
    for path in written:
        assert path.parent == run / "plots"
        assert_png(path)


def test_plot_run_is_reproducible(fast_run, tmp_path):
    run = tmp_path / "fast"
    shutil.copytree(fast_run, run)
    first = matplotlib.image.imread(plot_run(run)[-1])
    second = matplotlib.image.imread(plot_run(run)[-1])
    np.testing.assert_array_equal(first, second)  # a fixed trace episode: the same figure


def test_plot_run_on_evaluation_run_has_no_learning_curve(tmp_path):
    run = tmp_path / "eval-pid"
    run_kind(EVALUATE, run, policy="pid", env=EnvConfig(id=ENV_ID), episodes=1, seed=0)
    written = plot_run(run)
    assert [p.name for p in written] == ["observation_trace.png"]
    assert not (run / "plots" / "learning_curve.png").exists()
    assert_png(written[0])


def test_plot_run_with_history_and_delay(tmp_path):
    # PID gains on the newest frame of a 2-frame history; the trace shows that frame.
    spec = "pid:kp=[0,0,0,0,1,20,0,0],ki=0,kd=[0,0,0,0,1,3,0,0]"
    run = tmp_path / "eval-history"
    summary = run_kind(EVALUATE, run, policy=spec, env=EnvConfig(id=ENV_ID, history=2, delay=0.2), episodes=1, seed=0)
    assert summary["history"] == 2
    (trace,) = plot_run(run)
    assert_png(trace)


def test_observation_trace_figure(tmp_path):
    t = np.linspace(0, 1, 26)
    obs = np.stack([np.sin(t), np.cos(t), t, -t], axis=1)
    actions = np.sin(3 * t[1:])[:, None]
    path = observation_trace(obs, actions, 0.04, obs_labels(ENV_ID, 4), tmp_path / "sub" / "trace.png", "trace")
    assert path == tmp_path / "sub" / "trace.png"
    assert_png(path)
    image = matplotlib.image.imread(path)
    assert image.shape[0] > image.shape[1]  # one stacked panel per observation element plus the action


def test_obs_labels():
    assert obs_labels("InvertedPendulum-v5", 4)[1] == "pole angle (rad)"
    assert obs_labels("InvertedPendulum-v5", 8) == [f"obs[{i}]" for i in range(8)]  # unknown layout
    assert obs_labels("Reacher-v5", 2) == ["obs[0]", "obs[1]"]


def test_comparison_bars_mark_missing_values(tmp_path):
    path = comparison_bars(["pid", "ppo", "fast"], [1000.0, None, 100.0], "steps", tmp_path / "bars.png", "bars",
                           "Steps of each step.")
    assert_png(path)


def test_step_tick_labels_read_at_a_glance():
    from motorlab.report.plots import step_count
    assert [step_count(x) for x in (0, 500, 250_000, 1_000_000, 1_500_000)] == ["0", "500", "250k", "1M", "1.5M"]


def test_comparison_bars_without_any_value_draw_nothing_and_negatives_show(tmp_path):
    from unittest import mock

    import motorlab.report.plots as plots
    seen = {}
    real_save = plots.save_figure

    def spy(fig, path, caption):
        seen["ylim"] = fig.axes[0].get_ylim()
        return real_save(fig, path, caption)

    with mock.patch("motorlab.report.plots.save_figure", spy):
        assert comparison_bars(["ppo"], [None], "environment steps", tmp_path / "sts.png", "t", "c", steps=True) is None
        assert "ylim" not in seen and not (tmp_path / "sts.png").exists()  # no chart of nothing
        comparison_bars(["a", "b"], [-5.0, None], "return", tmp_path / "r.png", "t", "c")
        assert seen["ylim"][0] <= -5.0  # a negative return still shows
    assert_png(tmp_path / "r.png")
