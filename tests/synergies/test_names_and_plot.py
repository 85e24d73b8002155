"""Muscle names come through from the body's MuJoCo model (a MyoSuite hand, a user's own arm) into the
activations, the synergy file and the heatmap; `synergies plot` draws any SAR, naming a published one
from its env."""

from __future__ import annotations

import numpy as np
import pytest

from motorlab.envs import EnvConfig, make_env
from motorlab.synergy_runs.activations import load_activations, resolve_signal, signal_bounds, signal_names
from tests.helpers import HAND_ID, assert_ok, assert_one_line_error, run_cli


def model_names(env_id: str) -> tuple[list[str], list[str]]:
    """(names signal_names gives for the env's auto signal, the model's own actuator names)."""
    env = make_env(EnvConfig(id=env_id))
    try:
        signal = resolve_signal(env, "auto")
        model = env.unwrapped.mj_model if hasattr(env.unwrapped, "mj_model") else env.unwrapped.model
        return signal_names(env, signal, len(signal_bounds(env, signal)[0])), [model.actuator(i).name
                                                                              for i in range(model.nu)]
    finally:
        env.close()


def test_a_myosuite_hand_names_its_39_muscles_as_its_model_does():
    names, actuators = model_names(HAND_ID)
    assert len(names) == 39 and names == actuators and len(set(names)) == 39
    assert all(n and not n.startswith("act") for n in names)


def test_a_users_own_arm_names_its_motors_and_an_unnamed_one_by_index():
    names, actuators = model_names("tests.userpkg.arm:ArmReach-v0")
    assert names == ["shoulder_motor", "elbow_motor", "actuator2"] and actuators[:2] == names[:2]


def test_collected_activations_and_the_fit_carry_the_names(hand_activations, tmp_path):
    from motorlab.synergies.sar import load_sar

    _, meta = load_activations(hand_activations)
    names, _ = model_names(HAND_ID)
    assert meta["names"] == names
    assert_ok(run_cli("synergies", "fit", hand_activations, "--n", "4", "--out", tmp_path / "fit"))
    assert load_sar(tmp_path / "fit" / "sar.npz").metadata["names"] == names
    assert (tmp_path / "fit" / "heatmap.png").is_file()


def test_an_older_activations_file_gets_generic_distinct_names(tmp_path):
    from motorlab.runs import atomic_write_npz

    path = tmp_path / "old.npz"
    atomic_write_npz(path, activations=np.random.default_rng(0).uniform(size=(20, 3)))  # no names, no episodes
    acts, meta = load_activations(path)
    assert meta["names"] == ["act0", "act1", "act2"] and meta["episode"].tolist() == [0] * 20


def test_plot_draws_a_published_sar_named_from_its_env(hand_sar, hand_activations, tmp_path):
    proc = run_cli("synergies", "plot", hand_sar, "--out", tmp_path / "no-names")
    assert_one_line_error(proc, "saved without muscle names", "--names-from")
    out = tmp_path / "figures"
    assert_ok(run_cli("synergies", "plot", hand_sar, "--names-from", HAND_ID, "--activations", hand_activations,
                      "--out", out))
    assert (out / "heatmap.png").is_file() and (out / "coefficients.png").is_file()


@pytest.mark.parametrize("folds", [None, 2])
def test_plot_draws_a_vaf_runs_band(hand_activations, tmp_path, folds):
    vaf = tmp_path / "vaf"
    assert_ok(run_cli("synergies", "vaf", hand_activations, "--max-n", "6", *(["--cv", str(folds)] if folds else []),
                      "--out", vaf))
    assert_ok(run_cli("synergies", "fit", hand_activations, "--n", "4", "--out", tmp_path / "fit"))
    assert_ok(run_cli("synergies", "plot", tmp_path / "fit", "--vaf", vaf, "--out", tmp_path / "figs"))
    assert {p.name for p in (tmp_path / "figs").iterdir()} == {"heatmap.png", "coefficients.png", "vaf.png"}


def test_the_report_shows_the_named_heatmap_in_chromium(hand_activations, tmp_path):
    """A fit's report, opened in headless Chromium: the heatmap decodes, and its caption names each synergy's
    strongest muscle by the hand model's own names."""
    from tests.report.test_html import CHROMIUM, Opened, check_captions

    names, _ = model_names(HAND_ID)
    fit = tmp_path / "fit"
    assert_ok(run_cli("synergies", "fit", hand_activations, "--n", "4", "--out", fit))
    assert_ok(run_cli("report", fit, "--out", tmp_path / "report.html"))
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
        opened = Opened(browser, tmp_path / "report.html")
        figures = opened.page.eval_on_selector_all(
            "figure", "fs => fs.map(f => [f.querySelector('img').title, f.querySelector('img').naturalWidth, "
                      "(f.querySelector('figcaption') || {}).textContent || ''])")
        check_captions(opened.page)
        browser.close()
    assert opened.errors == []
    heat = [(w, caption) for title, w, caption in figures if "heatmap" in title]
    assert len(heat) == 1 and heat[0][0] > 0
    strongest = [part.split(" ", 1)[1].rstrip(".") for part in heat[0][1].split("strongest: ")[1].split("; ")]
    assert len(strongest) == 4 and all(name in names for name in strongest)
