"""The one exception type for mistakes a user can make, its kinds, and credentials masked.

The CLI prints a `MotorlabError` as a single line and exits nonzero; anything
else is a bug and keeps its traceback. Its subclasses are also the builtin a caller
may catch (`SettingsError` a ValueError, `StorageError` an OSError with the line the
CLI prints). `mask_secrets` is what every recorded string passes through.
"""

import difflib
import errno
import os
import re
from collections.abc import Iterable
from typing import Any
from urllib.parse import unquote, urlsplit


class MotorlabError(Exception):
    """A user-caused problem: the message names the thing and the fix, on one line whatever it quotes
    (a path or a library's message holding a newline is shown with the newline escaped, as `\\n`)."""

    def __str__(self) -> str:
        return one_line(super().__str__())


# control characters as Python writes them in a string literal: a message quoting them stays one line
_CONTROL = {c: repr(chr(c))[1:-1] for c in (*range(32), 127)}


def one_line(text: str) -> str:
    """`text` with its control characters (newlines, tabs, escapes) written out: one printable line."""
    return text.translate(_CONTROL)


def did_you_mean(word: str, choices: Iterable[str], n: int = 3) -> str:
    """Return ' (did you mean a, b?)' for close matches of `word`, or ''."""
    matches = difflib.get_close_matches(word, list(choices), n=n, cutoff=0.6)
    if not matches:
        lowered = word.lower()
        matches = [c for c in choices if lowered and lowered in c.lower()][:n]
    return f" (did you mean {', '.join(matches)}?)" if matches else ""


# ---- credentials in URLs ----------------------------------------------------------------------

MASK = "***"
MIN_SECRET = 3  # shorter credentials are masked in URLs only: in free text they would mask ordinary words
# query parameters that carry a credential (?password=..., ?token=..., ?api_key=...)
_SECRET_PARAM = re.compile(r"pass|pwd|secret|token|key|auth|credential|signature", re.IGNORECASE)


def _credentials(url: str) -> tuple[str, str | None, list[str]]:
    """A URL's authority (user:password@host:port, "" for none), its password (None: it has none)
    and the values of its query parameters named like a credential, as written in it."""
    try:
        parts = urlsplit(url)
    except ValueError:  # not a URL (e.g. an unbalanced "[" in a host)
        return "", None, []
    userinfo, at, _ = parts.netloc.rpartition("@")  # the last "@": a password may hold one itself
    _, colon, password = userinfo.partition(":")
    pairs = (pair.partition("=") for pair in parts.query.split("&")) if parts.query else ()
    return parts.netloc, (password if at and colon else None), [
        value for name, eq, value in pairs if eq and value and _SECRET_PARAM.search(name)]


def mask_url(url: str) -> str:
    """`url` as motorlab shows and records it: a password (`user:secret@host`) and credential query
    parameters (`?password=`, `?token=`) replaced by ***, the rest as written. For database URLs
    (`--storage postgresql://user:secret@host/db`), MLflow tracking URIs and Ray addresses.

    (SQLAlchemy's `URL.render_as_string(hide_password=True)` hides only the userinfo's password and
    re-renders the rest; this keeps the text as the user wrote it, for any scheme.)
    """
    netloc, password, values = _credentials(url)
    if password is not None:  # the authority follows "://" as written (urlunsplit would rewrite sqlite:////path)
        scheme, sep, rest = url.partition("://")
        userinfo, _, host = netloc.rpartition("@")
        url = f"{scheme}{sep}{userinfo.partition(':')[0]}:{MASK}@{host}{rest[len(netloc):]}"
    head, mark, query = url.partition("?")
    if values:
        query = "&".join(f"{name}={MASK}" if eq and value and _SECRET_PARAM.search(name) else name + eq + value
                         for name, eq, value in (pair.partition("=") for pair in query.split("&")))
    return head + mark + query


def redact(text: str, *urls: str | None) -> str:
    """`text` (a message, a library's error) with the credentials of `urls` masked: each URL as
    `mask_url` shows it, and each credential wherever else it appears (percent-decoded too)."""
    for url in filter(None, urls):
        text = text.replace(url, mask_url(url))
        _, password, values = _credentials(url)
        for secret in filter(None, [password, *values]):
            for form in {secret, unquote(secret)}:
                if len(form) >= MIN_SECRET:
                    text = text.replace(form, MASK)
    return text


# A URL inside free text: a scheme and "://", up to whitespace or a quote (a password holding either
# cannot be told from the text around it; a URL would percent-escape them)
_URL = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>`]*")


def _masked_url(url: str) -> tuple[str, list[str]]:
    """`url` masked, and the credentials it held. Unlike `mask_url`, the password ends at the last "@"
    of the URL, not at the first "/": free text (a sweep target, a command line) has passwords written
    unescaped, `user:pa/ss@host`. The user name must not hold "/", "?" or "#" (then it is a path)."""
    scheme, sep, rest = url.partition("://")
    userinfo, at, host = rest.rpartition("@")
    user, colon, password = userinfo.partition(":")
    secrets = []
    if at and colon and password and not any(c in user for c in "/?#"):
        url, secrets = f"{scheme}{sep}{user}:{MASK}@{host}", [password]
    _, _, values = _credentials(url)
    return mask_url(url), secrets + values


def _mask_text(text: str) -> str:
    """Every URL in `text` masked, and each credential it held masked wherever else the text quotes it
    (as written and percent-decoded; from MIN_SECRET characters, shorter ones would mask ordinary words)."""
    if "://" not in text:  # the common case: nothing to find
        return text
    found: list[str] = []

    def one(match: re.Match) -> str:
        masked, secrets = _masked_url(match.group(0))
        found.extend(secrets)
        return masked

    text = _URL.sub(one, text)
    for form in sorted({f for s in found for f in (s, unquote(s)) if len(f) >= MIN_SECRET and f != MASK},
                       key=len, reverse=True):  # the longest first: a short secret inside a long one
        text = text.replace(form, MASK)
    return text


def mask_secrets(value: Any) -> Any:
    """`value` as motorlab records it (settings, targets, command lines, reports, tracker params): every
    URL in every string masked (a password and credential query parameters as ***, see `mask_url`), and
    the credentials quoted elsewhere in that string too. Dicts (keys too), lists and tuples: the same
    structure, masked throughout; anything else as it is. Idempotent, so a recorded value compares
    equal to the value masked again.
    """
    if isinstance(value, str):
        return _mask_text(value)
    if isinstance(value, dict):
        return {mask_secrets(k): mask_secrets(v) for k, v in value.items()}
    if isinstance(value, list):
        return [mask_secrets(v) for v in value]
    if isinstance(value, tuple):
        return tuple(mask_secrets(v) for v in value)
    return value


# ---- the kinds of user mistakes (each a MotorlabError, and the builtin callers may catch) -------


class SettingsError(MotorlabError, ValueError):
    """A wrong value or type given to a command or an API function. A ValueError too, so code
    written for `except ValueError` keeps working."""


class ArgumentError(SettingsError, TypeError):
    """A call of an API function that does not fit its signature (an unknown keyword, a missing
    or wrong-typed argument): where Python raises TypeError, so `except TypeError` still works."""


class StorageError(MotorlabError, OSError):
    """What the system refused about a file or folder (a full disk, a name too long, a symlink
    loop, a read-only disk, too many open files), as one line naming the path and the fix. An
    OSError too, with its errno and filename, so `except OSError` callers keep working.

    `StorageError.of(e)` is the one table of causes: the CLI prints its line, the API raises it."""

    # errno -> what to do; the message is "<the system's reason>: <path>; <advice>"
    ADVICE = {
        errno.ENOSPC: "free some space, or choose an --out folder on another disk",
        errno.EDQUOT: "free some space under your quota, or choose an --out folder on another disk",
        errno.ENAMETOOLONG: "choose a shorter --out (each name in a path holds at most 255 bytes)",
        errno.ELOOP: "a symbolic link on the path points back at itself: remove it, or choose another --out",
        errno.EROFS: "choose an --out folder on a disk you can write to",
        errno.EMFILE: "raise the limit of open files (`ulimit -n 4096`) or run fewer processes at once "
                      "(--max-parallel, --workers)",
        errno.ENFILE: "the whole system is out of open files: close some programs, or run fewer processes at once",
        errno.EACCES: "check its permissions, or choose an --out folder you can write to",
        errno.EPERM: "check its permissions, or choose an --out folder you can write to",
        errno.ENOTDIR: "a file stands where a folder is expected on that path: rename it, or choose another --out",
        errno.EEXIST: "a file stands where a folder is expected: rename it, or choose another --out",
        errno.EISDIR: "a folder stands where a file is expected: rename it, or choose another path",
        errno.ENOENT: "check the path (was it moved or deleted while the command ran?)",
        errno.EIO: "the disk or network file system failed: check it, then run the command again",
    }

    def __init__(self, code: int, line: str, filename: str | None = None):
        super().__init__(code, line, filename)
        self.line = line

    def __str__(self) -> str:
        return one_line(self.line)

    def __reduce__(self):  # pickled across processes with its line (OSError's own drops extra arguments)
        return type(self), (self.errno, self.line, self.filename)

    @classmethod
    def of(cls, e: BaseException) -> "StorageError | None":
        """The one-line error for `e`, or None for an error the table does not know (a bug's, kept)."""
        if isinstance(e, StorageError):
            return e
        if isinstance(e, RuntimeError) and str(e).startswith(_PATHLIB_LOOP):  # Path.resolve() before Python 3.13
            e = OSError(errno.ELOOP, os.strerror(errno.ELOOP), _literal(str(e).removeprefix(_PATHLIB_LOOP)))
        if not isinstance(e, OSError) or e.errno not in cls.ADVICE:
            return None
        reason = (e.strerror or os.strerror(e.errno)).lower()
        path = e.filename if e.filename is not None else e.filename2
        where = f": {os.fsdecode(path)}" if path is not None else ""
        return cls(e.errno, f"{reason}{where}; {cls.ADVICE[e.errno]}.", None if path is None else os.fsdecode(path))


_PATHLIB_LOOP = "Symlink loop from "


def _literal(text: str) -> str:
    """A path pathlib wrote with %r, as it was."""
    import ast

    try:
        return str(ast.literal_eval(text))
    except (ValueError, SyntaxError):
        return text
