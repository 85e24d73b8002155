"""Muscle synergies: collect activations, measure VAF, fit or import a SAR, act in synergy space.

    from motorlab.synergy import load_sar, fit_sar, SynergyActionWrapper
"""

import importlib

_EXPORTS = {
    "SAR": "motorlab.synergy.sar", "fit_sar": "motorlab.synergy.sar", "load_sar": "motorlab.synergy.sar",
    "save_sar": "motorlab.synergy.sar", "vaf_curve": "motorlab.synergy.sar",
    "import_sklearn": "motorlab.synergy.sklearn_import",
    "SynergyActionWrapper": "motorlab.synergy.wrapper",
    "collect": "motorlab.synergy.collect",
}
__all__ = list(_EXPORTS)


def __getattr__(name: str):
    # Lazy: `motorlab.synergy.collect` workers need not import scikit-learn.
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'motorlab.synergy' has no attribute {name!r}")
