"""motorlab: learn motor control of simulated bodies in MuJoCo.

Workflows: robust policies (PID, PPO/SAC/TD3, delay, history, model-based LQR),
muscle synergies and model-based control (see the README).
"""

import os

# OpenMP threads that spin after each torch op steal the cores that env processes need
# (measured: SAC with 2 env processes, 480 -> 570 env steps/s). Read when torch loads,
# so it must be set before that; a user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
