"""Training: Stable-Baselines3 algorithms and motorlab's model-based learner."""
