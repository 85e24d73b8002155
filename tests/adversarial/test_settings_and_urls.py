"""An adversarial user's settings (issue 35): numbers are numbers or the run stops, every key a
search or sweep names is checked before trial 1, and credentials in URLs are never shown.

Each mistake is one line with exit status 2, no traceback, and leaves every earlier file as it was
(helpers.snapshot before and after): a finished study, tune or run folder beside it or under the
same --out. The commands run in this process (helpers.run_here); only trials run processes.
"""

from __future__ import annotations

import base64
import http.server
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, get_args

import pytest
from pydantic import BaseModel, TypeAdapter, ValidationError
from pydantic.errors import PydanticSchemaGenerationError

from motorlab.errors import MotorlabError, mask_url, redact
from motorlab.kinds import KINDS
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, run_here, snapshot

SECRET = "s3cr3t-pw"

# ---- settings: true/false is not a number -------------------------------------------------


def _coerced_paths(model: type[BaseModel], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every field, nested models' too, for which pydantic's lax mode turns true into a number:
    found by asking pydantic itself, not by reading annotations as motorlab.settings does."""
    for name, info in model.model_fields.items():
        try:
            value = TypeAdapter(info.annotation).validate_python(True)
        except (ValidationError, PydanticSchemaGenerationError):
            value = None
        if type(value) in (int, float):
            yield (*prefix, name)
        for member in (*get_args(info.annotation), info.annotation):
            if isinstance(member, type) and issubclass(member, BaseModel):
                yield from _coerced_paths(member, (*prefix, name))


def _nested(path: tuple[str, ...], value: Any) -> dict[str, Any]:
    data: Any = value
    for key in reversed(path):
        data = {key: data}
    return data


CASES = [(kind.name, path) for kind in KINDS.values() for path in _coerced_paths(kind.settings)]


def test_the_search_for_number_fields_finds_them():
    """The sweep below covers counts and amounts of every kind, env settings and LQR's nested ones."""
    paths = {(name, path) for name, path in CASES}
    assert ("evaluate", ("episodes",)) in paths
    assert ("train", ("env", "history")) in paths and ("train", ("env", "delay")) in paths
    assert ("train", ("lqr", "obs_lags")) in paths and ("train", ("solve_return",)) in paths
    assert {name for name, _ in CASES} == set(KINDS) - {"compare"}  # compare: run folders and labels only


@pytest.mark.parametrize("kind, path", CASES, ids=[f"{k}:{'.'.join(p)}" for k, p in CASES])
@pytest.mark.parametrize("flag", [True, False])
def test_no_kind_reads_true_or_false_as_a_number(kind, path, flag):
    data = _nested(path, flag)
    env = KINDS[kind].settings.model_fields.get("env")
    if path[0] == "env" and env is not None and env.is_required():  # kinds that need the id: only it given
        data["env"]["id"] = ENV_ID
    with pytest.raises(ValidationError) as caught:
        KINDS[kind].settings.model_validate(data)
    first = caught.value.errors()[0]
    assert first["type"] == "bool_not_number" and first["loc"] == path and first["input"] is flag
    assert first["msg"] in ("give a whole number, not true/false", "give a number, not true/false")


@pytest.mark.parametrize("kind, fields, line", [
    ("evaluate", {"policy": "pid", "episodes": True}, "--episodes True: give a whole number, not true/false"),
    ("evaluate", {"policy": "pid", "history": False}, "--history False: give a whole number, not true/false"),
    ("evaluate", {"policy": "pid", "delay": True}, "--delay True: give a number, not true/false"),
    ("evaluate", {"policy": "pid", "obs_noise": [0.1, True]}, "--obs-noise: give numbers, not true/false"),
    ("train", {"env": ENV_ID, "lqr": {"obs_lags": True}}, "--obs-lags True: give a whole number, not true/false"),
    ("train", {"env": ENV_ID, "timesteps": True}, "--timesteps True: give a whole number, not true/false"),
])
def test_make_names_the_setting_in_one_line(kind, fields, line):
    with pytest.raises(MotorlabError) as caught:
        KINDS[kind].make(**fields)
    assert str(caught.value) == line


def test_numbers_still_convert_as_before():
    """Only true/false is refused: 1e3 from TOML is 1000 steps, "3" from a command line 3 episodes,
    an int an amount, and switches and free tables (env kwargs, SB3's hyperparameters) take booleans."""
    train = KINDS["train"].make(env=ENV_ID, timesteps=1e3, delay=1, normalize=True, algo="ppo",
                                hyperparams={"normalize_advantage": False}, env_kwargs={"flag": True})
    assert train.timesteps == 1000 and train.env.delay == 1.0 and train.normalize is True
    assert train.hyperparams == {"normalize_advantage": False} and train.env.kwargs == {"flag": True}
    assert KINDS["evaluate"].make(policy="pid", env=ENV_ID, episodes="3").episodes == 3


RECIPE = """name = "one"
description = "one evaluation"

[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
env = "InvertedPendulum-v5"
episodes = 1
"""


@pytest.fixture(scope="module")
def finished_study(tmp_path_factory) -> tuple[Path, Path]:
    """A recipe and the study it ran: the folder a mistake must leave as it is."""
    folder = tmp_path_factory.mktemp("study")
    recipe = folder / "one.toml"
    recipe.write_text(RECIPE)
    assert_ok(run_here("run", recipe, "--out", folder / "study"))
    return recipe, folder / "study"


def test_run_check_refuses_true_for_a_count():
    proc = run_here("run", "pendulum", "--check", "--set", "episodes=true")
    assert_one_line_error(proc, "'episodes'", "give a whole number, not true/false")


def test_run_refuses_true_for_a_count_and_keeps_the_finished_study(finished_study):
    recipe, study = finished_study
    before = snapshot(study.parent)
    proc = run_here("run", recipe, "--set", "episodes=true", "--out", study)
    assert_one_line_error(proc, "'episodes'", "give a whole number, not true/false")
    assert snapshot(study.parent) == before


def test_sweep_grid_of_booleans_for_a_count_is_refused_before_any_trial(finished_study, tmp_path):
    recipe, study = finished_study
    before = snapshot(study.parent)
    proc = run_here("sweep", recipe, "--grid", "episodes=true,false", "--seeds", "1", "--out", tmp_path / "sweep")
    assert_one_line_error(proc, "episodes=true", "give a whole number, not true/false")
    assert not (tmp_path / "sweep").exists()
    assert snapshot(study.parent) == before


# ---- tune and sweep: every key checked before trial 1 ---------------------------------------

QUICK = f"train {ENV_ID} --preset fast --until-solved --timesteps 1500 --solve-episodes 2"  # LQR
PPO = f"train {ENV_ID} --algo ppo --timesteps 256"
# an SQLite URL works with a credential in it (pysqlite ignores the parameter): one that must not be written down
STORE = "study.db?password=" + SECRET


@pytest.fixture(scope="module")
def finished_tune(tmp_path_factory) -> Path:
    """A folder holding a tiny finished search in t/ (one trial, one seed) and its database, whose
    URL carries a credential."""
    folder = tmp_path_factory.mktemp("tune")
    proc = run_here("tune", QUICK, "--space", "delay=uniform:0.05,0.2", "--trials", "1", "--seeds", "1",
                    "--fresh-seeds", "0", "--sampler", "random", "--pruner", "none",
                    "--storage", f"sqlite:///{folder}/{STORE}", "--out", folder / "t")
    assert_ok(proc)
    (folder / "output.txt").write_text(proc.stdout + proc.stderr)  # what the user saw, for the tests below
    return folder


def test_a_finished_search_records_no_credential(finished_tune):
    """Config, summary, table, trials.csv, report and every trial's files: the storage URL masked."""
    out = finished_tune / "t"
    assert (finished_tune / "study.db").is_file() and (out / "trials.csv").is_file()
    assert not [p for p in finished_tune.rglob("*") if p.is_file() and SECRET.encode() in p.read_bytes()
                and p.name != "output.txt"]
    assert "password=***" in (out / "config.toml").read_text()
    assert "password=***" in (out / "summary.json").read_text()


def test_a_finished_search_shows_no_credential(finished_tune):
    """Its output, the line naming the optuna-dashboard command included (motorlab.cli's tune)."""
    output = (finished_tune / "output.txt").read_text()
    assert "optuna-dashboard" in output and "password=***" in output
    assert SECRET not in output


@pytest.mark.parametrize("target, space, fragments", [
    (QUICK, "fooo=uniform:0,1", ["--space fooo", "no option --fooo", "LQR takes no SB3 hyperparameters"]),
    (PPO, "fooo=uniform:0,1", ["--space fooo", "no option --fooo", "unknown hyperparameter 'fooo' for PPO"]),
    (PPO, "n_env=int:1,2", ["--space n_env", "did you mean --n-envs", "unknown hyperparameter 'n_env'"]),
    (PPO, "set.n_stepz=int:64,128", ["--space set.n_stepz", "did you mean n_steps"]),
    (PPO, "set.n_steps=choice:64,many", ["--space set.n_steps", "n_steps='many'", "should be int"]),
    (f"evaluate pid --env {ENV_ID}", "episodez=int:1,2", ["--space episodez", "did you mean --episodes"]),
    (f"evaluate pid --env {ENV_ID}", "set.gamma=uniform:0.9,0.99", ["takes no SB3 hyperparameters"]),
    (f"{PPO} --set n_stepz=64", "lr=loguniform:1e-4,1e-3", ["unknown hyperparameter 'n_stepz'"]),
    ("pendulum", "nosuch=int:1,2", ["--space nosuch", "has a field 'nosuch'"]),
    ("pendulum", "ppo.timesteps=choice:true,false", ["'timesteps'", "give a whole number, not true/false"]),
])
def test_unknown_or_mistyped_space_key_fails_before_the_study_exists(finished_tune, tmp_path, target, space,
                                                                     fragments):
    """Under a finished search's --out and its --storage, and in a new folder: nothing written, every
    file of the finished search as it was, its database included."""
    before = snapshot(finished_tune)
    for out in (finished_tune / "t", tmp_path / "new"):
        proc = run_here("tune", target, "--space", space, "--trials", "3", "--seeds", "1",
                        "--storage", f"sqlite:///{finished_tune}/{STORE}", "--out", out)
        assert_one_line_error(proc, *fragments)
    assert not (tmp_path / "new").exists()
    assert snapshot(finished_tune) == before


def test_valid_hyperparameter_keys_pass_the_check():
    """`set.KEY`, and a KEY that is no option, reach PPO as hyperparameters: the check lets them through."""
    from motorlab.sweeps.targets import read_target
    from motorlab.tuning.space import parse_space
    from motorlab.tuning.trials import Planner

    space = parse_space(["set.n_steps=int:64,128", "gamma=uniform:0.9,0.99", "lr=loguniform:1e-4,1e-3"])
    planner = Planner(read_target(PPO, "tune"), space, {})
    planner.check()
    assert [planner.passes_on(d) for d in space.values()] == [True, True, False]


def test_sweep_with_a_misspelt_hyperparameter_fails_before_any_trial(finished_tune, tmp_path):
    before = snapshot(finished_tune)
    proc = run_here("sweep", f"{PPO} --set n_stepz=64", "--seeds", "2", "--out", tmp_path / "sweep")
    assert_one_line_error(proc, "unknown hyperparameter 'n_stepz' for PPO", "did you mean n_steps")
    proc = run_here("sweep", PPO, "--grid", "n_stepz=64,128", "--seeds", "2", "--out", tmp_path / "sweep")
    assert_one_line_error(proc, "--grid n_stepz", "has no option --n-stepz")
    assert not (tmp_path / "sweep").exists()
    assert snapshot(finished_tune) == before


# ---- credentials in URLs ----------------------------------------------------------------------

@pytest.mark.parametrize("url, shown", [
    ("postgresql://user:secret@localhost:5432/db", "postgresql://user:***@localhost:5432/db"),
    ("mysql+pymysql://user:p%40ss@host/db?charset=utf8", "mysql+pymysql://user:***@host/db?charset=utf8"),
    ("postgresql://user:with@sign@host/db", "postgresql://user:***@host/db"),
    ("http://user:pw@mlflow.example:5000/x@y?token=abc&run=1", "http://user:***@mlflow.example:5000/x@y?token=***&run=1"),
    ("ray://admin:pw@10.0.0.5:10001", "ray://admin:***@10.0.0.5:10001"),
    ("sqlite:////tmp/study.db", "sqlite:////tmp/study.db"),  # no credential: exactly as written
    ("sqlite:///runs/tune/study.db?timeout=5", "sqlite:///runs/tune/study.db?timeout=5"),
    ("postgresql://user@host/db", "postgresql://user@host/db"),
    ("10.0.0.5:6379", "10.0.0.5:6379"),
])
def test_mask_url(url, shown):
    assert mask_url(url) == shown


def test_redact_masks_a_credential_quoted_anywhere_in_a_message():
    url = "postgresql://user:p%40ss-word@host/db"
    text = redact(f"cannot connect to {url}: password p@ss-word was refused (p%40ss-word)", url)
    assert "p@ss" not in text and "p%40ss" not in text and "user:***@host" in text


@pytest.mark.parametrize("storage, fragments", [
    (f"postgresql://user:{SECRET}@localhost:1/db", ["--storage postgresql://user:***@localhost:1/db"]),  # no driver
    (f"sqlite://user:{SECRET}@/no/such/dir/x.db", ["storage sqlite://user:***@/no/such/dir/x.db"]),  # refused
])
def test_storage_credentials_are_masked_in_the_error_and_files(tmp_path, storage, fragments):
    out = tmp_path / "t"
    proc = run_here("tune", QUICK, "--space", "delay=uniform:0.05,0.2", "--trials", "1", "--seeds", "1",
                    "--storage", storage, "--out", out)
    assert_one_line_error(proc, *fragments)
    assert SECRET not in proc.stdout + proc.stderr
    assert not [p for p in tmp_path.rglob("*") if p.is_file() and SECRET.encode() in p.read_bytes()]


def test_ray_address_credentials_are_masked(tmp_path):
    proc = run_here("sweep", QUICK, "--seeds", "1", "--backend", "ray", "--address",
                    f"ray://admin:{SECRET}@127.0.0.1:1", "--out", tmp_path / "s")
    assert_one_line_error(proc, "ray://admin:***@127.0.0.1:1")
    assert SECRET not in proc.stdout + proc.stderr
    assert not (tmp_path / "s").exists()


LQR = ["--preset", "fast", "--timesteps", "200", "--no-progress"]  # a second of training


def test_unreachable_mlflow_server_is_masked(tmp_path):
    proc = run_here("train", ENV_ID, *LQR, "--track", f"mlflow=http://user:{SECRET}@127.0.0.1:1", "--out", tmp_path / "e")
    assert_one_line_error(proc, "mlflow=http://user:***@127.0.0.1:1", "no MLflow tracking server answers")
    assert SECRET not in proc.stdout + proc.stderr
    assert not (tmp_path / "e").exists()


class _HealthOnly(http.server.BaseHTTPRequestHandler):
    """A server that answers /health and nothing else (no MLflow API): remembers the credentials."""

    seen: list[str | None] = []

    def do_GET(self):  # noqa: N802 - http.server's name
        _HealthOnly.seen.append(self.headers.get("Authorization"))
        self.send_response(200 if self.path.startswith("/health") else 404)
        self.end_headers()

    do_POST = do_GET  # noqa: N815

    def log_message(self, *args):
        pass


@pytest.fixture
def health_only_server() -> Iterator[int]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _HealthOnly)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    _HealthOnly.seen = []
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()


def test_tracked_run_sends_mlflow_credentials_but_shows_and_records_none(health_only_server, tmp_path, monkeypatch):
    """The password reaches the server (HTTP basic auth on the check, as MLflow's client sends it);
    the run completes though the tracker fails (one warning), and neither its output nor its folder
    holds the password."""
    from motorlab.trackers import tracked

    monkeypatch.setattr(tracked, "_broken", set())
    monkeypatch.setattr(tracked, "_warned", set())
    out = tmp_path / "e"
    proc = run_here("train", ENV_ID, *LQR, "--track", f"mlflow=http://user:{SECRET}@127.0.0.1:{health_only_server}",
                    "--out", out)
    assert_ok(proc)
    assert (out / "summary.json").is_file()
    assert f"Basic {base64.b64encode(f'user:{SECRET}'.encode()).decode()}" in _HealthOnly.seen
    assert "warning:" in proc.stderr and SECRET not in proc.stdout + proc.stderr
    assert not [p for p in out.rglob("*") if p.is_file() and SECRET.encode() in p.read_bytes()]


def test_tracker_messages_quoting_the_uri_are_masked(monkeypatch, capsys):
    """A tracker's failure may quote its URI (a warning, once per process); the line saying where a
    run went and the refusal of a misspelt --track quote it too."""
    from motorlab import trackers
    from motorlab.trackers import mlflow as mlflow_tracker
    from motorlab.trackers import tracked

    uri = f"http://user:{SECRET}@tracking.example:5000"
    monkeypatch.setattr(tracked, "_warned", set())
    monkeypatch.setattr(tracked, "_uris", {uri})
    tracked._warn_once("mlflow", f"tracking to MLflow failed (ConnectionError: {uri}/api/2.0 refused)")
    assert capsys.readouterr().err == ("warning: tracking to MLflow failed (ConnectionError: "
                                       "http://user:***@tracking.example:5000/api/2.0 refused)\n")
    sink = mlflow_tracker.Sink(trackers.Target("mlflow", uri))
    sink.run_id = "abc"
    assert SECRET not in sink.where() and "user:***@tracking.example" in sink.where()
    with pytest.raises(MotorlabError) as caught:
        trackers.parse([f"mlfow={uri}"])
    assert SECRET not in str(caught.value) and "mlfow=http://user:***@" in str(caught.value)


def test_ray_tune_pickles_no_storage_credential(tmp_path):
    """Ray Tune writes its settings, this search among them, to OUT/ray/tune/tuner.pkl: without the
    database URL's password (the study's storage objects hold it; they stay in this process)."""
    pytest.importorskip("ray.tune")
    import ray.cloudpickle

    from motorlab.tuning.objective import Objective
    from motorlab.tuning.ray_study import StudySearch
    from motorlab.tuning.search import TuneSpec, open_storage, open_study
    from motorlab.tuning.space import parse_space

    spec = TuneSpec(target=QUICK, space=parse_space(["delay=uniform:0.05,0.2"]), objective=Objective.make(
        "final_return", None), trials=1, seeds=1, out=tmp_path, storage=f"sqlite:///{tmp_path}/{STORE}", study_name="s")
    search = StudySearch(spec, open_storage(spec), open_study(spec).sampler, None, None, parallel=1, scheduler="none")
    assert SECRET.encode() in ray.cloudpickle.dumps(dict(search.__dict__))  # what it would pickle by default
    pickled = ray.cloudpickle.dumps(search)
    assert SECRET.encode() not in pickled
    assert ray.cloudpickle.loads(pickled).spec.storage == f"sqlite:///{tmp_path}/study.db?password=***"
