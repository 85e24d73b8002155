"""A fork server's children inherit the server's environment as it was when the server started, not
their parent's now. motorlab passes the user's env modules to every process it starts in
$MOTORLAB_IMPORTS, so a worker forked from a server started earlier would import the modules of then:
modules gone since (CI: a test file's own module, imported by SB3's env workers for a later file's
MyoSuite training, failed it as a reset pipe), and none the parent imported since. Each kind of worker
that a fork server starts takes its parent's list instead. Each case runs in a fresh process, whose
fork server starts with a stale list."""

from __future__ import annotations

import subprocess
import sys

import pytest

STALE = '''
import os, sys
import multiprocessing.forkserver
os.environ["MOTORLAB_IMPORTS"] = "{gone}"
multiprocessing.forkserver.ensure_running()  # the fork server starts now, with that environment
del os.environ["MOTORLAB_IMPORTS"]  # ...which the parent has left since
'''

TRAIN = STALE + '''
from motorlab.kinds.train import TRAIN
from motorlab.rl.config import resolve
cfg = resolve({{"env": {{"id": "InvertedPendulum-v5"}}, "algo": "ppo", "n_envs": 2, "timesteps": 128,
               "solve_episodes": 1, "progress": False, "hyperparams": {{"n_steps": 64, "batch_size": 64}}}})
print(TRAIN.perform(cfg, sys.argv[1]).keys()["timesteps"])
'''

EVALUATE = STALE + '''
import multiprocessing as mp
from unittest import mock
import gymnasium as gym
from motorlab.envs import EnvConfig
from motorlab.evaluation import evaluate, pool
from motorlab.policies import ZeroPolicy
with mock.patch.object(pool, "_context", lambda: mp.get_context("forkserver")):  # as with a thread running
    r = evaluate(ZeroPolicy(gym.make("InvertedPendulum-v5").action_space), EnvConfig(id="InvertedPendulum-v5"), 4,
                 seed=0, batch=4, workers=2)
print(len(r.returns))
'''


@pytest.mark.parametrize(("script", "expected"), [(TRAIN, "128"), (EVALUATE, "4")], ids=["sb3-env-workers", "evaluation-pool"])
@pytest.mark.parametrize("gone", ["a_module_removed_since", "tests_own_module,another_gone"])
def test_workers_from_a_fork_server_started_earlier_import_the_parents_modules_of_now(tmp_path, script, expected,
                                                                                      gone):
    proc = subprocess.run([sys.executable, "-c", script.format(gone=gone), str(tmp_path / "run")], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().splitlines()[-1] == expected
