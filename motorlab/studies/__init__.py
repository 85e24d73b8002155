"""Studies: run a recipe's steps in order, then tabulate and plot them."""

from motorlab.studies.runner import Execution, run_study

__all__ = ["Execution", "run_study"]
