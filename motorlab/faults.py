"""Numerical faults: episodes that `envs.wrappers.NumericalGuard` ended because the simulation
went bad (NaN/Inf observation or reward, MuJoCo resetting a diverging state).

Every command that runs episodes counts them (`numerical_faults` in summary.json) and lists
them, one line per faulted episode with its reason, in the run folder's `faults.log`, so a
run never crashes on a blow-up and never hides one either.
"""

from __future__ import annotations

from pathlib import Path

from motorlab.runs import atomic_write_text

FAULT_KEY = "numerical_fault"  # info key NumericalGuard sets, naming the cause
FAULTS_LOG = "faults.log"


def fault_of(info: dict) -> str | None:
    """The reason this step ended its episode on a numerical fault, or None."""
    return info.get(FAULT_KEY)


def fault_line(seed: int, length: int, reason: str) -> str:
    """One faults.log line: the episode's reset seed (to replay it), its length and the reason."""
    return f"seed={seed} length={length}: {reason}"


def write_faults_log(run_dir: Path, lines: list[str]) -> None:
    """faults.log in `run_dir` with one line per faulted episode (no file when none faulted)."""
    path = Path(run_dir) / FAULTS_LOG
    if lines:
        atomic_write_text(path, "".join(f"{line}\n" for line in lines))
    else:
        path.unlink(missing_ok=True)
