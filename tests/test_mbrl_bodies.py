"""benchmarks/mbrl_bodies.py: its scores, its judging, its settings (motorlab's defaults, no catalogue entry,
nothing per body), and one body end to end on tiny budgets, recorded in a development log and read back."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import mbrl_bodies as mb  # noqa: E402  (benchmarks/ is a folder of scripts, not a package)
from provenance import settings_hash  # noqa: E402

TINY = mb.Budgets(eval_episodes=1, collect_episodes=4, fit_epochs=1, loop_env_steps=100,
                  oracle=(("horizon", 3), ("population", 8), ("iterations", 1), ("elites", 2)))


def test_seeds_parse_and_odd_bodies_are_muscle_arms():
    assert mb.parse_seeds("100-103,0,2-2") == [0, 2, 100, 101, 102, 103]
    assert mb.body_env(100) == "bodies:GeneratedArm-s100-v0" and mb.body_env(101) == "bodies:GeneratedMuscleArm-s101-v0"
    assert sum(mb.muscles_of(s) for s in mb.HEADLINE_BODIES) == 5


def test_every_method_meets_the_loops_evaluation_episodes_fresh_for_each_body():
    from motorlab.planning import mbrl

    assert (mbrl.SEED_STRIDE, mbrl.EVAL_OFFSET) == (mb.SEED_STRIDE, mb.EVAL_OFFSET)
    fields = mb.step_fields(7, mb.FULL)
    resets = mb.eval_resets(7, 10)
    assert resets == [7_900_000 + j for j in range(10)]
    for name in ("mpc_user", "mpc_learned"):  # mpc resets episode i with seed + i
        assert fields[name]["seed"] == resets[0] and fields[name]["episodes"] == 10
    assert fields["mbrl"]["seed"] == 7 and fields["mbrl"]["eval_episodes"] == 10
    headline = {r for s in mb.HEADLINE_BODIES for r in mb.eval_resets(s, 10)}
    development = {r for s in range(100) for r in mb.eval_resets(s, 10)}
    assert not headline & development


def test_bodies_get_motorlabs_defaults_and_nothing_of_their_own():
    from motorlab.envs import facts
    from motorlab.envs.catalog import DEFAULT

    for seed in (0, 1, 100, 101):
        known = facts(mb.body_env(seed))  # no catalogue entry for a generated body: the defaults' facts
        assert known == DEFAULT
    a, b = mb.step_fields(0, mb.FULL), mb.step_fields(2, mb.FULL)  # two motor arms: only env and seeds differ
    for name in a:
        differ = {k for k in a[name] if a[name][k] != b[name][k]}
        assert differ <= {"env", "seed"}, (name, differ)
    from motorlab.kinds.planning import MbrlSettings

    resolved = {s: mb.resolved_settings(s, mb.FULL) for s in (0, 1, 2, 105)}
    common = mb.common_settings(list(resolved), resolved)  # motor and muscle arms alike, once the body is named
    assert mb.BODY_ENV == common["mbrl"]["env"]["id"] == common["collect"]["env"]["id"]
    assert common["oracle"]["reset_seeds"] == mb.BODY_RESETS and common["mpc_user"]["seed"] == mb.BODY_FIRST_RESET
    settings = resolved[0]
    for key in ("horizon", "population", "iterations", "ensemble", "probabilistic", "propagation", "hidden"):
        assert settings["mbrl"][key] == MbrlSettings.model_fields[key].get_default(call_default_factory=True), key
    assert settings["mbrl"]["max_env_steps"] == 3000 and settings["collect"]["episodes"] == 400
    assert settings["fit"]["learn_reward"] is True
    # a body that motorlab gave settings of its own (as a catalogue entry would) is refused
    resolved[2] = {**resolved[2], "mbrl": {**resolved[2]["mbrl"], "horizon": 25}}
    with pytest.raises(SystemExit, match="body 2 resolves other settings than body 0 \\(mbrl\\)"):
        mb.common_settings(list(resolved), resolved)


def _result(seed: int, random: float, oracle: float, **methods: float) -> dict:
    means = {"random": random, "oracle": oracle, **methods}
    return {"seed": seed, "gap_closed": mb.gap_shares(means)}


def test_the_share_of_the_gap_and_k_of_n_meeting_each_target():
    shares = mb.gap_shares({"random": -80.0, "oracle": -10.0, "loop": -24.0, "mpc_user": -80.0, "mpc_learned": -5.0})
    assert shares == pytest.approx({"loop": 0.8, "mpc_user": 0.0, "mpc_learned": 75 / 70})
    assert mb.gap_shares({"random": -10.0, "oracle": -10.0, "loop": 0.0, "mpc_user": 0.0, "mpc_learned": 0.0}) == {
        "loop": None, "mpc_user": None, "mpc_learned": None}  # no gap: no share
    # 8 of 10 headline bodies close >= 70% with the loop: met; 7: not; on other counts: not judged
    good = [_result(100 + i, -80, -10, loop=-24, mpc_user=-50, mpc_learned=-50) for i in range(8)]
    bad = [_result(108 + i, -80, -10, loop=-80, mpc_user=-80, mpc_learned=-80) for i in range(2)]
    judged = mb.judge(good + bad, headline=True)
    assert judged["loop"]["k"] == 8 and judged["loop"]["met"] is True and judged["loop"]["of"] == 10
    assert judged["mpc_user"]["k"] == 0 and judged["mpc_user"]["met"] is False  # 30/70 < 0.6
    assert judged["mpc_learned"]["k"] == 0 and judged["mpc_learned"]["median"] == pytest.approx(30 / 70)
    assert mb.judge(good[:7] + bad + [bad[0]], headline=True)["loop"]["met"] is False
    assert mb.judge(good, headline=False)["loop"]["met"] is None and mb.judge(good[:5], headline=True)["loop"]["met"] is None
    low, high = judged["loop"]["k_of_n_wilson_95"]
    assert 0.4 < low < 0.8 < high < 1.0


def test_the_command_line_refuses_what_it_cannot_do(capsys):
    for argv in (["--only", "0", "--bodies", "0,1"], ["--resume"], ["--bodies", "0", "--only", "1", "--keep", "x"]):
        with pytest.raises(SystemExit):
            mb.parse(argv)
    with pytest.raises(SystemExit, match="smoke run"):
        mb.main(["--bodies", "100", "--quick"])
    with pytest.raises(SystemExit, match="mix"):
        mb.main(["--bodies", "99,100", "--quick"])


def test_one_body_end_to_end_split_over_two_invocations_into_a_development_log(tmp_path, monkeypatch, capsys):
    from provenance import Harness

    monkeypatch.setattr(mb, "QUICK", TINY)
    monkeypatch.setattr(mb, "Harness", lambda name: Harness(name, results=tmp_path / "results",
                                                            devlog=tmp_path / "devlog"))
    keep, log = tmp_path / "keep", tmp_path / "devlog" / "mbrl_bodies-quick.jsonl"
    # 1. body 0 of bodies 0 and 2 now: nothing recorded while body 2 is left
    mb.main(["--bodies", "0,2", "--only", "0", "--quick", "--jobs", "1", "--keep", str(keep)])
    partial = json.loads(capsys.readouterr().out)
    assert partial["finished"] == [0] and partial["left"] == [2] and not log.exists()
    assert (keep / "body-s0" / mb.BODY_RESULT).is_file() and (keep / "body-s0" / "mbrl" / "curve.csv").is_file()
    # 2. body 0 read back (not run again) and recorded: one devlog line, never a result file
    mb.main(["--bodies", "0", "--quick", "--keep", str(keep), "--resume"])
    line = json.loads(capsys.readouterr().out)
    assert not (tmp_path / "results").exists()
    assert [json.loads(x) for x in log.read_text().splitlines()] == [line] and line["seeds"] == [0]
    assert line["result"]["read_back"] == [0]
    body = line["result"]["per_body"][0]
    means = body["return_mean"]
    assert set(means) == {"random", "oracle", "mpc_user", "mpc_learned", "loop"}
    assert body["gap_closed"] == pytest.approx(mb.gap_shares(means))
    assert len(body["returns"]["oracle"]) == 1 and body["eval_reset_seeds"] == [900_000]
    assert body["loop"]["env_steps"] >= 100 and body["return_mean"]["loop"] == body["loop"]["curve"][-1]["return_mean"]
    # the settings name no body: a run on other bodies with the same settings is the same configuration
    assert line["settings_hash"] == settings_hash(mb.run_settings(
        mb.common_settings([1, 2], {s: mb.resolved_settings(s, TINY) for s in (1, 2)}), TINY))
    with pytest.raises(SystemExit, match="exists"):  # a kept body is never overwritten without --resume
        mb.main(["--bodies", "0", "--quick", "--keep", str(keep)])
    other = mb.resolved_settings(0, replace(TINY, collect_episodes=5))
    with pytest.raises(SystemExit, match="other settings"):
        mb.read_back(0, keep / "body-s0", other, headline=False)


def test_development_settings_are_tried_on_development_bodies_only(capsys):
    args = mb.parse(["--bodies", "2", "--set", "fit.hidden=[200,200]", "--set", "collect.noise_beta=1", "--no-loop"])
    budgets = replace(mb.FULL, overrides=args.overrides, loop=False)
    fields = mb.step_fields(2, budgets)
    assert fields["fit"]["hidden"] == [200, 200] and fields["collect"]["noise_beta"] == "1"
    assert "mbrl" not in fields  # --no-loop: the one-shot path alone
    tried = mb.resolved_settings(2, budgets)
    assert tried["fit"]["hidden"] == [200, 200] and tried["collect"]["noise_beta"] == 1.0  # as motorlab reads them
    assert settings_hash(mb.body_free(2, tried)) != settings_hash(mb.body_free(2, mb.resolved_settings(2, mb.FULL)))
    with pytest.raises(SystemExit):
        mb.parse(["--set", "fit.hidden"])  # no value
    for given in (["--set", "fit.epochs=100"], ["--no-loop"], ["--baselines-from", "/tmp"]):
        with pytest.raises(SystemExit, match="headline runs motorlab's defaults"):
            mb.main(["--bodies", "100", *given])  # a headline: the defaults, every method, from scratch


def test_a_headline_on_other_bodies_is_recorded_beside_the_first_not_over_it():
    import mbrl_bodies

    assert mbrl_bodies.result_file(list(range(100, 110))) == "mbrl_bodies"
    assert mbrl_bodies.result_file(list(range(110, 120))) == "mbrl_bodies-110-119"
