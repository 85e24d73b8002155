"""Activations made from known synergies: what the synergy analyses must recover (motorlab.synergies.synthetic)."""

from motorlab.synergies.synthetic import KnownSynergies as GroundTruth
from motorlab.synergies.synthetic import known_synergies as ground_truth

__all__ = ["GroundTruth", "ground_truth"]
