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

# The API's names, loaded from motorlab.api when first used. `motorlab.dynamics` and `motorlab.synergies`
# are the domain packages; their collect / fit / ... are the API's (see their __init__.py).
__all__ = ["train", "evaluate", "video", "zeroshot", "robustness", "compare", "mpc", "mbrl", "run_recipe", "sweep",
           "tune", "step", "recipe", "load", "synergies", "Result", "Run", "Study", "Sweep", "Tune", "MotorlabError", "SettingsError",
           "ArgumentError", "StorageError", "dynamics", "tracking", "register_env"]


# This module is a façade at the top of the layers, beside motorlab.api (tests/test_layers.py): its
# imports are plain statements run when a name is first used, so the import graph sees them.
def __getattr__(name: str):
    if name == "dynamics":
        import motorlab.dynamics

        return motorlab.dynamics
    if name == "synergies":
        import motorlab.synergies

        return motorlab.synergies
    if name in __all__:
        import motorlab.api

        return getattr(motorlab.api, name)
    raise AttributeError(f"module 'motorlab' has no attribute {name!r}")
