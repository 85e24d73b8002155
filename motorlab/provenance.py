"""Provenance: what a run ran on (Python, the machine, the versions of the libraries that shape results).

Written beside every run's config.toml as environment.json, and shown in reports.
"""

from __future__ import annotations

import functools
import os
import platform
from importlib import metadata

# The libraries whose versions can change a result, in the order a reader looks for them.
PACKAGES = ("motorlab", "torch", "numpy", "mujoco", "gymnasium", "stable-baselines3", "myosuite", "scikit-learn",
            "evotorch", "upkie", "pybullet", "scipy", "matplotlib", "tensorboard", "ray")


@functools.cache
def describe() -> dict:
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "packages": versions,
    }
