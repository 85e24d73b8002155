"""Forward models: collect transitions (closed form, MuJoCo rollouts or Gymnasium envs), fit a
normalized-delta ensemble in torch, check it open loop against the simulator."""

import importlib

# `motorlab.dynamics.collect(...)`, `.fit(...)`, `.check(...)`: the Python API's functions
# (motorlab/api/dynamics.py), here because users reach forward models by this name. They are
# looked up when first used, by name: the API sits above this package and imports it, so a
# plain import here would point up the layers (and start a cycle).
__all__ = ["collect", "fit", "check"]


def __getattr__(name: str):
    if name in __all__:
        return getattr(importlib.import_module("motorlab.api.dynamics"), name)
    raise AttributeError(f"module 'motorlab.dynamics' has no attribute {name!r}")
