"""Turn every recorded version of benchmarks/results/mbrl-ENV.json into lines of the development log,
benchmarks/devlog/mbrl-ENV.jsonl (run once, when the devlog began; refuses a log that exists).

Those results were recorded on seeds 0-4, the seeds the settings were then chosen on (issue 53's audit):
they are in-sample numbers, development runs by the harness's rule. Each commit that changed a result
file is one run; its configuration is the loop's resolved settings (the hash counts a configuration
tried twice once). What they lack (a command line on most) is written as null, never guessed.

    .venv/bin/python scripts/devlog_from_history.py
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from provenance import DEVLOG, settings_hash  # noqa: E402

ENVS = ("pendulum", "reacher", "cartpole", "pusher", "arm")
NOT_SETTINGS = ("seed", "until_return", "resume")


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def line(env: str, commit: str, data: dict) -> dict:
    path = f"benchmarks/results/mbrl-{env}.json"
    runs = data.get("loop_runs") or []
    resolved = {k: v for k, v in (runs[0].get("settings_resolved") or {}).items() if k not in NOT_SETTINGS} if runs else {}
    settings = {"env": env, "loop": resolved, "loop_set": (data.get("settings", {}).get("loop") or {}).get("loop_set"),
                "sac": {k: v for k, v in (data.get("settings", {}).get("sac") or {}).items()}}
    result = {"loop": {k: data["loop"].get(k) for k in ("seeds", "steps_to_threshold", "final_return_mean")},
              "sac": {k: data["sac"].get(k) for k in ("seeds", "steps_to_threshold", "final_return_mean")},
              "ratio_sac_over_loop": data.get("ratio_sac_over_loop"), "targets": data.get("targets")}
    return {"date": data.get("date"), "argv": data.get("argv"), "git": data.get("git"),
            "seeds": data["loop"].get("seeds"), "settings_hash": settings_hash(settings), "settings": settings,
            "result": result, "imported_from": f"{path} at {commit}",
            "note": "recorded as a result before the development log existed; its seeds were the ones the "
                    "settings were chosen on (in-sample)"}


def main() -> None:
    DEVLOG.mkdir(parents=True, exist_ok=True)
    for env in ENVS:
        out = DEVLOG / f"mbrl-{env}.jsonl"
        if out.exists():
            raise SystemExit(f"{out} exists: the history was imported already")
        path = f"benchmarks/results/mbrl-{env}.json"
        commits = git("log", "--reverse", "--format=%H", "--", path).split()
        lines = [line(env, c[:7], json.loads(git("show", f"{c}:{path}"))) for c in commits]
        out.write_text("".join(json.dumps(x) + "\n" for x in lines))
        print(f"{out.relative_to(ROOT)}: {len(lines)} runs, {len({x['settings_hash'] for x in lines})} configurations")


if __name__ == "__main__":
    main()
