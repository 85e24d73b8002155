"""What the system refuses (a full disk, a name too long, a symlink loop, a file where a folder
should be, ...) is one line `error: ...` naming the path and the fix, exit status 2, wherever in a
command it is met, and what was written before is intact (motorlab.errors.StorageError.of, the one
table the CLI and the Python API share).

Commands run in this process through `motorlab.cli.main`, as in test_fuzz.py.
"""

from __future__ import annotations

import errno
import hashlib
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import motorlab
from motorlab.errors import MotorlabError, StorageError
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, run_here

pytestmark = pytest.mark.fast

EXAMPLES = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
EVALUATE = ("evaluate", "random", "--env", ENV_ID, "--episodes", "1")


def checksums(root: Path) -> dict[str, str]:
    """sha256 of every file under `root` (symbolic links as their target text), by relative path."""
    sums = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            path = Path(dirpath) / name
            data = os.readlink(path).encode() if path.is_symlink() else path.read_bytes()
            sums[os.path.relpath(path, root)] = hashlib.sha256(data).hexdigest()
    return sums


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory) -> Path:
    """A folder with the traps: a symlink loop, a file, and a finished run."""
    root = tmp_path_factory.mktemp("os-errors")
    (root / "loop").symlink_to("loop")
    (root / "a").symlink_to("b")
    (root / "b").symlink_to("a")
    (root / "file").write_text("not a folder")
    assert_ok(run_here(*EVALUATE, "--out", root / "done"))
    return root


component = st.text(st.characters(min_codepoint=0x61, max_codepoint=0x7a) | st.sampled_from("éλ😀 -_[]"),
                    min_size=1, max_size=12).filter(lambda s: s.strip() not in ("", ".", ".."))
too_long = st.builds(lambda c, n: (c * 300)[:n], component, st.integers(256, 400)).filter(
    lambda s: len(s.encode()) > 255)
trap = st.sampled_from(["loop", "a", "file"])


@st.composite
def bad_outs(draw) -> str:
    """An --out the system refuses: a name over 255 bytes somewhere, or a path through a symlink loop or
    through a file."""
    how = draw(st.sampled_from(["long", "trap"]))
    parts = draw(st.lists(component, max_size=2))
    if how == "long":
        parts.insert(draw(st.integers(0, len(parts))), draw(too_long))
    else:
        parts.insert(0, draw(trap))
    return "/".join(parts)


@EXAMPLES
@given(out=bad_outs())
def test_an_out_the_system_refuses_is_one_line_and_changes_nothing(sandbox, out):
    before = checksums(sandbox)
    proc = run_here(*EVALUATE, "--out", out, cwd=sandbox)
    if out == "file":  # the plain file: runs.py names it itself
        assert_one_line_error(proc, "file")
    else:
        line = assert_one_line_error(proc)
        assert "Traceback" not in proc.stdout
        assert any(word in line for word in ("too long", "symbolic link", "not a directory", "is a file")), line
    assert checksums(sandbox) == before


def _full_disk_after(monkeypatch, calls: int) -> list[int]:
    """os.replace (every atomic write's last step) fails with ENOSPC from its `calls`-th call on
    (0: never); returns the count of calls so far, as it grows."""
    real, count = os.replace, [0]

    def replace(src, dst, *args, **kwargs):
        count[0] += 1
        if calls and count[0] >= calls:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    return count


def test_a_full_disk_at_any_write_is_one_line_and_earlier_runs_are_intact(tmp_path, monkeypatch):
    """The disk fills at each of the run's atomic writes in turn: the command is one line (or, where
    that write was a best-effort one, finishes), and a finished run beside it is untouched."""
    writes = _full_disk_after(monkeypatch, 0)
    assert_ok(run_here(*EVALUATE, "--out", tmp_path / "done"))
    before = checksums(tmp_path)
    refused = 0
    for k in range(1, writes[0] + 1):
        out = tmp_path / f"new{k}"
        _full_disk_after(monkeypatch, k)
        proc = run_here(*EVALUATE, "--out", out)
        monkeypatch.undo()
        if proc.returncode == 0:
            assert (out / "summary.json").is_file()
        else:
            assert_one_line_error(proc, "no space left on device", "free some space", str(out))
            refused += 1
        after = checksums(tmp_path)
        assert {key: v for key, v in after.items() if key.startswith("done")} == before
    # best effort: the marker's list of the run's entries, written after summary.json and again when the
    # run's lock is given back (motorlab.claims): a full disk there costs the list, not the finished run
    assert refused >= writes[0] - 2, f"{refused} of {writes[0]} writes refused"


def test_the_api_raises_the_line_the_cli_prints(tmp_path, monkeypatch):
    _full_disk_after(monkeypatch, 1)
    proc = run_here(*EVALUATE, "--out", tmp_path / "cli")
    with pytest.raises(StorageError) as raised:
        motorlab.evaluate("random", ENV_ID, episodes=1, out=tmp_path / "api", progress=False)
    monkeypatch.undo()
    line = assert_one_line_error(proc, "no space left on device")
    assert isinstance(raised.value, MotorlabError) and isinstance(raised.value, OSError)
    assert raised.value.errno == errno.ENOSPC
    assert line.removeprefix("error: ").replace("cli", "api") == str(raised.value)


@pytest.mark.parametrize("code", sorted(StorageError.ADVICE))
def test_every_errno_of_the_table_is_one_line_naming_the_path(code):
    e = StorageError.of(OSError(code, os.strerror(code), "/some/where"))
    assert e is not None and e.errno == code and e.filename == "/some/where"
    assert "\n" not in str(e) and "/some/where" in str(e) and str(e).endswith(".")
    assert StorageError.of(e) is e


def test_an_errno_outside_the_table_is_a_bug_and_kept():
    assert StorageError.of(OSError(errno.EBADF, "bad file descriptor")) is None
    assert StorageError.of(ValueError("x")) is None
