"""The step kinds, one file each: train, evaluate (evaluate, zeroshot), media (video, compare),
synergies (collect, vaf, fit), ablate, similarity, import_emg, dynamics (dynamics collect, fit, check),
planning (mpc, mbrl), robustness; beside them the other commands (export, report, synergy_files).
`registry.py` names every kind; the CLI's sweeps, recipes and studies find them through it."""

from motorlab.kinds.registry import DEFAULT_KIND, KINDS, for_command, kind, providers

__all__ = ["DEFAULT_KIND", "KINDS", "for_command", "kind", "providers"]
