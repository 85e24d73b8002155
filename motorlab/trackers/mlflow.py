"""MLflow as a tracker (`--track mlflow[=URI]`), through MlflowClient (no global active run).

Where runs go: the URI given, else $MLFLOW_TRACKING_URI, else `sqlite:///$PWD/mlflow.db`, MLflow 3's
own default (MLflow's file store, `file:///PATH`, is in maintenance mode: it still works when
named, and motorlab then sets MLFLOW_ALLOW_FILE_STORE=true). A local SQLite store keeps its
artifacts beside the database, in `mlruns/<experiment>/`. Runs go to the experiment
$MLFLOW_EXPERIMENT_NAME, else "motorlab"; a sweep's, study's or tune's runs to its parent's.
"""

from __future__ import annotations

import base64
import logging
import os
import re
import socket
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Any

from motorlab.errors import MotorlabError, mask_url, redact
from motorlab.trackers.targets import RunInfo, Target, flat, numbers

LABEL = "MLflow"
EXPERIMENT = "motorlab"
CHECK_SECONDS = 5.0  # how long `check` waits for a tracking server to answer


def _sqlite_path(uri: str) -> Path | None:
    """The database file of a sqlite:/// URI (None for other URIs and in-memory databases)."""
    if not uri.startswith("sqlite:///"):
        return None
    rest = uri[len("sqlite:///"):].split("?", 1)[0]
    return Path(rest) if rest and rest != ":memory:" else None


def _file_path(uri: str) -> Path | None:
    if uri.startswith("file:"):
        return Path(urllib.request.url2pathname(uri.removeprefix("file://") if uri.startswith("file://")
                                                else uri.removeprefix("file:")))
    return None


def resolve(target: Target) -> Target:
    """The tracking URI to use, local paths made absolute (so child processes anywhere use the same store)."""
    uri = target.where or os.environ.get("MLFLOW_TRACKING_URI") or "sqlite:///mlflow.db"
    if "://" not in uri and not uri.startswith("file:"):  # a plain path: MLflow's file store
        uri = Path(uri).resolve().as_uri()
    if (db := _sqlite_path(uri)) is not None:
        uri = f"sqlite:///{db.resolve()}" + (uri[uri.index("?"):] if "?" in uri else "")
    elif (folder := _file_path(uri)) is not None:
        uri = folder.resolve().as_uri()
    return Target("mlflow", uri)


def _writable(path: Path) -> str | None:
    """Why `path` (a file or folder to create or write) cannot be written, or None."""
    existing = path
    while not existing.exists():
        if existing.parent == existing:
            return "no such folder"
        existing = existing.parent
    if existing == path and path.is_file():
        return None if os.access(path, os.W_OK) and os.access(path.parent, os.W_OK | os.X_OK) else "not writable"
    if not existing.is_dir():
        return f"{existing} is a file"
    return None if os.access(existing, os.W_OK | os.X_OK) else f"{existing} is not writable"


def _health_request(uri: str) -> urllib.request.Request:
    """The tracking server's /health, asked with the URI's user and password as HTTP basic auth, as
    MLflow's client (requests) sends them; urllib would take `user:password@` for part of the host."""
    parts = urllib.parse.urlsplit(uri)
    headers = {}
    if parts.username is not None:
        pair = f"{urllib.parse.unquote(parts.username)}:{urllib.parse.unquote(parts.password or '')}"
        headers["Authorization"] = "Basic " + base64.b64encode(pair.encode()).decode()
        parts = parts._replace(netloc=parts.netloc.rpartition("@")[2])
    return urllib.request.Request(urllib.parse.urlunsplit(parts).rstrip("/") + "/health", headers=headers)


def check(target: Target) -> Target:
    """The resolved target, once its store can be written or its server answers (seconds, not MLflow's retries).

    Raises:
        MotorlabError: one line naming the URI and what is wrong.
    """
    t = resolve(target)
    uri = t.where
    local = _sqlite_path(uri) or _file_path(uri)
    if local is not None:
        why = _writable(local)
        if why:
            raise MotorlabError(f"--track mlflow={mask_url(uri)}: cannot write the MLflow store at {local} ({why}); choose "
                                "a path you can write, e.g. --track mlflow=sqlite:///$HOME/mlflow.db.")
    elif uri.startswith(("http://", "https://")):
        try:
            urllib.request.urlopen(_health_request(uri), timeout=CHECK_SECONDS).close()
        except urllib.error.HTTPError:
            pass  # the server answered (an old one may have no /health)
        except (urllib.error.URLError, OSError, socket.timeout) as e:
            reason = getattr(e, "reason", e)
            reason = redact(getattr(reason, "strerror", None) or str(reason), uri)
            raise MotorlabError(f"--track mlflow={mask_url(uri)}: no MLflow tracking server answers there ({reason}); start "
                                "one (mlflow server --port 5000) or check the URI.") from None
    return t


_BAD = re.compile(r"[^\w\-. /:]")


def _key(name: str) -> str:
    """A name MLflow accepts as a metric or param key (letters, digits, _ - . space / :; no "..", 250 characters)."""
    key = _BAD.sub("_", str(name)).replace("..", "_").lstrip("/") or "_"
    return key[:250]


def load(target: Target) -> None:
    """Import what the tracking thread will use (in the main thread, before the run starts), and set
    MLflow's client up: short HTTP retries (its default retries for minutes), the file store allowed
    when it is named, its own log lines ("Creating initial MLflow database tables...") quiet."""
    os.environ.setdefault("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "2")
    os.environ.setdefault("MLFLOW_HTTP_REQUEST_TIMEOUT", "20")
    if _file_path(target.where) is not None:
        os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
    import mlflow.entities  # noqa: F401
    import mlflow.exceptions  # noqa: F401
    import mlflow.tracking  # noqa: F401

    if _sqlite_path(target.where) is not None:
        import mlflow.store.tracking.sqlalchemy_store  # noqa: F401  (SQLAlchemy: a second of imports)
    for name in ("mlflow", "alembic"):
        logging.getLogger(name).setLevel(logging.WARNING)


class Sink:
    """One run in MLflow (its methods run in the tracking thread)."""

    backend = "mlflow"
    label = LABEL

    def __init__(self, target: Target):
        self.uri = target.where
        self.started = False
        self.last_ms: dict[str, int] = {}

    def start(self, info: RunInfo) -> None:
        from mlflow.tracking import MlflowClient

        if (db := _sqlite_path(self.uri)) is not None:
            db.parent.mkdir(parents=True, exist_ok=True)
        self.client = MlflowClient(tracking_uri=self.uri)
        parent = info.parent.get("mlflow")
        self.experiment_id = parent["experiment_id"] if parent else self._experiment()
        tags = {**info.tags, "mlflow.source.name": "motorlab"}
        if parent:
            tags["mlflow.parentRunId"] = parent["run_id"]
        self.run_id = self.client.create_run(self.experiment_id, run_name=info.name, tags=tags).info.run_id
        self.started = True
        self._params(info.config)

    def _experiment(self) -> str:
        from mlflow.exceptions import MlflowException

        name = os.environ.get("MLFLOW_EXPERIMENT_NAME") or EXPERIMENT
        found = self.client.get_experiment_by_name(name)
        if found is not None:
            return found.experiment_id
        db = _sqlite_path(self.uri)
        location = (db.parent / "mlruns" / re.sub(r"[^\w.-]", "_", name)).as_uri() if db else None
        try:
            return self.client.create_experiment(name, artifact_location=location)
        except MlflowException:  # another process created it first
            found = self.client.get_experiment_by_name(name)
            if found is None:
                raise
            return found.experiment_id

    def _params(self, config: dict[str, Any]) -> None:
        from mlflow.entities import Param

        params = [Param(_key(k), v[:6000]) for k, v in flat(config).items()]
        for i in range(0, len(params), 100):
            self.client.log_batch(self.run_id, params=params[i:i + 100])

    def scalars(self, rows: list[tuple[str, float, int, float]]) -> None:
        from mlflow.entities import Metric

        metrics = []
        for tag, value, step, wall in rows:
            key = _key(tag)
            # MLflow keeps one of two equal (key, step, value, time) points; TensorBoard keeps both
            ms = max(int(wall * 1000), self.last_ms.get(key, -1) + 1)
            self.last_ms[key] = ms
            metrics.append(Metric(key, value, ms, step))
        for i in range(0, len(metrics), 1000):
            self.client.log_batch(self.run_id, metrics=metrics[i:i + 1000])

    def summary(self, summary: dict[str, Any]) -> None:
        import time

        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        metrics = [Metric(_key(k), v, now, 0) for k, v in numbers(summary).items()]
        for i in range(0, len(metrics), 1000):
            self.client.log_batch(self.run_id, metrics=metrics[i:i + 1000])

    def files(self, files: list[tuple[Path, str]]) -> None:
        for path, folder in files:
            self.client.log_artifact(self.run_id, str(path), folder or None)

    def end(self, status: str) -> None:
        self.client.set_terminated(self.run_id, status)

    def handoff(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "experiment_id": self.experiment_id}

    def where(self) -> str:
        uri = mask_url(self.uri)  # printed: a server's password is not
        return f"MLflow run {self.run_id} in {uri} (mlflow ui --backend-store-uri {uri})"
