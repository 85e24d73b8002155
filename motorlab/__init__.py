"""motorlab: learn motor control of simulated bodies in MuJoCo.

Workflows: robust policies (PID, PPO/SAC/TD3, delay, history, model-based LQR),
muscle synergies and model-based control (see the README).
"""

__version__ = "0.1.0"
