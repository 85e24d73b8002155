"""Forward models: collect transitions (closed form, MuJoCo rollouts or Gymnasium envs), fit a
normalized-delta ensemble in torch, check it open loop against the simulator."""

# `motorlab.dynamics.collect(...)`, `.fit(...)`, `.check(...)`: the Python API's functions
# (motorlab/api/dynamics.py), here because users reach forward models by this name. They are
# looked up when first used, with a plain import the import graph sees: this module is a façade at
# the top of the layers, beside motorlab.api (tests/test_layers.py); the package's modules sit below.
__all__ = ["collect", "fit", "check"]


def __getattr__(name: str):
    if name in __all__:
        from motorlab.api import dynamics as api

        return getattr(api, name)
    raise AttributeError(f"module 'motorlab.dynamics' has no attribute {name!r}")
