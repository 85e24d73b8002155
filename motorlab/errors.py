"""The one exception type for mistakes a user can make.

The CLI prints a `MotorlabError` as a single line and exits nonzero; anything
else is a bug and keeps its traceback.
"""

import difflib
import re
from collections.abc import Iterable
from urllib.parse import unquote, urlsplit


class MotorlabError(Exception):
    """A user-caused problem: the message names the thing and the fix."""


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
