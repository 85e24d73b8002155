"""Feedback controllers: PID (pid.py) and a least-squares linear model with LQR (lqr.py).

Built-in policies without a network, below the policy loader (motorlab.policies), which loads them
by name (`pid`) or from a run folder's policy.json, and below the algorithm registry
(motorlab.algos), whose LQR learner fits them.
"""

from motorlab.controllers.files import save_controller

__all__ = ["save_controller"]
