"""The `video` and `compare` step kinds: a policy's episodes as MP4, and learning curves of
settings across seeds."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator
from rich.console import Console

from motorlab.errors import MotorlabError
from motorlab.report.results import Metric, Number, show
from motorlab.runs import require_run_dir
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Ref, StepKind

# ---- video ------------------------------------------------------------------------------------


class VideoSettings(Settings):
    run: str = Field(description="A training run folder (or an evaluation's: its policy on its env)")
    episodes: int = Field(5, gt=0, description="Episodes to render, one MP4 each")
    camera: str | None = Field(None, description="Camera name or index (default: the model's first; -1: free "
                               "camera)")
    width: int = Field(640, ge=16, le=4096, description="Frame width in pixels")
    height: int = Field(480, ge=16, le=4096, description="Frame height in pixels")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (episode k starts from seed + k)")


class VideoSummary(Summary):
    videos: list[str]
    frames: list[int]
    fps: float
    returns: list[float]
    camera: str | int
    width: int
    height: int


class VideoKind(StepKind[VideoSettings, VideoSummary]):
    """Render episodes of a run's policy offscreen to H.264 MP4 (MUJOCO_GL=egl works without a display)."""

    name = "video"
    headline_keys = ("videos", "returns", "fps")
    refs = (Ref("run", ("policy", "evaluation")),)
    arguments = ("run",)
    out_help = "Folder for the videos (default RUN_DIR/videos)."
    examples = ("MUJOCO_GL=egl motorlab video runs/play --episodes 5 --camera hand_side_inter",)

    def run(self, settings: VideoSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> VideoSummary:
        from motorlab.media.videos import render_video

        s = settings
        folder = out if out is not None else require_run_dir(Path(s.run)) / "videos"
        made: list[Path] = []  # the folder, once the env rendered a frame and the policy loaded

        def start() -> Path:
            made.append(self.start(folder))
            return made[0]

        rendered = render_video(Path(s.run), s.episodes, s.seed, s.camera, s.width, s.height, start=start)
        return self.finish(made[0], settings, VideoSummary.model_validate(rendered))

    def describe(self, settings: VideoSettings, copies: int = 1) -> str:
        return f"video of {settings.run}, {settings.episodes} episode{'s' * (settings.episodes > 1)}"

    def numbers(self, settings: VideoSettings, h: dict[str, Any]) -> list[Number]:
        returns = h.get("returns") or []
        numbers = [Number("videos", "episodes filmed", len(h["videos"]), show(len(h["videos"]), "count"))]
        if returns:
            mean = sum(returns) / len(returns)
            numbers.append(Number("returns", "return (mean of the filmed episodes)", mean, show(mean, "return")))
        return numbers

    def notes(self, settings: VideoSettings, h: dict[str, Any]) -> str:
        return ", ".join(f"{Path(v).parent.name}/{Path(v).name}" for v in h["videos"])

    def report(self, s: VideoSummary, settings: VideoSettings, console: Console) -> None:
        for path, ret in zip(s.videos, s.returns, strict=True):
            console.print(f"written: {path}  (return {ret:.1f})")


VIDEO = VideoKind()


# ---- compare ----------------------------------------------------------------------------------


GROUP_FORM = "write LABEL=RUN_DIR[,RUN_DIR...], e.g. --group SAR-RL=runs/a,runs/b."


class CompareSettings(Settings):
    groups: dict[str, list[str]] = Field(min_length=1, description="LABEL=RUN_DIR[,RUN_DIR...]: one setting, its "
                                         "seeds (a recipe: LABEL = [RUN_DIR, ...])")
    title: str = Field("Learning curves", description="Figure title")
    curve: Literal["training", "evaluation"] = Field(
        "training", description="What the curves show against env steps: training (the running mean of training "
        "episodes, train runs' metrics.csv) or evaluation (each run's evaluation returns: train runs' evaluations, "
        "model-based loops' rounds, curve.csv; a group may mix them)")

    @field_validator("groups", mode="before")
    @classmethod
    def _groups(cls, v: Any) -> Any:
        """Groups as a table (LABEL = [RUN_DIR, ...], or LABEL = "RUN_DIR,RUN_DIR" as the command line's
        --group LABEL=... gives them) or as the command line's items, "LABEL=RUN_DIR[,RUN_DIR...]".

        Raises:
            MotorlabError: an item without a label or a run folder.
        """
        if isinstance(v, str):
            v = [v]
        if isinstance(v, (list, tuple)) and all(isinstance(item, str) for item in v):
            groups: dict[str, Any] = {}
            for item in v:
                label, sep, runs = item.partition("=")
                if not sep or not label or not runs:
                    raise MotorlabError(f"--group {item!r}: {GROUP_FORM}")
                groups[label] = runs
            v = groups
        if isinstance(v, dict):
            out = {}
            for label, runs in v.items():
                if isinstance(runs, str):  # "runs/a,runs/b"
                    if not label or not [r for r in runs.split(",") if r]:
                        raise MotorlabError(f"--group {f'{label}={runs}'!r}: {GROUP_FORM}")
                    runs = [r for r in runs.split(",") if r]
                out[label] = runs
            return out
        return v


class CompareKind(StepKind[CompareSettings, Summary]):
    """Learning curves (return and success vs env steps) of settings across seeds, with 95% bands.

    Writes plots/learning_curves.png (mean and 95% band per group) and summary.json: "<group>.<key>"
    per group, rliable's IQMs and probabilities of improvement."""

    name = "compare"
    key_figures = ("plots/learning_curves.png",)
    refs = (Ref("groups", ("policy", "model")),)  # train runs; mbrl loops (their model/ stands for the loop)
    flags = {"groups": ("--group",)}
    examples = ("motorlab compare --group SAR-RL=runs/sar-s0,runs/sar-s1 --group RL-E2E=runs/e2e-s0,runs/e2e-s1",
                "motorlab compare --curve evaluation --group PETS=runs/pets-s0,runs/pets-s1 --group SAC=runs/sac-s0")

    def run(self, settings: CompareSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> Summary:
        from motorlab.report.compare import check_runs, compare_curves, group_statistics

        groups = {g: [Path(d) for d in ds] for g, ds in settings.groups.items()}
        check_runs(groups, settings.curve)  # a wrong folder is one line, before the run folder is made
        run_dir = self.start(out)
        result = compare_curves(groups, run_dir / "plots" / "learning_curves.png", settings.title, settings.curve)
        summary = Summary(**{f"{label}.{k}": v for label, r in result.items() for k, v in r.items()},
                          **group_statistics(groups))
        return self.finish(run_dir, settings, summary)

    def describe(self, settings: CompareSettings, copies: int = 1) -> str:
        return f"compare {', '.join(settings.groups)}" + (" (evaluations)" if settings.curve == "evaluation" else "")

    def headline(self, s: Summary) -> dict[str, Any]:
        return {k: v for k, v in s.keys().items() if "." in k}  # already "<group>.<key>"

    def metric(self, key: str) -> Metric:
        group, _, rest = key.partition(".")
        if "_p_better_than[" in rest:  # "<metric>_p_better_than[<other>]"
            metric, other = rest[:-1].split("_p_better_than[")
            return Metric(key, f"P({group} > {other}) on {metric.replace('_', ' ')}", "percent")
        labels = {"final_episode_return": ("final training return (running mean)", "return"),
                  "final_episode_success": ("final training success (last 100)", "percent"),
                  "final_eval_return_mean": ("final evaluation return (curve)", "return"),
                  "final_return_iqm": ("evaluation return IQM (95% CI from 5 seeds)", "return"),
                  "final_return_mean": ("evaluation return, mean over seeds", "return"),
                  "success_rate_iqm": ("evaluation success IQM (95% CI from 5 seeds)", "percent"),
                  "success_rate_mean": ("evaluation success, mean over seeds", "percent")}
        if rest in labels:
            return Metric(key, f"{group}: {labels[rest][0]}", labels[rest][1])
        return super().metric(key)

    def numbers(self, settings: CompareSettings, h: dict[str, Any]) -> list[Number]:
        """Per group its final return and success (learning curves), rliable's IQMs with their 95%
        CIs (from 5 seeds, said in the label), and the probability that one group beats another."""
        numbers = []
        for key, value in h.items():
            if value is None or key.endswith(("_ci_low", "_ci_high", ".seeds")):
                continue
            m = self.metric(key)
            if m.label == key.replace("_", " "):
                continue  # a key without a reader's label: in the full summary only
            numbers.append(m.number(h))  # with its CI where the group has one
        return numbers

    def default_findings(self, settings: CompareSettings, h: dict[str, Any]) -> list[str]:
        return [k for k in h if "_p_better_than[" in k and h[k] is not None]

    def notes(self, settings: CompareSettings, h: dict[str, Any]) -> str:
        return "learning curves: plots/learning_curves.png"

    def report(self, s: Summary, settings: CompareSettings, console: Console) -> None:
        console.print(f"written: {s.run_dir}/plots/learning_curves.png")


COMPARE = CompareKind()
