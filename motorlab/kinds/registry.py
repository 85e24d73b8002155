"""The registry of step kinds: one line per kind in KINDS (a new kind is one file beside this one and
one line here), and the look-ups the CLI, recipes, sweeps and studies use."""

from __future__ import annotations

from motorlab.errors import MotorlabError, did_you_mean
from motorlab.kinds.ablate import ABLATE
from motorlab.kinds.dynamics import DYNAMICS_CHECK, DYNAMICS_COLLECT, DYNAMICS_FIT
from motorlab.kinds.evaluate import EVALUATE, ZEROSHOT
from motorlab.kinds.import_emg import IMPORT_EMG
from motorlab.kinds.media import COMPARE, VIDEO
from motorlab.kinds.planning import MBRL, MPC
from motorlab.kinds.robustness import ROBUSTNESS
from motorlab.kinds.similarity import SIMILARITY
from motorlab.kinds.synergies import COLLECT, FIT, VAF
from motorlab.kinds.train import TRAIN
from motorlab.stepkind import StepKind

KINDS: dict[str, StepKind] = {k.name: k for k in (
    TRAIN,
    EVALUATE,
    VIDEO,
    COLLECT,
    VAF,
    FIT,
    ABLATE,
    IMPORT_EMG,
    SIMILARITY,
    ZEROSHOT,
    ROBUSTNESS,
    COMPARE,
    DYNAMICS_COLLECT,
    DYNAMICS_FIT,
    DYNAMICS_CHECK,
    MPC,
    MBRL,
)}
DEFAULT_KIND = TRAIN.name  # a recipe step that names no kind


def kind(name: str) -> StepKind:
    """The kind called `name`.

    Raises:
        MotorlabError: no such kind, with close matches.
    """
    if name not in KINDS:
        raise MotorlabError(f"unknown kind {name!r}{did_you_mean(name, KINDS)}; kinds: {', '.join(KINDS)}.")
    return KINDS[name]


def for_command(command: str) -> StepKind | None:
    """The kind the CLI command `command` ("train", "dynamics fit") runs, if any."""
    return next((k for k in KINDS.values() if k.command == command), None)


def providers(artifacts: tuple[str, ...]) -> list[str]:
    """Names of the kinds whose runs provide one of `artifacts`."""
    return [k.name for k in KINDS.values() if k.provides is not None and k.provides.name in artifacts]
