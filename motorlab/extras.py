"""The optional stacks (pip extras) and the one-line error when one is missing.

The core install runs the pendulum and Reacher workflows; MyoSuite, Upkie, Ray Tune,
EvoTorch, ONNX export, the experiment trackers (MLflow, W&B: `--track`) and Gymnasium-Robotics'
goal-conditioned tasks come with
`pip install 'motorlab[EXTRA]'` (`motorlab[all]`: all of them). A module
that needs one imports it through `require`, which turns a missing stack into a
`MotorlabError` naming the pip command. Ground floor: imports nothing of motorlab's but
`motorlab.errors`.
"""

from __future__ import annotations

import importlib
import shlex
from types import ModuleType

from motorlab.errors import MotorlabError

# extra -> its pinned requirements; keep in step with [project.optional-dependencies] in pyproject.toml
EXTRAS: dict[str, tuple[str, ...]] = {
    "myosuite": ("myosuite==3.0.0",),
    "upkie": ("upkie==13.1.0", "pybullet==3.2.7"),
    "ray": ("ray[tune]==2.60.0",),
    "evotorch": ("evotorch==0.6.1",),
    "onnx": ("onnx==1.23.2", "onnxruntime==1.20.1"),
    "mlflow": ("mlflow-skinny==3.17.2",),
    "wandb": ("wandb==0.31.0",),
    "notebook": ("ipykernel==7.4.0", "ipywidgets==8.1.9"),  # Jupyter: the kernel, live progress bars
    "robotics": ("gymnasium-robotics==1.4.2",),  # goal-conditioned tasks (mazes, Adroit hand): Dict observations
}


def install_hint(extra: str) -> str:
    """`pip install 'motorlab[EXTRA]' (or: pip install PINNED...)`, ready to paste into a shell."""
    if extra not in EXTRAS:
        raise KeyError(f"unknown extra {extra!r}; motorlab's are {', '.join(EXTRAS)}")
    return f"pip install 'motorlab[{extra}]' (or: pip install {' '.join(map(shlex.quote, EXTRAS[extra]))})"


def missing(what: str, extra: str) -> MotorlabError:
    """The error for a missing stack. `what` says who needs what, e.g. "myoHandReorient8-v0 needs MyoSuite"."""
    return MotorlabError(f"{what}, which is not installed: {install_hint(extra)}")


def require(module: str, extra: str, what: str) -> ModuleType:
    """Import `module` (dotted names allowed) from the optional stack `extra`.

    Args:
        module: what to import, e.g. "upkie.envs".
        extra: the pip extra that installs it (a key of `EXTRAS`).
        what: who needs what, e.g. "myoHandReorient8-v0 needs MyoSuite".

    Raises:
        MotorlabError: the module, or something it imports, cannot be imported; one line
            with the pip command.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        top = module.partition(".")[0]
        if e.name is None or e.name.partition(".")[0] == top:
            raise missing(what, extra) from None
        # installed, but one of its own dependencies is not: a partial or broken install
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise MotorlabError(f"{what}, but importing {module} failed ({reason}): reinstall with "
                            f"{install_hint(extra)}") from None
