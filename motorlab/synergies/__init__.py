"""Synergy space: SARs (PCA, then ICA, scaled to [-1, 1]) and VAF, their analyses (held-out VAF,
similarity, shuffled nulls), EMG import, synthetic activations, scikit-learn SAR files, and the action
wrapper an env puts on with `--sar`. It sits below the envs, which act in synergy space through the
wrapper.

The activations a fit starts from are rollouts of a trained policy: `motorlab.synergy_runs`, a layer
above. The Python API's steps (collect, vaf, fit, ...) are `motorlab.api.synergies`:

    from motorlab.api import synergies
    sar = synergies.fit(synergies.collect(run, 1000), vaf=0.8)
    synergies.load_sar(sar).decode(z)
"""

from motorlab.synergies.sar import SAR, fit_sar, load_sar, save_sar, vaf_curve
from motorlab.synergies.wrapper import SynergyActionWrapper

__all__ = ["SAR", "fit_sar", "load_sar", "save_sar", "vaf_curve", "SynergyActionWrapper"]
