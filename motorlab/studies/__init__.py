"""Studies: run a recipe's steps in order, then tabulate and plot them."""

from motorlab.studies.runner import run_study

__all__ = ["run_study"]
