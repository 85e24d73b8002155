"""The RL algorithms `motorlab train --algo NAME` knows, one module each in this package.

A module here that defines `ALGORITHM` (an `Algorithm`, see base.py) registers it: adding an
algorithm is adding one file, found by `pkgutil` at the first look-up. The modules import no
torch or SB3, so the registry is cheap enough for `motorlab --help`.
"""

from motorlab.algos._registry import (
    NOT_ALGORITHMS,
    eval_cadence_help,
    get,
    names,
    of_network,
    preset_help,
    presets,
    registry,
    summary_help,
    titles_with,
)
from motorlab.algos.base import Algorithm, OffPolicy, OnPolicy, Preset, SB3Algorithm

__all__ = ["Algorithm", "NOT_ALGORITHMS", "OffPolicy", "OnPolicy", "Preset", "SB3Algorithm", "eval_cadence_help", "get",
           "names", "of_network", "preset_help", "presets", "registry", "summary_help", "titles_with"]
