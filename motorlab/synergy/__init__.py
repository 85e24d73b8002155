"""Muscle synergies: collect activations, measure VAF, fit, import or export a SAR, act in synergy space.

    from motorlab.synergy import collect, load_sar, fit_sar, SynergyActionWrapper
"""

import importlib

# `collect` is imported here, not lazily: a lazy name equal to its submodule's would be the
# submodule once anything imported `motorlab.synergy.collect` (Python sets that attribute).
from motorlab.synergy.collect import collect

_LAZY = {
    "SAR": "motorlab.synergy.sar", "fit_sar": "motorlab.synergy.sar", "load_sar": "motorlab.synergy.sar",
    "save_sar": "motorlab.synergy.sar", "vaf_curve": "motorlab.synergy.sar",
    "import_sklearn": "motorlab.synergy.sklearn_import",
    "export_sklearn": "motorlab.synergy.sklearn_export",
    "SynergyActionWrapper": "motorlab.synergy.wrapper",
}
__all__ = ["collect", *_LAZY]


def __getattr__(name: str):
    # Lazy: collection workers need not import scikit-learn.
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'motorlab.synergy' has no attribute {name!r}")
