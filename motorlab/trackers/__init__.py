"""Experiment tracking: each run mirrored to MLflow or Weights & Biases (`--track mlflow[=URI]`,
`--track wandb[=PROJECT]`, on train, mpc, mbrl, dynamics fit, sweep, tune and run).

A tracked run holds what its run folder holds, minus the models: the resolved settings
(MLflow params, W&B config), the scalars TensorBoard gets with their tags and steps, the
numbers of summary.json, and the files people read (config.toml, summary.json, results.json,
metrics.csv, table.txt, report.html, plots/*.png, videos/*.mp4; never model.zip, policy or model
weights, checkpoint/, tensorboard/ or data such as transitions.npz).

Live, and where TensorBoard writes. Training scalars reach the tracker as they are written, so a
researcher can watch MLflow's UI while a run trains. They are caught at the one place that
defines them: `mirror(writer)` wraps a TensorBoard writer's add_scalar (motorlab's own
writers in rl/monitor.py and dynamics/train.py, and the writer of SB3's TensorBoard output
format, wrapped by the training callback), so the tracker gets exactly the tags, values and steps
TensorBoard got, and no list of tags is kept twice. Tailing the event files after training
(tensorboard's EventAccumulator) would be simpler, but nothing would show until the end. Kinds
that write no TensorBoard scalars report theirs with `scalars` (mpc: one row per episode; mbrl:
one per round, against env steps).

Robust: training never waits on a tracker. A scalar is appended to a buffer; one background
thread per process starts and ends the tracked runs, sends the buffer every FLUSH_SECONDS
(MLflow's log_batch, W&B's log) and uploads the files. A failure there (a server that went
down, a store that cannot be written) prints one warning line and turns that tracker off for
the rest of the process; the run itself goes on and its folder is complete. The end of a run
waits for the thread at most CLOSE_SECONDS. What can be checked before a run starts is checked
by `tracking` (the CLI's --track, the API's track=): the package is installed (else the pip
line), a tracking server answers within seconds (MLflow's own client would retry for minutes), a
local store can be written. Each is one error line, before anything is written.

Explicit: tracking is on inside a `with tracking(values):` block and nowhere else. The trackers,
the open parent and the tracked step are context variables, not process state: one
`motorlab.train(track="mlflow")` in a notebook tracks that call only, and two steps running in
threads of one study (each in a copy of the context) each have their own tracked run.
`tracking(None)` changes nothing, so calls inside an outer block (a sweep's trials inside
`with motorlab.tracking("mlflow"):`) stay tracked.

Processes: nothing travels in the environment. A process that starts others puts `handoff()` in
each job's settings: the trackers, resolved (an absolute store path, W&B's project), and the
identity of the open parent, as JSON. The child runs its work inside `adopted(handoff)`, which
turns those trackers on without checking them again (the parent did). A sweep, study or tune
folder is a parent run: runs started inside `parent(...)`, in its process or in a child that
adopted its handoff, nest under it (MLflow: one experiment, `mlflow.parentRunId`; W&B: one
group), named by their folder inside the parent's ("lr=0.001-f3b8f2fc/seed2", "trials/3/seed0", "ppo")
and tagged with their kind and seed.

A step kind's run is one tracked run (see StepKind in motorlab/stepkind.py: `step` opens it
around `run`, `folder_ready` starts it once the run folder exists, so a mistake caught before
that leaves no run in the tracker; `step.done` logs the summary and the files).

Ground floor: imports nothing of motorlab's but errors and extras; mlflow and wandb are imported
only when a run is tracked (motorlab/trackers/mlflow.py, motorlab/trackers/wandb.py).
"""

from motorlab.trackers.targets import (
    BACKENDS,
    CLOSE_SECONDS,
    FLUSH_SECONDS,
    RunInfo,
    Target,
    flat,
    numbers,
    parse,
    run_files,
)
from motorlab.trackers.tracked import (
    Parent,
    Step,
    adopted,
    also,
    check,
    folder_ready,
    handoff,
    mirror,
    outputs,
    parent,
    scalar,
    scalars,
    step,
    targets,
    tracking,
)

__all__ = ["BACKENDS", "CLOSE_SECONDS", "FLUSH_SECONDS", "RunInfo", "Target", "flat", "numbers", "parse", "run_files",
           "Parent", "Step", "adopted", "also", "check", "folder_ready", "handoff", "mirror", "outputs", "parent",
           "scalar", "scalars", "step", "targets", "tracking"]
