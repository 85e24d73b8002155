"""Learning-rate and clip-range schedules from text.

    "3e-4"                 constant
    "linear:3e-4,1e-5"     linear from the first value at the start to the second at the end
    "3e-4->1e-5"           the same, shorter

SB3 calls a schedule with progress_remaining (1 at the start, 0 at the end of the
budget); SB3's own picklable LinearSchedule / FloatSchedule classes are returned so
saved models stay loadable.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from motorlab.errors import MotorlabError

if TYPE_CHECKING:
    from stable_baselines3.common.utils import FloatSchedule, LinearSchedule


def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise MotorlabError(f"{what} schedule {spec!r}: {text!r} is not a number; e.g. 3e-4 or linear:3e-4,1e-5.") from None
    if not math.isfinite(value) or value < 0:
        raise MotorlabError(f"{what} schedule {spec!r}: values must be finite and non-negative, got {value}.")
    return value


def schedule_ends(spec: str | float, what: str = "learning-rate") -> tuple[float, float]:
    """The schedule's value at the start and at the end of the budget (equal for a constant).

    Raises:
        MotorlabError: unreadable spec or a negative value.
    """
    if isinstance(spec, (int, float)):
        value = _number(str(spec), what, str(spec))
        return value, value
    text = spec.strip()
    if text.startswith("linear:"):
        parts = text[len("linear:"):].split(",")
    elif "->" in text:
        parts = text.split("->")
    else:
        value = _number(text, what, spec)
        return value, value
    if len(parts) != 2:
        raise MotorlabError(f"{what} schedule {spec!r} needs two values, start and end: linear:3e-4,1e-5.")
    start, end = (_number(p.strip(), what, spec) for p in parts)
    return start, end


def parse_schedule(spec: str | float, what: str = "learning-rate") -> FloatSchedule | LinearSchedule:
    """The schedule `spec` describes (see module doc), as SB3's own schedule object.

    Raises:
        MotorlabError: unreadable spec or a negative value.
    """
    # SB3 (and torch) load only when a schedule is built for training: settings validation
    # (schedule_ends) runs at every command's start-up
    from stable_baselines3.common.utils import FloatSchedule, LinearSchedule

    start, end = schedule_ends(spec, what)
    is_constant = isinstance(spec, (int, float)) or not (spec.strip().startswith("linear:") or "->" in spec)
    return FloatSchedule(start) if is_constant else LinearSchedule(start, end, 1.0)
