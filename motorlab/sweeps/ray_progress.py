"""The Ray Tune callback that reports finished trials to the sweep's progress bar. A module of
its own so that Ray Tune is imported only by the ray backend, and so that Tune pickles the
class by reference (it pickles its settings into the experiment state)."""

from __future__ import annotations

from ray import tune


class Reporter(tune.Callback):
    def __init__(self, on_done):
        self.on_done = on_done

    def __getstate__(self):  # the progress bar and console belong to this process only
        return {"on_done": None}

    def on_trial_result(self, iteration, trials, trial, result, **info):
        if self.on_done:
            self.on_done(trial.config["trial"], int(result["returncode"]), float(result["seconds"]))

    def on_trial_error(self, iteration, trials, trial, **info):
        if self.on_done:
            self.on_done(trial.config["trial"], 1, 0.0)
