"""Weights & Biases as a tracker (`--track wandb[=PROJECT]`).

Offline unless an API key is configured ($WANDB_API_KEY, or `wandb login`'s entry in ~/.netrc):
then motorlab sets WANDB_MODE=offline, so W&B never asks to log in and never waits on the
network. An offline run is a folder, `wandb/offline-run-<time>-<id>/` under $WANDB_DIR or the
current directory (the run's .wandb log holds its config, scalars and summary; files/ its
files); `wandb sync wandb/offline-run-*` uploads it later. $WANDB_MODE, when set, is obeyed.
Runs go to the project given, else $WANDB_PROJECT, else "motorlab"; a sweep's, study's or
tune's runs share one group. Scalars are logged against `global_step`, TensorBoard's step.
"""

from __future__ import annotations

import netrc
import os
import shutil
import socket
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from motorlab.errors import MotorlabError
from motorlab.trackers.targets import CLOSE_SECONDS, RunInfo, Target

LABEL = "W&B"
PROJECT = "motorlab"
CHECK_SECONDS = 5.0  # how long `check` waits for the W&B server (online mode)
OFFLINE = ("offline", "dryrun", "disabled")


def _base_url() -> str:
    return os.environ.get("WANDB_BASE_URL") or "https://api.wandb.ai"


def has_api_key() -> bool:
    """An API key W&B would use: $WANDB_API_KEY, an identity token file, or ~/.netrc ($NETRC) for the server's host."""
    if os.environ.get("WANDB_API_KEY") or os.environ.get("WANDB_IDENTITY_TOKEN_FILE"):
        return True
    path = os.environ.get("NETRC") or str(Path.home() / ".netrc")
    try:
        return netrc.netrc(path).authenticators(urlsplit(_base_url()).hostname or "") is not None
    except (OSError, netrc.NetrcParseError):
        return False


def resolve(target: Target) -> Target:
    """The project, and W&B's mode settled: offline when no API key is configured (WANDB_MODE, passed on)."""
    if not os.environ.get("WANDB_MODE") and not has_api_key():
        os.environ["WANDB_MODE"] = "offline"
    return Target("wandb", target.where or os.environ.get("WANDB_PROJECT") or PROJECT)


def check(target: Target) -> Target:
    """The resolved target, once the W&B server answers (online mode only; seconds, not W&B's retries).

    Raises:
        MotorlabError: one line naming the server.
    """
    t = resolve(target)
    if os.environ.get("WANDB_MODE", "").lower() not in OFFLINE:
        url = urlsplit(_base_url())
        port = url.port or (443 if url.scheme == "https" else 80)
        try:
            socket.create_connection((url.hostname, port), timeout=CHECK_SECONDS).close()
        except OSError as e:
            raise MotorlabError(f"--track wandb: the W&B server {_base_url()} does not answer "
                                f"({e.strerror or e}); track offline with WANDB_MODE=offline and upload later with "
                                "`wandb sync`.") from None
    return t


def load(target: Target) -> None:
    """Import wandb (in the main thread, before the run starts)."""
    import wandb  # noqa: F401


class Sink:
    """One W&B run (its methods run in the tracking thread)."""

    backend = "wandb"
    label = LABEL

    def __init__(self, target: Target):
        self.project = target.where
        self.started = False

    def start(self, info: RunInfo) -> None:
        import wandb

        tags = [info.kind] + ([f"seed={info.tags['motorlab.seed']}"] if "motorlab.seed" in info.tags else [])
        self.run = wandb.init(
            project=self.project, group=info.group, job_type=info.kind, name=info.name, config=info.config,
            tags=tags, notes=str(info.run_dir) if info.run_dir else None, reinit="create_new",
            settings=wandb.Settings(console="off", silent=True, x_disable_stats=True, init_timeout=CLOSE_SECONDS,
                                    finish_timeout=CLOSE_SECONDS - 10))
        self.run.define_metric("global_step")
        self.run.define_metric("*", step_metric="global_step")  # TensorBoard's step, not W&B's row count
        self.started = True

    def scalars(self, rows: list[tuple[str, float, int, float]]) -> None:
        row: dict[str, float] = {}
        at = None
        for tag, value, step, _wall in rows:
            if row and (step != at or tag in row):  # one W&B row per step (a tag logged twice: two rows)
                self.run.log({**row, "global_step": at})
                row = {}
            row[tag], at = value, step
        if row:
            self.run.log({**row, "global_step": at})

    def summary(self, summary: dict[str, Any]) -> None:
        self.run.summary.update({k: v for k, v in summary.items() if isinstance(v, (int, float, str, bool))})

    def files(self, files: list[tuple[Path, str]]) -> None:
        """Copied into the run's files/ folder (kept there offline, uploaded online); not linked, so the
        offline run stays whole if the run folder moves."""
        base = Path(self.run.dir)
        for path, folder in files:
            dest = base / folder / path.name
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, dest)
            self.run.save(str(dest), base_path=str(base), policy="now")

    def end(self, status: str) -> None:
        self.run.finish(exit_code=0 if status == "FINISHED" else 1)

    def handoff(self) -> dict[str, Any]:
        return {}

    def where(self) -> str:
        if self.run.settings.mode in OFFLINE:
            folder = Path(self.run.dir).parent
            return f"W&B offline run {folder} (upload it with: wandb sync {folder})"
        return f"W&B run {self.run.url}"
