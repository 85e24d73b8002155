"""Muscle synergies: collect activations, measure VAF, fit, import or export a SAR, act in synergy space.

`motorlab.synergies.collect(...)`, `.vaf(...)`, `.fit(...)`, `.import_sklearn(...)`,
`.export_sklearn(...)`, `.load_sar(...)` are the Python API's functions (motorlab/api/synergies.py),
here because users reach synergies by this name, as the CLI's `motorlab synergies ...`. The domain
code is in the modules: `sar` (SAR, fit_sar, vaf_curve), `wrapper` (SynergyActionWrapper),
`sklearn_import` and `sklearn_export`. They sit below the envs, which act in synergy space through
the wrapper; the activations a fit starts from are rollouts of a policy (motorlab.evaluation.activations).
"""

import importlib

# Looked up when first used, by name: the API sits above this package and imports it, so a plain
# import here would point up the layers (and start a cycle). Lazy also because collection workers
# need not import scikit-learn.
_DOMAIN = {"SAR": "motorlab.synergies.sar", "fit_sar": "motorlab.synergies.sar",
           "save_sar": "motorlab.synergies.sar", "vaf_curve": "motorlab.synergies.sar",
           "SynergyActionWrapper": "motorlab.synergies.wrapper"}


def __getattr__(name: str):
    if name in _DOMAIN:
        return getattr(importlib.import_module(_DOMAIN[name]), name)
    if name.startswith("_"):  # a probe (copy, inspect, pickle) for a private name: no API import for it
        raise AttributeError(f"module 'motorlab.synergies' has no attribute {name!r}")
    api = importlib.import_module("motorlab.api.synergies")
    if name in api.__all__:
        return getattr(api, name)
    raise AttributeError(f"module 'motorlab.synergies' has no attribute {name!r}")
