"""The Python API: every command as a function that writes the same run folder and returns it.

    import motorlab

    run = motorlab.train("InvertedPendulum-v5", preset="fast", until_solved=True)
    run.summary["steps_to_success"], run.evaluate(delay=0.2)["return_mean"]
    run.policy(obs)                                   # the trained policy, one observation in
    study = motorlab.run_recipe("pendulum")           # a whole study; in Jupyter, its table and plots

The functions go through the same step kinds as the CLI, recipes and sweeps (`motorlab.kinds`):
the same settings (keyword arguments named as the options), defaults, checks and files. A
user mistake raises `MotorlabError` with the message the CLI prints, and nothing else
(motorlab.api.checks): `SettingsError` (a ValueError too), `ArgumentError` (a TypeError too) and
`StorageError` (an OSError too) are its kinds. Results are views of
their folders (`Result`, `Run`, `Study`, `Sweep`, `Tune`); `load(path)` opens any finished one.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # as the CLI: videos render offscreen, in a notebook too

from motorlab.api import dynamics, synergies  # noqa: E402
from motorlab.api.checks import api_function  # noqa: E402
from motorlab.api.planning import mbrl, mpc  # noqa: E402
from motorlab.api.policies import Run, compare, evaluate, robustness, train, video, zeroshot  # noqa: E402
from motorlab.api.studies import recipe, run_recipe, step, sweep, tune  # noqa: E402
from motorlab.api.views import PolicyFunction, Result, Study, Sweep, Tune, load  # noqa: E402
from motorlab.envs import catalog  # noqa: E402
from motorlab.errors import ArgumentError, MotorlabError, SettingsError, StorageError  # noqa: E402
from motorlab.trackers import tracking  # noqa: E402

register_env = api_function(catalog.register_env)

__all__ = [
    "train", "evaluate", "video", "zeroshot", "robustness", "compare", "mpc", "mbrl",
    "run_recipe", "sweep", "tune", "step", "recipe", "load", "synergies", "dynamics",
    "Result", "Run", "Study", "Sweep", "Tune", "PolicyFunction", "MotorlabError", "tracking", "register_env",
    "SettingsError", "ArgumentError", "StorageError",
]
