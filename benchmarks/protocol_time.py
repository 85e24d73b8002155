"""How long a study's training takes at a recorded rate: on one machine and on a Ray cluster of N.

    from protocol_time import training_hours
    training_hours("sar-hand-reference", env_steps_per_second=26.7, machines=5)

The budgets come from the bundled recipe itself (its train steps' `timesteps` and seeds), so a changed
recipe changes the projection; the rate is a recorded one (a benchmark's JSON: sar_study.py's one run
alone on this CPU, gpu_check.py's on a GPU). The schedule is the one `motorlab run` keeps:
- on one machine, the train steps one after another, a step's seeds one after another (the recipe's
  `parallel_steps` runs two chains at once, but they share the machine's cores or GPU, so the rate of
  each falls: one run at a time at the recorded rate is the honest unit);
- on a Ray cluster (`--backend ray`), the steps one after another and each step's seeds at once, one
  seed per machine: ceil(seeds / N) rounds a step, each at one machine's recorded rate.
Counted: the env steps of training only. Not counted: evaluations during training, collection, the fit,
zero-shot episodes, start-up: a projection is a lower bound of the wall time.
"""

from __future__ import annotations

import math
from functools import cache

HOUR = 3600.0


@cache
def train_budgets(recipe: str) -> tuple[tuple[str, int, int], ...]:
    """(step, env steps per seed, seeds) of each train step of the bundled recipe, in order."""
    from motorlab.kinds import KINDS
    from motorlab.recipes import find_recipe, load_recipe

    steps = load_recipe(find_recipe(recipe)).steps
    return tuple((s.name, int(s.settings.timesteps), len(s.seeds or [0])) for s in steps if s.kind is KINDS["train"])


def training_hours(recipe: str, env_steps_per_second: float, machines: int = 1) -> float:
    """Hours of training of `recipe` at `env_steps_per_second` per run, on `machines` machines."""
    if not env_steps_per_second > 0 or machines < 1:
        raise ValueError(f"a rate > 0 and at least one machine, not {env_steps_per_second!r} and {machines!r}")
    steps = sum(budget * math.ceil(seeds / machines)
                for _, budget, seeds in train_budgets(recipe))
    return steps / env_steps_per_second / HOUR
