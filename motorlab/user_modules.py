"""The user's own modules that register envs: Gymnasium's `module:EnvId` ids, `--import MODULE`
and a recipe's `imports = [...]`.

Importing such a module runs its `gymnasium.register(...)` calls. motorlab imports each once
per process and remembers which ids it registered (for the error that lists them). The names
also go into the environment variable MOTORLAB_IMPORTS, so every process motorlab starts
(env workers, collection pools, a study's or a sweep's training processes, Ray workers)
imports them too before it builds an env; and a run folder records them (environment.json,
"imports"), so a fresh process reading the folder can rebuild its env.

Ground floor: this module imports no other part of motorlab but the error type.
"""

from __future__ import annotations

import importlib
import os

from motorlab.errors import MotorlabError

ENV_VAR = "MOTORLAB_IMPORTS"  # comma-separated module names, inherited by child processes

_registered: dict[str, list[str]] = {}  # module -> the env ids its import registered


def split_env_id(env_id: str) -> tuple[str | None, str]:
    """Gymnasium's "module:EnvId" form as (module, EnvId); (None, id) for a plain id."""
    module, sep, name = env_id.partition(":")
    return (module, name) if sep else (None, env_id)


def import_modules(names: list[str] | tuple[str, ...], why: str = "") -> None:
    """Import each module (once per process) and pass the names on to child processes.

    Args:
        why: where the names came from, for the error ("for env mypkg.envs:MyArm-v0").

    Raises:
        MotorlabError: one line naming the module and its ImportError (or whatever its import raised).
    """
    for name in names:
        name = name.strip()
        if not name:
            continue
        if name in _registered:  # imported once; still passed on (the variable may have been reset since)
            _pass_on(name)
            continue
        import gymnasium as gym  # here: the CLI imports this module when it starts

        before = set(gym.registry)
        try:
            importlib.import_module(name)
        except Exception as e:  # a user's module may raise anything while it imports
            where = f" ({why})" if why else ""
            raise MotorlabError(f"cannot import module {name!r}{where}: {type(e).__name__}: {e}; check that "
                                "it is installed or on PYTHONPATH (pip install -e YOUR_PACKAGE).") from None
        _registered[name] = sorted(set(gym.registry) - before)
        _pass_on(name)


def _pass_on(name: str) -> None:
    names = imported_names()
    if name not in names:
        os.environ[ENV_VAR] = ",".join([*names, name])


def imported_names() -> list[str]:
    """The user modules this process imports for its envs (and passes on to the processes it starts)."""
    return [n for n in os.environ.get(ENV_VAR, "").split(",") if n]


def adopt(names: list[str]) -> None:
    """In a worker process: make the parent's user modules this process's, and import them. A fork server's
    child inherits the server's environment as it was when the server started, not its parent's now: its
    $MOTORLAB_IMPORTS may name modules the parent imported since, or modules gone since (a test's own)."""
    os.environ[ENV_VAR] = ",".join(names)
    import_modules(names, f"passed on in ${ENV_VAR}")


def import_inherited() -> None:
    """Import the modules a parent process passed on (a worker, before it builds an env)."""
    adopt(imported_names())


def remember(names: list[str]) -> None:
    """Pass on modules a run folder recorded (they are imported when an env is next built)."""
    for name in names:
        if isinstance(name, str) and name:
            _pass_on(name)


# A module the user imported themselves (in Python, before calling motorlab) is not passed on:
# it may be importable only there (a script's folder, a test file). Name it with MODULE:ID or
# import_modules([...]) for child processes and run folders to know it.


def _home(spec) -> str:
    """The module an env spec's entry point lives in."""
    entry = spec.entry_point
    return entry.partition(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")


def registered_by(module: str) -> list[str]:
    """The env ids `module` registered: those its import added in this process, else (it was
    imported before motorlab asked for it) those whose entry point lives in it."""
    if _registered.get(module):
        return _registered[module]
    import gymnasium as gym

    return sorted(i for i, spec in gym.registry.items()
                  if _home(spec) == module or _home(spec).startswith(module + "."))


def user_env_ids() -> set[str]:
    """Env ids registered by the user's modules (these get Gymnasium's env checker once)."""
    return {i for ids in _registered.values() for i in ids}
