"""The registry of commands: every `motorlab` command, the step kinds' (motorlab.kinds) and the
others (export, report, run, sweep, tune, ...), each a `Command` object beside its domain code.
The CLI makes one sub-command of each; the worker finds a job's command here by name."""

from __future__ import annotations

from motorlab.command import Command
from motorlab.kinds import KINDS
from motorlab.kinds.export import EXPORT
from motorlab.kinds.report import PLOT, REPORT
from motorlab.kinds.synergy_files import EXPORT_SKLEARN, IMPORT_SKLEARN, PLOT_SYNERGIES
from motorlab.recipe_list import RECIPES
from motorlab.studies.run_command import RUN
from motorlab.sweeps.sweep_command import SWEEP
from motorlab.tuning.tune_command import TUNE

OTHERS: tuple[Command, ...] = (EXPORT, REPORT, PLOT, IMPORT_SKLEARN, EXPORT_SKLEARN, PLOT_SYNERGIES, RUN, SWEEP, TUNE, RECIPES)
# by the words that run them on the command line ("train", "dynamics fit"); kinds for recipes only have none
COMMANDS: dict[str, Command] = {c.command: c for c in (*KINDS.values(), *OTHERS) if c.command}
BY_NAME: dict[str, Command] = {c.name: c for c in (*KINDS.values(), *OTHERS)}
# the command groups and their help
GROUPS = {
    "synergies": "Synergies of muscles or motor commands: collect, VAF, fit, import or export a SAR.",
    "dynamics": "Forward models: collect transitions, fit a model, check it against the simulator.",
}
