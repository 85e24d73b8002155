"""`--state observation`: the observation itself (the default; a Dict observation flattened, its desired_goal the goal)."""

from __future__ import annotations

from motorlab.dynamics.layouts.base import LayoutSpec
from motorlab.dynamics.state import DESIRED, KeySlice, StateLayout
from motorlab.errors import MotorlabError


def _entry_labels(keys: tuple[KeySlice, ...]) -> tuple[str, ...]:
    return tuple(f"{k.key}[{i}]" for k in keys for i in range(k.stop - k.start))


def build(env_id: str, obs_dim: int, keys: tuple[KeySlice, ...]) -> StateLayout:
    """The observation as the state; a Dict observation's entries named after their keys, and its
    desired_goal (if any) the planner's goal."""
    if not keys:
        return StateLayout("observation", tuple(f"obs[{i}]" for i in range(obs_dim)))
    if keys[-1].stop != obs_dim:
        raise MotorlabError(f"the observation has {obs_dim} entries and its Dict keys cover {keys[-1].stop}: a "
                            "wrapper changed the flat observation; collect and plan on the env without it.")
    desired = next((k for k in keys if k.key == DESIRED), None)
    if desired is None:
        return StateLayout("observation", _entry_labels(keys), keys=tuple(keys))
    cut = slice(desired.start, desired.stop)
    return StateLayout("observation", _entry_labels(keys), _entry_labels((desired,)),
                       _goal=lambda obs: obs[..., cut], keys=tuple(keys))


LAYOUT = LayoutSpec(build)
