"""The `export` command: a run folder or an SB3 zip as a folder that is safe to share (no pickle),
or a run's policy as ONNX for a robot. The work is motorlab.export's and motorlab.deploy_onnx's,
imported when the command runs (they import torch and SB3)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import Field, model_validator
from rich.console import Console

from motorlab.command import Command, Invocation
from motorlab.envs import ENV_KEYS, EnvConfig, EnvSettings, option_name
from motorlab.errors import MotorlabError


def _algo_help() -> str:
    """--algo's help, naming the SB3 algorithms the registry knows (motorlab.algos: no torch)."""
    from motorlab.algos import SB3Algorithm, registry

    names = [name for name, algo in registry().items() if isinstance(algo, SB3Algorithm)]
    return f"The SB3 algorithm of the zip: {', '.join(names)} (default: read from the zip)"


# What an SB3 zip's policy needs of its env to act (the robustness curves' STRUCTURE): its id, arguments,
# observation history and synergy space; delays and disturbances are how it is tested, `evaluate`'s.
ZIP_ENV_KEYS = frozenset({"env", "history", "sar", "phi", "env_kwargs"})


class ExportSettings(EnvSettings):
    """What `motorlab export` writes, and from what."""

    aliases: ClassVar[frozenset[str]] = ZIP_ENV_KEYS
    env_refused: ClassVar[dict[str, str]] = {
        field: "an exported zip records the env its policy acts in (its id, arguments, history and synergies); "
               "give delays and disturbances to `motorlab evaluate` instead."
        for key, field in ENV_KEYS.items() if key not in ZIP_ENV_KEYS}
    source: Path = Field(description="A run folder, or an SB3 zip written by model.save")
    trust: bool = Field(False, description="Allow unpickling an SB3 zip / VecNormalize file (they can run code); "
                        "needed for a zip only")
    env: EnvConfig | None = Field(None, description="The env an SB3 zip's policy acts in: its id, arguments, "
                                  "history and synergies (checked against the policy, and recorded so that "
                                  "evaluate needs no --env)")
    vecnormalize: Path | None = Field(None, description="VecNormalize.save's file, if the zip's policy saw "
                                      "normalized observations")
    algo: str | None = Field(None, description=_algo_help())
    onnx: bool = Field(False, description="Write the run's policy as OUT/policy.onnx for onnxruntime on a robot "
                       "(observation normalization, history stack and action bounds inside the graph; checked "
                       "against torch to 1e-5 first) and its interface as OUT/policy.onnx.json")

    @model_validator(mode="after")
    def _zip_options_for_zips(self) -> ExportSettings:
        if self.env is not None and "id" not in self.env.model_fields_set:
            given = ", ".join(option_name(field) for field in ENV_KEYS.values() if field in self.env.model_fields_set)
            raise MotorlabError(f"{given} describe{'s' * (',' not in given)} the env of an SB3 zip's policy: give its "
                                "id too, with --env ENV_ID.")
        zip_options = self.env or self.vecnormalize or self.algo or self.trust
        if self.onnx and zip_options:
            raise MotorlabError("--onnx exports a run folder's policy; --trust, --env (and its --history, --sar, "
                                "--phi, --env-arg), --vecnormalize and --algo are for SB3 zips (export the zip to a "
                                "folder first, then that folder with --onnx).")
        if not self.onnx and zip_options and self.source.is_dir():
            raise MotorlabError(f"{self.source} is a run folder: it is exported as it is, without --trust, --env (and "
                                "its --history, --sar, --phi, --env-arg), --vecnormalize or --algo (those are for SB3 "
                                "zips).")
        return self


@dataclass(frozen=True)
class Exported:
    """What an export wrote: `what` it exported (onnx, run, zip) and its export function's summary."""

    what: Literal["onnx", "run", "zip"]
    summary: dict[str, Any]


class ExportCommand(Command[ExportSettings]):
    """Write a policy folder that is safe to share: no pickle in it.

    From a run folder: copies policy.json, policy.safetensors, config.toml, summary.json, metrics.csv,
    plots and videos, and leaves out model.zip (a pickle), checkpoint/ and tensorboard/.
    From an SB3 zip (with --trust): loads it once and writes policy.json + policy.safetensors,
    which `motorlab evaluate`, `video` and `synergies collect` read without unpickling.
    """

    name = "export"
    settings = ExportSettings
    invocation = Invocation
    arguments = ("source",)
    out_help = "The folder to write."
    out_required = True
    examples = (
        "motorlab export runs/ppo --out share/ppo   # only the files safe to send",
        "motorlab export ppo_pendulum.zip --trust --env InvertedPendulum-v5 --out runs/imported",
        "motorlab export ppo_history.zip --trust --env InvertedPendulum-v5 --history 4 --out runs/imported",
        "motorlab export sac.zip --vecnormalize vec_normalize.pkl --trust --env Hopper-v5 --out runs/sac",
        "motorlab export runs/ppo --onnx --out deploy/ppo   # policy.onnx for a robot (docs/deployment.md)",
    )

    def execute(self, settings: ExportSettings, how: Invocation, console: Console | None,
                progress: bool) -> Exported:
        s, out = settings, how.out
        if out is None:
            raise MotorlabError("give --out, the folder to write.")
        if s.onnx:
            from motorlab.deploy_onnx import export_onnx

            return Exported("onnx", export_onnx(s.source, out))
        if s.source.is_dir():
            from motorlab.export import export_run

            return Exported("run", export_run(s.source, out))
        from motorlab.export import export_sb3_zip

        return Exported("zip", export_sb3_zip(s.source, out, s.trust, s.env, s.vecnormalize, s.algo))

    def report(self, result: Exported, settings: ExportSettings, console: Console) -> None:
        s = result.summary
        if result.what == "onnx":
            console.print(f"exported {s['algo'].upper()} policy to ONNX (history {s['history']}, max |onnxruntime - "
                          f"torch| {s['max_abs_error']:.1g} on {s['checked_observations']} observations) -> "
                          f"{s['onnx']}, {s['sidecar']}", highlight=False)
        elif result.what == "run":
            console.print(f"exported {len(s['exported_files'])} files (no pickle) -> {s['run_dir']}")
        else:
            console.print(f"{s['algo'].upper()} policy ({s['num_timesteps']:,} steps"
                          + (", normalized observations" if s["observation_normalized"] else "")
                          + f") -> {s['run_dir']}/policy.json, policy.safetensors"
                          + ("" if settings.env else "; evaluate it with --env ENV_ID"))


EXPORT = ExportCommand()
