"""The run-folder lifecycle under generated sequences (Hypothesis' stateful testing): runs of two
kinds created, finished, killed at a random moment, resumed and overwritten, second writers holding
a folder, symbolic links planted in it, files a user put there, folders that are not motorlab's, and
odd names (brackets, globs, spaces, unicode, long). After every step:

- a finished run is never lost or mixed: reading its folder (as the next command would, after
  `recover`) gives exactly the files it finished with, or those of the run that replaced it whole;
- nothing outside the run folders changes (a planted link's target, the user's own folders);
- every refusal is one line (a MotorlabError with no newline).

Runs are made through motorlab.runs' own calls (what every kind's `start`/`finish` does), in this
process; a kill is a forked child that `os._exit`s at the chosen write, as SIGKILL would leave it,
and a second writer is a forked child that holds the folder until it is told to go.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import Bundle, RuleBasedStateMachine, initialize, invariant, multiple, rule

from motorlab import claims
from motorlab.errors import MotorlabError
from motorlab.runs import (
    SUMMARY,
    atomic_write_bytes,
    prepare_run_dir,
    recover,
    run_folders,
    write_config,
    write_summary,
)

pytestmark = pytest.mark.fast

KINDS = ("train", "evaluate")
MODES = ("new", "resume", "overwrite")
# names a user may give --out: globs and brackets (a pattern would match other runs' asides), spaces,
# unicode, leading dots and dashes, a newline (a refusal quoting it is still one line), long ones
NAME_CHARS = st.sampled_from(list("ab[]*?-. _é✓\n") + ["x"])
NAMES = st.one_of(
    st.text(NAME_CHARS, min_size=1, max_size=12),
    st.integers(150, 230).map(lambda n: "long" + "é" * ((n - 4) // 2)),
).filter(lambda s: s not in (".", "..") and len(os.fsencode(s)) <= 230)


def _files(folder: Path) -> dict[str, str]:
    """Every file under `folder` with its hash, the marker and environment.json (library versions) left out."""
    out = {}
    for root, _, names in os.walk(folder):
        for n in names:
            p = Path(root) / n
            if n in (claims.MARKER, "environment.json"):
                continue
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _run(out: Path, kind: str, mode: str, payload: bytes, die_at: int | None = None) -> None:
    """One run as every kind makes one: the folder, config, an artifact, summary.json last. `die_at`:
    the write after which the process dies (a child's os._exit: no cleanup, as SIGKILL)."""

    def moment(i: int) -> None:
        if die_at == i:
            os._exit(9)

    with run_folders(mode):
        run_dir = prepare_run_dir(out, kind)
        moment(0)
        write_config(run_dir, {"payload": payload.hex()})
        moment(1)
        atomic_write_bytes(run_dir / "artifact.bin", payload)
        atomic_write_bytes(run_dir / "plots" / "curve.png", payload[::-1])
        moment(2)
        write_summary(run_dir, {"payload": payload.hex(), "kind": kind})
        moment(3)
    moment(4)


def _expected_files(payload: bytes, kind: str) -> dict[str, str]:
    """What a finished `_run` leaves (besides the marker and environment.json)."""
    h = lambda b: hashlib.sha256(b).hexdigest()  # noqa: E731
    import tomli_w

    return {"config.toml": h(tomli_w.dumps({"payload": payload.hex()}).encode()), "artifact.bin": h(payload),
            "plots/curve.png": h(payload[::-1]),
            SUMMARY: h((json.dumps({"payload": payload.hex(), "kind": kind}, indent=2) + "\n").encode())}


def _fork(target) -> int:
    pid = os.fork()
    if pid == 0:  # the child: run, then leave without pytest's cleanup
        try:
            target()
        except BaseException:  # noqa: BLE001 - a refusal in the child: it exits as the CLI would
            os._exit(2)
        os._exit(0)
    return pid


class RunFolders(RuleBasedStateMachine):
    outs = Bundle("outs")

    def __init__(self):
        super().__init__()
        import tempfile

        self.root = Path(tempfile.mkdtemp(prefix="lifecycle-"))
        self.work = self.root / "work"
        self.outside = self.root / "outside"
        self.work.mkdir()
        self.outside.mkdir()
        (self.outside / "precious.txt").write_text("the user's own file\n")
        self.outside_files = _files(self.outside)
        # per out name: the run finished there (kind, files), None when none is owed
        self.finished: dict[str, tuple[str, dict[str, str]] | None] = {}
        self.user_files: dict[str, dict[str, str]] = {}  # files a user put into a folder, never to be lost
        self.kinds: dict[str, str | None] = {}  # the kind whose marker the folder carries (None: not motorlab's)
        self.holder: int | None = None  # a second writer's pid, holding `held`
        self.held: str | None = None

    def teardown(self):
        self._let_go()
        import shutil

        shutil.rmtree(self.root, ignore_errors=True)

    # ---- the runs ---------------------------------------------------------------------------

    @initialize(target=outs, names=st.lists(NAMES, min_size=1, max_size=2, unique=True),
                twin=st.sampled_from(["?", "*", "[]"]))
    def names(self, names, twin):
        # a name whose glob pattern matches the first name's moved-aside runs ("ab" -> "a?", "ab*", "[a]b")
        first = names[0]
        names.append({"?": first[:-1] + "?", "*": first + "*", "[]": f"[{first[0]}]{first[1:]}"}[twin])
        names = list(dict.fromkeys(names))
        for n in names:
            self.finished[n] = None
            self.kinds[n] = None
        return multiple(*names)

    @rule(target=outs, name=NAMES)
    def another_name(self, name):
        self.finished.setdefault(name, None)
        self.kinds.setdefault(name, None)
        return name

    def _allowed(self, name: str, kind: str, mode: str) -> bool:
        """What the rules say a run of `kind` in `mode` may do with `name`'s folder as it stands (a
        second writer aside: see `_busy`)."""
        folder = self.work / name
        if not folder.is_dir() or not any(folder.iterdir()):
            return True
        have = self.kinds.get(name)
        if have is None or have != kind:
            return False  # not motorlab's, or another kind's run
        if self.finished[name] is not None and mode == "new":
            return False
        if self.user_files.get(name) and mode == "overwrite" and self.finished[name] is not None:
            return False
        return True

    def _busy(self, name: str) -> bool:
        return self.held == name

    @rule(name=outs, kind=st.sampled_from(KINDS), mode=st.sampled_from(MODES), payload=st.binary(max_size=64))
    def run(self, name, kind, mode, payload):
        allowed = self._allowed(name, kind, mode)
        try:
            _run(self.work / name, kind, mode, payload)
        except MotorlabError as e:
            assert "\n" not in str(e), str(e)
            assert not allowed or self._busy(name), f"refused what the rules allow: {e}"
            if allowed:  # refused only for the second writer, named by its pid
                assert f"pid {self.holder}" in str(e), str(e)
            return
        assert allowed and not self._busy(name), f"{mode} {kind} into {name!r} ({self.kinds.get(name)}) was not refused"
        self.kinds[name] = kind
        self.finished[name] = (kind, {**_expected_files(payload, kind), **self.user_files.get(name, {})})

    @rule(name=outs, kind=st.sampled_from(KINDS), mode=st.sampled_from(MODES), payload=st.binary(max_size=64),
          die_at=st.integers(0, 4))
    def killed_run(self, name, kind, mode, payload, die_at):
        allowed = self._allowed(name, kind, mode) and not self._busy(name)
        pid = _fork(lambda: _run(self.work / name, kind, mode, payload, die_at))
        _, status = os.waitpid(pid, 0)
        code = os.waitstatus_to_exitcode(status)
        if not allowed:
            assert code == 2, f"the child ran ({code}) where the rules refuse"
            return
        assert code == 9, code
        for other in self.finished:  # the next commands touch the other folders first
            if other != name:
                recover(self.work / other)
        self.kinds[name] = kind
        if die_at >= 3:  # summary.json was written: the new run finished
            self.finished[name] = (kind, {**_expected_files(payload, kind), **self.user_files.get(name, {})})
        elif mode == "resume" or self.finished[name] is None:
            self.finished[name] = None  # continued, or never finished: nothing finished is owed
        # an --overwrite killed before it finished: the old run must come back (the invariant)

    # ---- what others do to the folders -----------------------------------------------------

    @rule(name=outs, kind=st.sampled_from(KINDS))
    def second_writer(self, name, kind):
        """Another process takes the folder (a run of the same kind into a folder it may write) and
        holds it until `let_go`."""
        if self.holder is not None or not self._allowed(name, kind, "resume"):
            return
        read, write = os.pipe()

        def hold():
            os.close(read)
            with run_folders("resume"):
                prepare_run_dir(self.work / name, kind)
                os.write(write, b"1")
                time.sleep(120)

        self.holder = _fork(hold)
        os.close(write)
        assert os.read(read, 1) == b"1"
        os.close(read)
        self.held = name
        self.kinds[name] = kind
        if self.finished[name] is not None:
            self.finished[name] = None  # resumed by the holder, which will never finish

    @rule()
    def let_go(self):
        self._let_go()

    def _let_go(self):
        if self.holder is not None:
            os.kill(self.holder, signal.SIGKILL)  # dies holding it: the kernel drops the lock
            os.waitpid(self.holder, 0)
            self.holder = self.held = None

    @rule(name=outs, entry=st.sampled_from(["metrics.csv", "config.toml", "plots"]))
    def plant_link(self, name, entry):
        """A link to a file outside, planted in a folder: every run into it is refused, and the target
        never changes; then the link is taken away again."""
        folder = self.work / name
        if self.held == name or not folder.is_dir() or self.kinds.get(name) is None:
            return
        link = folder / entry
        if link.exists() or link.is_symlink():
            return
        link.symlink_to(self.outside / "precious.txt")
        try:
            for mode in ("new", "resume"):  # (--overwrite replaces the folder, link and all: it never follows it)
                with pytest.raises(MotorlabError) as e:
                    _run(folder, self.kinds[name], mode, b"link")
                assert "\n" not in str(e.value)
        finally:
            link.unlink()

    @rule(name=outs, where=st.sampled_from(["my-notes.txt", "plots/my-notes.txt"]))
    def user_file(self, name, where):
        """The user keeps a note in a finished run's folder, or in a folder inside it: no command may delete it."""
        folder = self.work / name
        if self.finished.get(name) is None or self.held == name or not (folder / where).parent.is_dir():
            return
        (folder / where).write_text("mine\n")
        files = {where: hashlib.sha256(b"mine\n").hexdigest()}
        self.user_files[name] = {**self.user_files.get(name, {}), **files}
        kind, run_files = self.finished[name]
        self.finished[name] = (kind, {**run_files, **files})

    @rule(name=outs)
    def not_motorlabs(self, name):
        """A folder of the user's own (no marker) where a run folder could go."""
        folder = self.work / name
        if folder.exists():
            return
        folder.mkdir()
        (folder / "data.csv").write_text("1,2,3\n")
        self.kinds[name] = None
        self.finished[name] = ("user", {"data.csv": hashlib.sha256(b"1,2,3\n").hexdigest()})

    # ---- what must hold after every step ---------------------------------------------------

    @invariant()
    def nothing_finished_is_lost_or_mixed(self):
        for name, owed in self.finished.items():
            if owed is None or name == self.held:
                continue
            folder = self.work / name
            recover(folder)  # what the next command on it does first
            assert _files(folder) == owed[1], f"{name!r}: the finished run changed"

    @invariant()
    def nothing_outside_changes(self):
        assert _files(self.outside) == self.outside_files


RunFolders.TestCase.settings = settings(max_examples=int(os.environ.get("MOTORLAB_LIFECYCLE_EXAMPLES", 25)),
                                        stateful_step_count=12, deadline=None, derandomize=True, database=None,
                                        suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
test_run_folder_lifecycle = RunFolders.TestCase
