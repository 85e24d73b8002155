"""The one exception type for mistakes a user can make.

The CLI prints a `MotorlabError` as a single line and exits nonzero; anything
else is a bug and keeps its traceback.
"""

import difflib
from collections.abc import Iterable


class MotorlabError(Exception):
    """A user-caused problem: the message names the thing and the fix."""


def did_you_mean(word: str, choices: Iterable[str], n: int = 3) -> str:
    """Return ' (did you mean a, b?)' for close matches of `word`, or ''."""
    matches = difflib.get_close_matches(word, list(choices), n=n, cutoff=0.6)
    if not matches:
        lowered = word.lower()
        matches = [c for c in choices if lowered and lowered in c.lower()][:n]
    return f" (did you mean {', '.join(matches)}?)" if matches else ""
