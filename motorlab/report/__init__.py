"""Figures (PNG, non-interactive matplotlib) for runs and studies."""
