"""The Python API raises only MotorlabError subclasses for a caller's mistakes (motorlab/api/checks.py):
generated calls of every public function (wrong types, non-finite and negative numbers, unknown
names, paths that do not exist) either get as far as the work, which is mocked here, or raise a
MotorlabError; never a pydantic ValidationError, TypeError, KeyError, AttributeError, OSError...
The subclasses are also the builtin a caller may catch (SettingsError is a ValueError, ArgumentError
a TypeError, StorageError an OSError).
"""

from __future__ import annotations

import inspect
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import motorlab
import motorlab.api.dynamics
import motorlab.api.running
import motorlab.api.synergies
from motorlab.errors import ArgumentError, MotorlabError, SettingsError, StorageError
from tests.helpers import ENV_ID

pytestmark = pytest.mark.fast

CALLS = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


class Accepted(Exception):
    """Raised in place of the work: the call got past every check."""


def _accepted(*args, **kwargs):
    raise Accepted


@pytest.fixture(autouse=True)
def no_work(monkeypatch):
    """Every function's work (a step kind's run, a study, sweep or search) is replaced by Accepted."""
    import motorlab.studies
    import motorlab.sweeps.sweep
    import motorlab.tuning.tune

    monkeypatch.setattr(motorlab.api.running, "run", _accepted)
    monkeypatch.setattr(motorlab.studies, "run_study", _accepted)
    monkeypatch.setattr(motorlab.sweeps.sweep, "run_sweep", _accepted)
    monkeypatch.setattr(motorlab.tuning.tune, "run_tune", _accepted)


def functions() -> dict[str, object]:
    """Every public function of the API, by the name a user calls it by."""
    found = {}
    for name in motorlab.__all__:
        value = getattr(motorlab, name)
        if inspect.isfunction(value) and name != "tracking":  # tracking: a context manager, checked on entry
            found[f"motorlab.{name}"] = value
    for module in (motorlab.api.synergies, motorlab.api.dynamics):
        for name in module.__all__:
            found[f"motorlab.{module.__name__.rpartition('.')[2]}.{name}"] = getattr(module, name)
    return found


FUNCTIONS = functions()
HOSTILE = st.sampled_from([None, 0, -1, -10**12, 10**18, math.nan, math.inf, -math.inf, 1.5, True, "", " ", "x" * 300,
                           "no/such/path", "/", "bogus-v0", [], {}, [1, "a"], {"a": [1]}, (), b"bytes", Path("nowhere"),
                           object(), ENV_ID, "random", "pid", "0", "-1", "nan", "1e400"])
NAMES = st.sampled_from(["bogus", "timestep", "episodes", "seed", "workers", "algo", "delay", "history", "lr",
                         "n_envs", "env_kwargs", "hyperparams", "out", "overwrite", "resume", "track", "progress",
                         "horizon", "epochs", "rounds", "seeds", "trials", "backend", "max_parallel", "reward"])


@st.composite
def calls(draw) -> tuple[str, list, dict]:
    """A function, positional arguments for its leading parameters, and keyword arguments."""
    name = draw(st.sampled_from(sorted(FUNCTIONS)))
    params = [p for p in inspect.signature(FUNCTIONS[name]).parameters.values()
              if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    args = draw(st.lists(HOSTILE, max_size=len(params) + 1))
    kwargs = draw(st.dictionaries(NAMES, HOSTILE, max_size=3))
    return name, args, kwargs


@CALLS
@given(call=calls())
def test_every_mistake_is_a_motorlab_error(call, tmp_path):
    name, args, kwargs = call
    kwargs = {**kwargs, "out": tmp_path / "out"} if "out" not in kwargs else kwargs
    try:
        FUNCTIONS[name](*args, **kwargs)
    except (Accepted, MotorlabError):
        pass
    except Exception as e:  # noqa: BLE001 - the property under test
        pytest.fail(f"{name}(*{args!r}, **{kwargs!r}) raised {type(e).__name__}: {e}")


# ---- the listed mistakes, as regression tests ---------------------------------------------------

@pytest.mark.parametrize("call, kind, fragment", [
    (lambda: motorlab.train(ENV_ID, timestepz=5), MotorlabError, "timestepz"),
    (lambda: motorlab.zeroshot(["r"], ["e"], bogus=1), ArgumentError, "bogus"),
    (lambda: motorlab.zeroshot("run", envs=[ENV_ID]), ArgumentError, "runs='run'"),
    (lambda: motorlab.robustness(["pid"], vary=5), ArgumentError, "vary=5"),
    (lambda: motorlab.evaluate("random", ENV_ID, episodes=math.nan), ArgumentError, "episodes=nan"),
    (lambda: motorlab.train(5), ArgumentError, "env=5"),
    (lambda: motorlab.compare({"a": "run"}), ArgumentError, "groups"),
    (lambda: motorlab.load(Path("no/such/run")), MotorlabError, "does not exist"),
    (lambda: motorlab.api.synergies.load_sar("no/such/sar.npz"), MotorlabError, "sar.npz"),
])
def test_listed_mistakes(call, kind, fragment):
    with pytest.raises(kind, match=None) as raised:
        call()
    assert fragment in str(raised.value) and "\n" not in str(raised.value)


def test_the_kinds_are_the_builtins_callers_catch():
    assert issubclass(SettingsError, ValueError) and issubclass(ArgumentError, TypeError)
    assert issubclass(StorageError, OSError)
    with pytest.raises(TypeError):  # code written before the API checked its arguments keeps working
        motorlab.zeroshot(["r"], ["e"], bogus=1)
