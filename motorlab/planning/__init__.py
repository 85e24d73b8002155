"""Model-based control: MPC on a learned forward model (mpc.py, mpc_episodes.py) and the MBRL loop (mbrl.py)."""
