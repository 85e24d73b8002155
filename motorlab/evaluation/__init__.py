"""Evaluation: batched rollouts of any policy (returns, success, falls, numerical faults),
and zero-shot transfer to envs a policy never trained on. (The motor signals of a policy's good episodes, for
synergies: motorlab.synergy_runs.activations; a run's figures and videos: motorlab.media.)

    from motorlab.evaluation import evaluate, Evaluator, Rollouts
"""

from motorlab.evaluation.rollouts import (
                                          EpisodeSuccess,
                                          Evaluator,
                                          Rollouts,
                                          evaluate,
                                          step_success,
                                          success_by,
                                          success_mode,
                                          trained_env_settings,
)

__all__ = ["EpisodeSuccess", "Evaluator", "Rollouts", "evaluate", "step_success", "success_by", "success_mode",
           "trained_env_settings"]
