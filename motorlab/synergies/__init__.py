"""Muscle synergies: collect activations, measure VAF, fit, import or export a SAR, act in synergy space.

`motorlab.synergies.collect(...)`, `.vaf(...)`, `.fit(...)`, `.import_sklearn(...)`,
`.export_sklearn(...)`, `.load_sar(...)` are the Python API's functions (motorlab/api/synergies.py),
here because users reach synergies by this name, as the CLI's `motorlab synergies ...`. The domain
code is in the modules: `sar` (SAR, fit_sar, vaf_curve), `wrapper` (SynergyActionWrapper),
`sklearn_import` and `sklearn_export`. They sit below the envs, which act in synergy space through
the wrapper; the activations a fit starts from are rollouts of a policy (motorlab.synergies.activations).
"""

# Looked up when first used, by name, with plain imports the import graph sees: this module is a
# façade at the top of the layers, beside motorlab.api (tests/test_layers.py), while the modules of
# the package sit in lower layers. Lazy also because collection workers need not import scikit-learn.
_DOMAIN = ("SAR", "fit_sar", "save_sar", "vaf_curve", "SynergyActionWrapper")


def __getattr__(name: str):
    if name == "SynergyActionWrapper":
        from motorlab.synergies.wrapper import SynergyActionWrapper

        return SynergyActionWrapper
    if name in _DOMAIN:
        from motorlab.synergies import sar

        return getattr(sar, name)
    if name.startswith("_"):  # a probe (copy, inspect, pickle) for a private name: no API import for it
        raise AttributeError(f"module 'motorlab.synergies' has no attribute {name!r}")
    from motorlab.api import synergies as api

    if name in api.__all__:
        return getattr(api, name)
    raise AttributeError(f"module 'motorlab.synergies' has no attribute {name!r}")
