"""Robustness curves: how far each policy holds as a disturbance grows (delay, latency, noise,
pushes, motor noise), one evaluation per policy and grid value (`motorlab robustness`)."""
