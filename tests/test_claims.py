"""motorlab.claims: the marker that makes a folder a run folder, the lock of its one writer, no links.

The lifecycle under generated sequences is tests/adversarial/test_run_folder_lifecycle.py; these are
the mechanisms one by one, and the listed defects of issue 52 as regressions."""

from __future__ import annotations

import os
import signal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab import claims
from motorlab.errors import MotorlabError
from motorlab.runs import move_aside, prepare_run_dir, recover, run_folders, write_summary
from tests.helpers import snapshot

pytestmark = pytest.mark.fast


def test_every_run_folder_carries_its_kind_and_a_finished_one_names_its_entries(tmp_path):
    run = prepare_run_dir(tmp_path / "run", "evaluate")
    claim = claims.read_claim(run)
    assert claim.kind == "evaluate" and claim.pid == os.getpid() and claim.files is None
    (run / "artifact.bin").write_bytes(b"x")
    write_summary(run, {"x": 1})
    assert claims.read_claim(run).files == ("artifact.bin", "summary.json")


@pytest.mark.parametrize("mode", ["new", "resume", "overwrite"])
def test_a_folder_that_is_not_motorlabs_is_refused_in_every_mode(tmp_path, mode):
    """`--overwrite --out d` where d holds a copied run and the user's files; `--out .`: refused."""
    d = tmp_path / "d"
    inner = prepare_run_dir(d / "r1", "evaluate")
    write_summary(inner, {"x": 1})
    (d / "notes.txt").write_text("mine")
    before = snapshot(tmp_path)
    with pytest.raises(MotorlabError, match="not a motorlab run folder") as e, run_folders(mode):
        prepare_run_dir(d, "evaluate")
    assert "\n" not in str(e.value)
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("mode", ["resume", "overwrite"])
def test_another_kinds_run_is_neither_resumed_nor_replaced(tmp_path, mode):
    """`run RECIPE --resume --out TRAIN_RUN` replaced the train run's summary and config."""
    run = prepare_run_dir(tmp_path / "train-run", "train")
    write_summary(run, {"x": 1})
    before = snapshot(tmp_path)
    with pytest.raises(MotorlabError, match="holds a motorlab train run, not a study run"), run_folders(mode):
        prepare_run_dir(run, "pendulum", kind="study")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("note", ["my-notes.txt", "plots/my-notes.txt"])
def test_overwrite_refuses_entries_its_run_did_not_leave(tmp_path, note):
    run = prepare_run_dir(tmp_path / "run", "train")
    (run / "plots").mkdir()
    (run / "plots" / "curve.png").write_bytes(b"png")
    write_summary(run, {"x": 1})
    (run / note).write_text("mine")
    with pytest.raises(MotorlabError, match=f"{note}, which its run did not write"), run_folders("overwrite"):
        prepare_run_dir(run, "train")
    assert (run / note).read_text() == "mine"


def test_a_run_folder_inside_another_is_listed_as_one_entry(tmp_path):
    """A study's step is a run of its own: the study's marker names the step's folder, not its files."""
    study = prepare_run_dir(tmp_path / "study", "pendulum", kind="study")
    step = prepare_run_dir(study / "ppo", "train")
    (step / "policy.json").write_text("{}")
    write_summary(step, {"x": 1})
    write_summary(study, {"x": 1})
    assert claims.read_claim(study).files == ("ppo", "summary.json")
    assert claims.read_claim(step).files == ("policy.json", "summary.json")


def _holder(run, ready_w):
    """A child process that takes `run` as a writer and waits to be killed."""
    pid = os.fork()
    if pid == 0:
        try:
            prepare_run_dir(run, "train")
            os.write(ready_w, b"1")
            signal.pause()
        finally:
            os._exit(0)
    return pid


def test_a_second_writer_is_refused_naming_the_holder_and_a_dead_holders_lock_is_free(tmp_path):
    run = tmp_path / "run"
    r, w = os.pipe()
    pid = _holder(run, w)
    try:
        assert os.read(r, 1) == b"1"
        for mode in ("new", "resume", "overwrite"):
            with pytest.raises(MotorlabError, match=f"being written by another motorlab process \\(pid {pid}\\)"), \
                    run_folders(mode):
                prepare_run_dir(run, "train")
        assert not claims.free(run)
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    assert claims.free(run)  # the kernel dropped the dead holder's lock: no stale lock to clear
    with run_folders("new"):
        assert prepare_run_dir(run, "train") == run


def test_the_lock_is_given_back_when_the_block_ends(tmp_path):
    with run_folders("new"):
        run = prepare_run_dir(tmp_path / "run", "train")
        assert claims.holds(run)
    assert not claims.holds(run)


@pytest.mark.parametrize("entry", ["metrics.csv", "tensorboard", "plots/curve.png"])
def test_a_link_planted_in_a_run_folder_is_refused_and_its_target_untouched(tmp_path, entry):
    run = prepare_run_dir(tmp_path / "run", "train")
    victim = tmp_path / "victim.txt"
    victim.write_text("outside --out")
    link = run / entry
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(victim)
    for mode in ("new", "resume"):
        with pytest.raises(MotorlabError, match="symbolic link"), run_folders(mode):
            prepare_run_dir(run, "train")
    assert victim.read_text() == "outside --out"


def test_a_damaged_marker_is_refused(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / claims.MARKER).write_text("not json")
    with pytest.raises(MotorlabError, match="damaged"):
        prepare_run_dir(run, "train")


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(name=st.text(st.sampled_from(list("ab[]*?!- é")), min_size=1, max_size=6).filter(lambda s: s not in (".", "..")),
       other=st.sampled_from(["?", "*", "[]", "[!x]"]))
def test_a_moved_aside_run_is_found_by_its_exact_name_only(tmp_path_factory, name, other):
    """A killed --overwrite's aside comes back to its own folder; a name that is a glob matching it
    (`a?` for `ab`) neither restores nor deletes it."""
    root = tmp_path_factory.mktemp("asides")
    twin = {"?": name[:-1] + "?", "*": name + "*", "[]": f"[{name[0]}]{name[1:]}", "[!x]": f"{name}[!x]"}[other]
    run = prepare_run_dir(root / name, "train")
    write_summary(run, {"x": 1})
    aside = move_aside(run, [])
    os.rename(aside, aside.with_name(aside.name.rsplit("-", 1)[0] + "-999999999"))  # its process is gone
    if twin != name:
        prepare_run_dir(root / twin, "train")  # another run's folder: recovering it touches nothing of `name`
        recover(root / twin)
        assert not (root / name).exists()
    recover(root / name)
    assert claims.read_claim(root / name).kind == "train" and (root / name / "summary.json").is_file()


def test_a_long_name_is_moved_aside_under_a_hash(tmp_path):
    run = prepare_run_dir(tmp_path / ("é" * 120), "train")  # 240 bytes: the aside name would not fit
    write_summary(run, {"x": 1})
    with run_folders("overwrite"):
        prepare_run_dir(run, "train")
        assert len(list(tmp_path.iterdir())) == 2
        write_summary(run, {"x": 2})
    assert [p.name for p in tmp_path.iterdir()] == [run.name]


def test_a_folder_another_process_is_marking_counts_as_empty(tmp_path):
    """Two searches started at once into one new --out (they share it): one sees the other's marker
    being written, its temp file, for a moment; the folder is no less empty for it."""
    run = tmp_path / "run"
    run.mkdir()
    (run / f".{claims.MARKER}.k3j2x1.tmp").write_text("{}")
    assert prepare_run_dir(run, "tune") == run and claims.read_claim(run).kind == "tune"
