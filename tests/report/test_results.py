"""Headline numbers as people read them: labels, units and formats (motorlab.report.results),
each kind's numbers, findings of a study, figure captions, and no empty figure."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pytest

from motorlab.envs import early_end_label
from motorlab.errors import MotorlabError
from motorlab.kinds import KINDS
from motorlab.recipes import parse_recipe
from motorlab.report.plots import comparison_bars, figure_caption, save_figure
from motorlab.report.results import Metric, read_run_results, show
from motorlab.stepkind import SCORED_METRICS, StepKind, scored_numbers

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


@pytest.mark.parametrize("value, form, text", [
    (0.2, "percent", "20%"), (1.0, "percent", "100%"), (0.125, "percent", "12.5%"),
    (12288, "steps", "12,288 steps"), (1_500_000, "steps", "1.5M steps"),
    (3.456, "ms", "3.46 ms"), (42.0, "ms", "42 ms"), (12.34, "s", "12.3 s"),
    (950.04, "return", "950.0"), (1234, "count", "1,234"), (None, "percent", "–"), ("egl", "text", "egl"),
])
def test_values_show_in_their_units(value, form, text):
    assert show(value, form) == text


def test_a_metric_scales_and_adds_its_spread_and_total():
    distance = Metric("d", "final distance", "mm", scale=1000, spread="d_std")
    assert distance.number({"d": 0.0123, "d_std": 0.002}).text == "12.3 ± 2.0 mm"
    falls = Metric("falls", "falls", "count", of="episodes")
    assert falls.number({"falls": 2, "episodes": 10}).text == "2/10"
    assert falls.number({"episodes": 10}) is None  # no value, no number


def test_falls_only_where_the_env_defines_a_fall():
    assert early_end_label("InvertedPendulum-v5") == "falls"
    assert early_end_label("Upkie-PyBullet-Pendulum") == "falls"
    assert early_end_label("myoLegWalk-v0") == "falls"
    assert early_end_label("myoHandReorient100-v0") == "ended early"
    assert early_end_label("Reacher-v5") == "ended early"
    h = {"return_mean": 10.0, "return_std": 1.0, "falls": 3, "episodes": 10}
    hand = {n.key: n for n in scored_numbers(SCORED_METRICS, h, "myoHandReorient100-v0")}
    assert hand["falls"].label == "ended early" and hand["falls"].text == "3/10"
    assert {n.key: n.label for n in scored_numbers(SCORED_METRICS, h, "Hopper-v5")}["falls"] == "falls"


def test_every_kind_names_its_numbers_or_derives_them():
    """A kind either lists metrics or computes its numbers (zero-shot, check, compare, vaf, video)."""
    for kind in KINDS.values():
        overrides = type(kind).numbers is not StepKind.numbers
        assert kind.metrics or overrides, kind.name
        for m in kind.metrics:
            assert m.label and m.key, kind.name


def test_zeroshot_numbers_and_per_seed_values():
    zs = KINDS["zeroshot"]
    summary = zs.summary.model_validate({
        "runs": ["sar-rl/seed0", "sar-rl/seed1"], "envs": ["E-v0"], "episodes": 4, "seed": 0, "numerical_faults": 0,
        "sar-rl/seed0.E-v0.success_rate": 0.5, "sar-rl/seed1.E-v0.success_rate": 0.25,
        "sar-rl/seed0.E-v0.return_mean": 1.0, "sar-rl/seed1.E-v0.return_mean": 2.0})
    h = zs.headline(summary)
    settings = zs.make(runs=["a"], envs=["E-v0"], episodes=4)
    (n,) = zs.numbers(settings, h)
    assert n.label == "sar-rl on E-v0: success" and n.text == "37.5%"  # the mean over its seeds
    assert zs.seed_values([("zeroshot", summary)], "sar-rl.E-v0.success_rate_mean") == [("seed0", 0.5),
                                                                                        ("seed1", 0.25)]


def test_figures_carry_their_caption_and_empty_ones_are_not_written(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 2])
    path = save_figure(fig, tmp_path / "a.png", "A line from (0, 1) to (1, 2).")
    assert figure_caption(path) == "A line from (0, 1) to (1, 2)."
    fig, _ = plt.subplots()
    assert save_figure(fig, tmp_path / "a.png", "nothing") is None and not path.exists()  # an older one removed
    assert comparison_bars(["a", "b"], [None, None], "steps", tmp_path / "b.png", "t", "c") is None
    assert not (tmp_path / "b.png").exists()
    assert comparison_bars(["a", "b"], [None, 5.0], "steps", tmp_path / "b.png", "t", "five") is not None
    assert figure_caption(tmp_path / "b.png") == "five"


def test_recipe_findings_are_checked(tmp_path):
    base = '''name = "x"
[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
env = "InvertedPendulum-v5"
'''
    recipe = parse_recipe(base + '[[findings]]\nstep = "pid"\nkey = "return_mean"\nlabel = "PID return"\n')
    assert [(f.step, f.key, f.label) for f in recipe.findings] == [("pid", "return_mean", "PID return")]
    with pytest.raises(MotorlabError, match="findings\\[0\\]: no step named 'pdi' \\(did you mean pid"):
        parse_recipe(base + '[[findings]]\nstep = "pdi"\nkey = "return_mean"\n')
    with pytest.raises(MotorlabError, match="lable"):
        parse_recipe(base + '[[findings]]\nstep = "pid"\nkey = "return_mean"\nlable = "x"\n')


def test_results_json_of_an_evaluation(tmp_path):
    from tests.helpers import run_kind

    run_kind(KINDS["evaluate"], tmp_path / "eval", policy="pid", env="InvertedPendulum-v5", episodes=2)
    results = read_run_results(tmp_path / "eval")
    assert results.kind == "evaluate"
    shown = {n.key: n for n in results.numbers}
    assert shown["return_mean"].label == "return" and shown["return_mean"].text == "1,000.0 ± 0.0"
    assert shown["success_rate"].text == "100%" and shown["falls"].text == "0/2"
    assert shown["episodes"].setup and not shown["return_mean"].setup
