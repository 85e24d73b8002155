"""motorlab: learn motor control of simulated bodies in MuJoCo.

Workflows: robust policies (PID, PPO/SAC/TD3, delay, history, model-based LQR),
muscle synergies and model-based control (see the README and the docs).

The Python API (motorlab.api) is here too, imported on first use so that `motorlab --help`
and the worker processes start fast:

    import motorlab
    run = motorlab.train("InvertedPendulum-v5", timesteps=20_000)
    run.evaluate(episodes=10)
"""

import os

# OpenMP threads that spin after each torch op steal the cores that env processes need
# (measured: SAC with 2 env processes, 480 -> 570 env steps/s). Read when torch loads,
# so it must be set before that; a user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"

# The API's names, loaded from motorlab.api when first used. The API's forward-model and synergy steps are
# `motorlab.api.dynamics` and `motorlab.api.synergies`: `motorlab.dynamics` and `motorlab.synergies` are
# the domain packages (a subpackage's name is its own once imported, so it cannot also be the API's).
__all__ = ["train", "evaluate", "video", "zeroshot", "robustness", "compare", "mpc", "mbrl", "run_recipe", "sweep",
           "tune", "step", "recipe", "load", "Result", "Run", "Study", "Sweep", "Tune", "MotorlabError", "SettingsError",
           "ArgumentError", "StorageError", "tracking", "register_env"]


# This module is a façade at the top of the layers, beside motorlab.api (tests/test_layers.py): its
# import is a plain statement run when a name is first used, so the import graph sees it.
def __getattr__(name: str):
    if name == "api" or name in __all__:  # `motorlab.api.dynamics.fit(...)` after a bare `import motorlab`
        import motorlab.api

        return motorlab.api if name == "api" else getattr(motorlab.api, name)
    raise AttributeError(f"module 'motorlab' has no attribute {name!r}")
