"""Env ids: motorlab's own envs registered with Gymnasium, MyoSuite's and Gymnasium-Robotics' registered on first
use, and an id checked (with close matches) before anything is made."""

from __future__ import annotations

import functools
import logging
import warnings

import gymnasium as gym

from motorlab.envs.catalog import facts
from motorlab.envs.upkie import register_upkie
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.extras import missing
from motorlab.user_modules import (
    import_inherited,
    import_modules,
    registered_by,
    split_env_id,
)


@functools.cache
def route_mujoco_warnings() -> None:
    """Send MuJoCo's C-level warnings to Python logging instead of stderr and a
    MUJOCO_LOG.TXT in the working directory. MyoSuite models warn on every load;
    instabilities are still counted from mjData.warning by NumericalGuard. Once per process,
    from make_env (every model motorlab loads is an env's, or read from one): not when motorlab.envs
    is imported, which every motorlab process does at its start (MuJoCo takes ~0.25 s to import)."""
    import mujoco

    log = logging.getLogger("motorlab.mujoco")
    mujoco.set_mju_user_warning(lambda message: log.debug("MuJoCo: %s", message.strip()))


# Envs motorlab ships (motorlab/envs/<module>.py and its MuJoCo model): id -> (entry point, time
# limit, the return that counts as solved). Registered when motorlab.envs is imported, which every process that makes an env does;
# the entry point is a string, so a module's model is read only when its env is made.
BUNDLED_ENVS = {
    # PETS' swing-up; solved: 170 of the 200 a pole held upright from the first step would earn
    "CartpoleSwingup-v0": ("motorlab.envs.cartpole_swingup:CartpoleSwingup", 200, 170.0),
}


def register_bundled() -> None:
    """Register motorlab's own envs with Gymnasium (once: an id already registered is left as it is)."""
    for env_id, (entry_point, steps, solved) in BUNDLED_ENVS.items():
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=entry_point, max_episode_steps=steps, reward_threshold=solved)


register_bundled()



def register_myosuite() -> bool:
    """Import MyoSuite, which registers its env ids (myoHandReorient8-v0, myoLegWalk-v0, ...).

    Returns:
        False when MyoSuite is not installed (the `myosuite` extra).
    """
    route_mujoco_warnings()  # before MyoSuite, whose import may already load a model
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import myosuite  # noqa: F401  (import registers the envs)
    except ImportError:
        return False
    return True


def register_robotics() -> bool:
    """Import Gymnasium-Robotics, which registers its env ids (PointMaze_UMaze-v3, AntMaze_*,
    AdroitHand*, ...), without the notice it prints to stderr on import.

    Returns:
        False when Gymnasium-Robotics is not installed (the `robotics` extra).
    """
    import contextlib
    import io

    try:
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            import gymnasium_robotics  # noqa: F401  (import registers the envs)
    except ImportError:
        return False
    return True


def is_robotics(env_id: str) -> bool:
    """An id of Gymnasium-Robotics' families (registered or not)."""
    return facts(env_id).extra == "robotics"


def check_env_id(env_id: str) -> None:
    """Raise a clear error for an env id Gymnasium does not know, with close matches.

    A "module:EnvId" id imports the module first (Gymnasium's convention: the import registers
    the id), as do the modules given with --import or a recipe's `imports`. MyoSuite ids
    (`myo...`) are registered on first use; without MyoSuite installed they get a message
    saying how to install it.
    """
    import_inherited()
    module, name = split_env_id(env_id)
    if module is not None:
        import_modules([module], f"for env {env_id}")
        if name not in gym.registry:
            ids = registered_by(module)
            raise MotorlabError(f"module {module!r} registers no env {name!r}; it registers "
                                f"{', '.join(ids) if ids else 'no env at all'}.")
        return
    if facts(env_id).extra == "upkie":
        register_upkie()  # clear message when upkie or pybullet is missing
    if env_id not in gym.registry and is_robotics(env_id):  # registered on first use, like MyoSuite's
        if not register_robotics():
            raise missing(f"{env_id} needs Gymnasium-Robotics", "robotics")
    if env_id not in gym.registry:
        installed = register_myosuite()
        if env_id in gym.registry:
            return
        if facts(env_id).extra == "myosuite" and not installed:
            raise missing(f"{env_id} needs MyoSuite", "myosuite")
        if not is_robotics(env_id) and register_robotics() and env_id in gym.registry:
            return  # one of its families this list does not name
        raise MotorlabError(
            f"unknown env id {env_id!r}{did_you_mean(env_id, gym.registry.keys())}; "
            "`python -c \"import gymnasium; gymnasium.pprint_registry()\"` lists the ids; an env of your own: "
            "give MODULE:ID (e.g. mypkg.envs:MyArm-v0) or --import MODULE."
        )


