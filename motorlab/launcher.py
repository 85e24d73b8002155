"""The process launcher of sweeps, searches and studies: where their trials run. Each trial is
a `python -m motorlab.worker JOB` process (motorlab.jobs) writing its own run folder and log, so
the two backends differ only in who starts the processes:

    local  a pool of at most K processes on this machine (K defaults to the cores)
    ray    Ray Tune, on a running cluster (--address) or a Ray instance started here;
           trials are Tune trials (grid_search over them), each starting the same process
           on whichever node Tune places it. Run folders are written by absolute path, so
           every node must see the sweep folder at the same path (a shared file system).

`init_ray` (connecting, the auth token, the user's modules in the runtime_env) is shared with
`motorlab tune --backend ray` (motorlab/tuning/ray_search.py).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path
from typing import Any, Callable, Literal

from pydantic import Field

from motorlab import jobs, processes
from motorlab.errors import MotorlabError, mask_url, redact
from motorlab.extras import missing
from motorlab.kinds import KINDS
from motorlab.runs import (
    STUDY,
    atomic_write_text,
    claim_folder,
    finished_with,
    is_complete,
    toml_holds,
    write_toml,
    wrote_into,
)
from motorlab.settings import Settings
from motorlab.user_modules import ENV_VAR, imported_names

TRIAL_FILE = "sweep_trial.toml"
STARTED_FILE = "sweep_trial_started.toml"  # the job a trial's folder was started with

def trial(name: str, setting: str, seed: int, job: jobs.Job, run_dir: Path, log: Path,
          env: dict[str, str] | None = None, fingerprint: str = "", files: dict[Path, str] | None = None) -> dict[str, Any]:
    """`fingerprint`: a hash of inputs the job only names (a recipe file's text); `env`: the process's
    variables (e.g. one math thread per process); `files`: what the job reads that is written only when it
    starts (a recipe variant, in the sweep's folder: planning writes nothing, so a refused sweep has
    touched no folder)."""
    return {"name": name, "setting": setting, "seed": seed, "job": job.as_dict(),
            "run_dir": str(Path(run_dir).resolve()), "log": str(Path(log).resolve()), "env": env or {},
            "fingerprint": fingerprint, "files": {str(Path(p).resolve()): text for p, text in (files or {}).items()}}


def _marker(t: dict[str, Any]) -> dict[str, Any]:
    return {"job": jobs.from_dict(t["job"]).identity(), "fingerprint": t["fingerprint"]}


def is_finished(t: dict[str, Any]) -> bool:
    """The trial's run folder finished with this very job (and recipe text)."""
    return finished_with(Path(t["run_dir"]), _marker(t), TRIAL_FILE)


def mark_finished(t: dict[str, Any]) -> None:
    write_toml(Path(t["run_dir"]) / TRIAL_FILE, _marker(t))
    wrote_into(Path(t["run_dir"]))  # after its run: the trial folder's marker lists it too


def mark_started(t: dict[str, Any]) -> None:
    """The trial's folder, marked as its run's kind (motorlab.claims: the worker then writes into it,
    and a folder that is not that kind's run is refused here), and what started it."""
    command = jobs.from_dict(t["job"]).command
    claim_folder(Path(t["run_dir"]), KINDS[command].name if command in KINDS else STUDY)
    for path, text in t.get("files", {}).items():
        atomic_write_text(Path(path), text)
    write_toml(Path(t["run_dir"]) / STARTED_FILE, _marker(t))


def launch_job(t: dict[str, Any]) -> jobs.Job:
    """The job that runs `t`: its own, or the same one resumed where an interrupted start of this
    very job left a checkpoint (then only the rest of the budget is trained; the result is the same
    run folder)."""
    job = jobs.from_dict(t["job"])
    run_dir = Path(t["run_dir"])
    kind = KINDS.get(job.command)
    if (kind is not None and not is_complete(run_dir) and toml_holds(run_dir / STARTED_FILE, _marker(t))
            and kind.can_resume(run_dir)):  # else: another job started it, or nothing to go on from
        return jobs.Job(**{**job.as_dict(), "resume": True})
    return job


OnDone = Callable[[dict[str, Any], int, float], None]  # (trial, exit status, seconds)


def _start(t: dict[str, Any]) -> subprocess.Popen:
    log = Path(t["log"])
    log.parent.mkdir(parents=True, exist_ok=True)
    # the child dies with this process (motorlab.processes), even with one killed outright
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), **t["env"], **processes.child_env()}
    job = jobs.tracked(launch_job(t))  # resumed where an interrupted start left a checkpoint
    path = job.write(log.with_name(log.stem + jobs.JOB_SUFFIX))  # beside the log: on the shared file system
    mark_started(t)
    with open(log, "ab" if job.resume else "wb") as f:  # the child keeps its own handle
        return subprocess.Popen(jobs.process(path), stdout=f, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=env)


def last_line(log: Path) -> str:
    """A failed trial's last words, and where to read the rest."""
    try:
        lines = [x for x in Path(log).read_text(errors="replace").splitlines() if x.strip()]
    except OSError:
        return f"no log at {log}"
    return (lines[-1][:200] if lines else "no output") + f"  (log: {log})"


def run_one(t: dict[str, Any]) -> int:
    """Run one trial to the end (the Ray worker's side); marks it finished when it succeeds."""
    proc = _start(t)
    try:
        rc = proc.wait()
    except BaseException:
        _stop([proc])
        raise
    if rc == 0:
        mark_finished(t)
    return rc


def _stop(procs: list[subprocess.Popen], grace: float = 20.0) -> None:
    """Ask running trials to stop as Ctrl-C would (they leave their folders visibly unfinished, their
    checkpoints kept), then kill. Whatever stopped this process (SIGINT, SIGTERM, SIGHUP) asks the same."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    deadline = time.monotonic() + grace
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def run_local(trials: list[dict[str, Any]], max_parallel: int, on_done: OnDone,
              stop: threading.Event | None = None) -> None:
    """At most `max_parallel` trial processes at a time, started in order. Polling (not a
    thread pool) keeps Ctrl-C in this process, which then stops the running trials; so does
    `stop` being set (from another thread, which cannot receive Ctrl-C itself)."""
    pending = list(trials)
    running: list[tuple[dict[str, Any], subprocess.Popen, float]] = []
    try:
        while pending or running:
            while pending and len(running) < max_parallel:
                t = pending.pop(0)
                running.append((t, _start(t), time.perf_counter()))
            time.sleep(0.1)
            for entry in [e for e in running if e[1].poll() is not None]:
                running.remove(entry)
                t, proc, t0 = entry
                if proc.returncode == 0:
                    mark_finished(t)
                on_done(t, proc.returncode, time.perf_counter() - t0)
            if stop is not None and stop.is_set():  # after the finished ones are counted as finished
                raise KeyboardInterrupt
    except BaseException:
        _stop([p for _, p, _ in running])
        raise


BACKENDS = ("local", "ray")


def check_execution(backend: str, address: str | None, max_parallel: int | None) -> None:
    """Check where trials are to run before anything is written.

    Raises:
        MotorlabError: unknown backend, --address without ray, max_parallel < 1, no cluster at address.
    """
    if backend not in BACKENDS:
        raise MotorlabError(f"--backend {backend!r}: choose local (this machine) or ray (a Ray cluster).")
    if address and backend != "ray":
        raise MotorlabError("--address names a Ray cluster; add --backend ray.")
    if max_parallel is not None and max_parallel < 1:
        raise MotorlabError(f"--max-parallel {max_parallel}: give at least 1.")
    if address:
        check_address(address)


def check_address(address: str) -> None:
    """Fail in seconds, not minutes: Ray's own connect retries for a long time on a wrong address."""
    if address == "auto":
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    host = host.rpartition("@")[2]  # ray://USER:PASSWORD@HOST:PORT: the host is what answers
    if not sep or not host or not port.isdigit():
        raise MotorlabError(f"--address {mask_url(address)!r}: write HOST:PORT as `ray start --head` prints it, "
                            "e.g. 10.0.0.5:6379.")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as e:
        raise MotorlabError(f"no Ray cluster answers at {mask_url(address)} ({e.strerror or e}); start one with "
                            f"`ray start --head --port {port}` or check --address.") from None


def _auth_token_available() -> bool:
    """Ray's token sources, in its own order: RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token."""
    path = os.environ.get("RAY_AUTH_TOKEN_PATH") or str(Path.home() / ".ray" / "auth_token")
    return bool(os.environ.get("RAY_AUTH_TOKEN")) or Path(path).is_file()


def _ray_trial(config: dict[str, Any]) -> None:
    """Ray Tune's function trainable: run the trial's process, report its exit status."""
    from ray import tune

    t0 = time.perf_counter()
    rc = run_one(config["trial"])
    tune.report({"returncode": rc, "seconds": time.perf_counter() - t0})


def init_ray(address: str | None) -> Any:
    """Connect to the Ray cluster at `address`, or start a Ray instance here (None); the user's
    env modules reach every worker. Returns the `ray` module (`ray.shutdown()` when done). Shared by
    the sweep's (and a study's) ray backend and `motorlab tune --backend ray`.

    Raises:
        MotorlabError: Ray Tune is not installed, or no cluster answers at `address`.
    """
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("TUNE_DISABLE_AUTO_CALLBACK_LOGGERS", "1")  # run folders already hold the results
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    if address and "RAY_AUTH_MODE" not in os.environ and _auth_token_available():
        # Clusters from `ray start` (Ray >= 2.59) require token authentication, but a client given
        # an address only sends its token in token mode. RAY_AUTH_MODE=disabled opts out.
        os.environ["RAY_AUTH_MODE"] = "token"
    try:
        import ray
        from ray import tune  # noqa: F401 - the extra that is missing when only ray's core is installed
    except ImportError:
        raise missing("the ray backend needs Ray Tune", "ray") from None

    # the user's env modules (--import, MODULE:ID, a recipe's imports) reach the workers' processes, on this
    # machine and on a cluster's other nodes (where the modules must be installed too); jobs carry them too,
    # and the tracking, but the env and collection workers those processes start read this variable
    modules = imported_names()
    env_vars = {ENV_VAR: ",".join(modules)} if modules else {}
    runtime_env = {"env_vars": env_vars} if env_vars else None
    try:
        if address:
            ray.init(address=address, logging_level="ERROR", log_to_driver=False, runtime_env=runtime_env)
        else:
            ray.init(num_cpus=os.cpu_count(), include_dashboard=False, logging_level="ERROR", log_to_driver=False,
                     runtime_env=runtime_env)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise MotorlabError(f"cannot reach a Ray cluster at {address and mask_url(address)}: "
                            f"{redact(str(e).splitlines()[0], address)} "
                            "Start one with `ray start --head` or check --address (HOST:PORT).") from None
    return ray


def run_ray(trials: list[dict[str, Any]], address: str | None, max_parallel: int | None, cpus_per_trial: float,
            storage: Path, on_done: OnDone) -> None:
    """Every trial as one Ray Tune trial (grid_search over the trial list).

    Raises:
        MotorlabError: Ray is not installed, or no cluster answers at `address`.
    """
    ray = init_ray(address)
    from ray import tune

    from motorlab.sweeps.ray_progress import Reporter

    try:
        tuner = tune.Tuner(
            tune.with_resources(_ray_trial, {"cpu": cpus_per_trial}),
            param_space={"trial": tune.grid_search(trials)},
            tune_config=tune.TuneConfig(max_concurrent_trials=max_parallel, reuse_actors=False),
            run_config=tune.RunConfig(name="tune", storage_path=str(Path(storage).resolve()), verbose=0,
                                      callbacks=[Reporter(on_done)]),
        )
        tuner.fit()
    finally:
        ray.shutdown()


class ExecutionSettings(Settings):
    """Where a study's, sweep's or search's processes run (the settings they share)."""

    backend: Literal["local", "ray"] = Field("local", description=(
        "local: a pool of processes on this machine; ray: Ray Tune on a cluster (--address) or a Ray instance "
        "started here"))
    address: str | None = Field(None, description=(
        "Ray cluster address HOST:PORT (from `ray start --head`); every node must see --out at the same path"))
    max_parallel: int | None = Field(None, ge=1, description=(
        "Processes at once (default: one per core locally, as many as the cluster's CPUs fit with ray)"))
