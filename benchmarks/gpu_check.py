"""A GPU machine's check: SAC, the forward model and MPC, and the SAR hand study, on the device and on the CPU.

    scripts/gpu-check.sh [--device cuda] [--quick] [--out DIR]
    (= .venv/bin/python benchmarks/gpu_check.py ...)

Run it whenever a GPU machine is lent (`device` tool: `status`, then `run scripts/gpu-check.sh`), and
commit its JSON (benchmarks/results/gpu_check.json; --quick: gpu_check-quick.json). It takes <= 10 min
on one GPU and exits nonzero on any error (the step that failed and its last lines of stderr).

What runs, each through motorlab's CLI in its own process (what a user's command does), on --device and,
for the rates, also on the CPU (fewer steps: the CPU's rate needs fewer to settle):
  1. SAC at the SAR study's reference settings (preset sar-sac: [400, 300] networks, batch 256, one
     update per env step) on myoHandReorient8-v0: env steps/s and gradient updates/s once learning
     runs (after learning_starts; from metrics.csv's training clock and model.zip's update count).
  2. The forward model: `dynamics collect Reacher-v5` (random episodes, once) -> `dynamics fit` (the
     default ensemble) -> `mpc` (the default planner, 10 envs side by side): the fit's seconds and
     the planning time per env per control step.
  3. The sar-hand-reference study at 1/50 of its env steps (play 20k, SAR-RL 30k x 5 seeds, RL-E2E
     50k x 5 seeds, collect 20 episodes, zero-shot 10 episodes), every train step on --device: that it
     runs end to end, its wall time, and its findings. Its success rates at 1/50 say nothing of SAR.
Output: one JSON object on stdout (progress on stderr), with the device's name, each rate on the device
and on the CPU and their ratio, and provenance (date, command line, commit, versions, machine).
`projection`: the full published protocol's training hours (sar-hand-reference: play 1M, SAR-RL and RL-E2E
5 seeds each; protocol_time.py) at the SAC rate measured on each device, on one machine and on Ray clusters
of 2 and 5 machines (docs/benchmarks.md#gpu-check).
--quick (CI, on the CPU): the same steps at tiny sizes (SAC 300 steps, 20 collected episodes, the study at
1/5000 with one seed per arm), ~2-3 min; it checks that every part runs and the JSON's shape.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from protocol_time import train_budgets, training_hours  # benchmarks/ is the script's folder
from provenance import Recorder

HAND = "myoHandReorient8-v0"
FULL = {"sac_steps": {"device": 6000, "cpu": 1600}, "learning_starts": 1000, "collect_episodes": 200,
        "mpc_episodes": 10, "study_scale": 50, "study_seeds": 5}
QUICK = {"sac_steps": {"device": 300, "cpu": 300}, "learning_starts": 100, "collect_episodes": 20,
         "mpc_episodes": 2, "study_scale": 5000, "study_seeds": 1}
STUDY = "sar-hand-reference"
STUDY_EPISODES = {"collect": 1000, "zeroshot": 500}
CLUSTERS = (1, 2, 5)  # machines the projection is given for


def say(text: str) -> None:
    print(f"[gpu-check {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def motorlab(*args: str, step: str) -> None:
    """One motorlab command; any failure ends the check (nonzero) with its stderr's tail."""
    cmd = [sys.executable, "-m", "motorlab", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"gpu-check: {step} failed (exit {proc.returncode}): {' '.join(cmd[2:])}\n"
                         f"{proc.stderr[-3000:]}")


def sac_rates(device: str, steps: int, starts: int, out: Path) -> dict:
    """Env steps/s and updates/s of the reference SAC once learning runs."""
    motorlab("train", HAND, "--preset", "sar-sac", "--device", device, "--timesteps", str(steps),
             "--set", f"learning_starts={starts}", "--eval-every", str(10 * steps), "--solve-episodes", "1",
             "--checkpoint-every", "0", "--no-progress", "--out", str(out), step=f"SAC on {device}")
    with zipfile.ZipFile(out / "model.zip") as z:  # SB3's JSON part: no pickle is loaded
        updates = int(json.loads(z.read("data"))["_n_updates"])
    with open(out / "metrics.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r.get("episode_return")]
    warm = [r for r in rows if int(float(r["timesteps"])) <= starts]
    t0, s0 = (float(warm[-1]["train_seconds"]), int(float(warm[-1]["timesteps"]))) if warm else (0.0, 0)
    summary = json.loads((out / "summary.json").read_text())
    seconds = float(summary["train_seconds"]) - t0
    return {"device": device, "env_steps": int(summary["timesteps"]), "learning_starts": starts, "updates": updates,
            "seconds_learning": round(seconds, 2),
            "updates_per_second": round(updates / seconds, 1) if seconds > 0 else None,
            "env_steps_per_second": round((int(summary["timesteps"]) - s0) / seconds, 1) if seconds > 0 else None}


def model_rates(device: str, collected: Path, episodes: int, out: Path) -> dict:
    """The forward model's fit and the planner on `device`."""
    fit, mpc = out / f"fit-{device}", out / f"mpc-{device}"
    t = time.perf_counter()
    motorlab("dynamics", "fit", str(collected), "--device", device, "--out", str(fit), step=f"dynamics fit on {device}")
    fit_wall = time.perf_counter() - t
    motorlab("mpc", "Reacher-v5", "--model", str(fit), "--device", device, "--episodes", str(episodes), "--parallel", str(episodes),
             "--out", str(mpc), step=f"mpc on {device}")
    f, m = (json.loads((d / "summary.json").read_text()) for d in (fit, mpc))
    return {"device": device, "fit_train_seconds": round(float(f["train_seconds"]), 2),
            "fit_command_seconds": round(fit_wall, 1), "epochs": f["epochs_run"], "valid_mse": f["valid_mse"],
            "plan_ms_per_env_step": round(float(m["plan_ms_median"]), 2), "mpc_return_mean": m["return_mean"]}


def study(device: str, scale: int, seeds: int, out: Path) -> dict:
    """The SAR hand study at 1/scale of its env steps, every train step on `device`."""
    budgets = {name: steps for name, steps, _ in train_budgets(STUDY)}  # the recipe's own
    sets = [f"{name}.timesteps={max(100, steps // scale)}" for name, steps in budgets.items()]
    sets += [f"{name}.episodes={max(2 if name == 'zeroshot' else 5, n // scale)}" for name, n in STUDY_EPISODES.items()]
    sets += [f"sar-rl.seeds={seeds}", f"rl-e2e.seeds={seeds}", "device=" + device,
             f"eval_every={max(100, budgets['play'] // scale // 4)}", f"collect.preview={max(5, 200 // scale)}"]
    t = time.perf_counter()
    motorlab("run", STUDY, *[a for s in sets for a in ("--set", s)], "--out", str(out), step=f"{STUDY} at 1/{scale}")
    summary = json.loads((out / "summary.json").read_text())
    findings = {k: v for k, v in summary.items() if k in ("sar-rl.success_rate", "rl-e2e.success_rate")
                or (k.startswith(("zeroshot.sar-rl.", "zeroshot.rl-e2e.")) and k.endswith("success_rate_mean"))}
    return {"recipe": STUDY, "scale": f"1/{scale}", "seeds_per_arm": seeds, "set": sets,
            "wall_seconds": round(time.perf_counter() - t, 1), "step_seconds": summary["step_seconds"],
            "findings": findings}


def ratio(a: float | None, b: float | None) -> float | None:
    return round(a / b, 2) if a and b else None


def device_over_cpu(by_device: dict[str, dict], device: str, key: str, faster: str = "higher") -> float | None:
    """The device's figure over the CPU's (None when the device is the CPU: nothing was compared)."""
    if device == "cpu":
        return None
    a, b = by_device[device][key], by_device["cpu"][key]
    return ratio(a, b) if faster == "higher" else ratio(b, a)


def projection(sac: dict[str, dict]) -> dict:
    """The full protocol's training hours at each device's measured SAC rate, by machines."""
    return {"recipe": STUDY, "counts": "training env steps only (protocol_time.py): a lower bound",
            **{d: {str(m): round(training_hours(STUDY, r["env_steps_per_second"], m), 1) for m in CLUSTERS}
               for d, r in sac.items()}}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--device", default="cuda", help="the device under test (cuda; cpu to rehearse it)")
    p.add_argument("--quick", action="store_true", help="tiny sizes, for CI: " + json.dumps(QUICK))
    p.add_argument("--out", type=Path, default=None, help="keep the run folders here (default: a temporary folder)")
    p.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results",
                   help="where the JSON goes (default benchmarks/results)")
    args = p.parse_args(argv)
    size = QUICK if args.quick else FULL
    recorder = Recorder("gpu_check", results=args.results)
    import torch

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        raise SystemExit("gpu-check: --device cuda but torch sees no CUDA device (torch.cuda.is_available() is "
                         "False); run it on a GPU machine, or rehearse with --device cpu --quick")
    name = torch.cuda.get_device_name(0) if args.device.startswith("cuda") else "cpu"
    devices = [args.device] if args.device == "cpu" else [args.device, "cpu"]
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.out or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        say(f"SAC (sar-sac) on {HAND}: {', '.join(devices)}")
        sac = {d: sac_rates(d, size["sac_steps"]["device" if d == args.device else "cpu"], size["learning_starts"],
                            root / f"sac-{d}") for d in devices}
        for d, r in sac.items():
            say(f"  {d}: {r['updates_per_second']} updates/s, {r['env_steps_per_second']} env steps/s")
        say("forward model and MPC on Reacher-v5")
        collected = root / "collect"
        motorlab("dynamics", "collect", "Reacher-v5", "--episodes", str(size["collect_episodes"]), "--out",
                 str(collected), step="dynamics collect")
        model = {d: model_rates(d, collected, size["mpc_episodes"], root) for d in devices}
        for d, r in model.items():
            say(f"  {d}: fit {r['fit_train_seconds']} s, planning {r['plan_ms_per_env_step']} ms per env step")
        say(f"{STUDY} at 1/{size['study_scale']} on {args.device}")
        sar = study(args.device, size["study_scale"], size["study_seeds"], root / "study")
        say(f"  {sar['wall_seconds']} s")
    d = args.device
    result = {"device": d, "device_name": name, "quick": args.quick, "sizes": size,
              "sac": {**sac, "updates_per_second_device_over_cpu": device_over_cpu(sac, d, "updates_per_second"),
                      "env_steps_per_second_device_over_cpu": device_over_cpu(sac, d, "env_steps_per_second")},
              "forward_model": {**model,
                                "plan_speedup_device_over_cpu": device_over_cpu(model, d, "plan_ms_per_env_step", "lower"),
                                "fit_speedup_device_over_cpu": device_over_cpu(model, d, "fit_train_seconds", "lower")},
              "study": sar, "projection": projection(sac),
              "wall_seconds": round(time.perf_counter() - started, 1)}
    recorder.record(result, file="gpu_check" + ("-quick" if args.quick else ""))


if __name__ == "__main__":
    main()
