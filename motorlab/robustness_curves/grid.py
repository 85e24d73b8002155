"""`--vary KEY=START:STOP:N` (N evenly spaced values) or `--vary KEY=V1,V2,...`: the disturbance
grid of a robustness run. Each axis is varied on its own, the others at the policy's own settings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motorlab.errors import MotorlabError, did_you_mean

# What can be varied: the env setting it sets, and how a reader calls it (with its unit).
VARIABLES: dict[str, str] = {
    "delay": "delay time constant (s)",
    "latency": "latency (steps)",
    "obs_noise": "observation noise std",
    "action_noise": "action noise std",
    "push_force": "push force (N)",
    "motor_noise": "motor noise (x van Beers 2004)",
}
EXAMPLE = "delay=0:0.3:7 or obs-noise=0,0.01,0.02"


@dataclass(frozen=True)
class Axis:
    """One disturbance and the values it takes, smallest first."""

    key: str  # an EnvConfig field, e.g. "obs_noise"
    values: tuple[float, ...]

    @property
    def label(self) -> str:
        return VARIABLES[self.key]

    def env_value(self, value: float):
        """The env setting for one grid value: no wrapper at all for zero delay or latency."""
        if self.key == "latency":
            return int(value) or None
        if self.key in ("delay", "obs_noise", "action_noise", "motor_noise") and value == 0:
            return None
        return float(value)


def parse_axis(spec: str) -> Axis:
    """One `--vary` value as an Axis.

    Raises:
        MotorlabError: no "=", an unknown key (with close matches), bad numbers, negative or
            (latency) fractional values, fewer than two values.
    """
    key, sep, values = spec.partition("=")
    key = key.strip().replace("-", "_")
    if not sep or not key or not values.strip():
        raise MotorlabError(f"--vary {spec!r}: write KEY=START:STOP:N or KEY=V1,V2,..., e.g. {EXAMPLE}.")
    if key not in VARIABLES:
        names = ", ".join(k.replace("_", "-") for k in VARIABLES)
        raise MotorlabError(f"--vary {spec!r}: cannot vary {key.replace('_', '-')!r}"
                            f"{did_you_mean(key, VARIABLES)}; it varies {names}.")
    try:
        if ":" in values:
            start, stop, n = values.split(":")
            if int(n) < 2:
                raise ValueError
            grid = np.linspace(float(start), float(stop), int(n))
        else:
            grid = np.array([float(v) for v in values.split(",") if v.strip()])
    except ValueError:
        raise MotorlabError(f"--vary {spec!r}: write START:STOP:N with N >= 2 (e.g. 0:0.3:7) or numbers "
                            "separated by commas.") from None
    if len(grid) < 2 or not np.all(np.isfinite(grid)) or np.any(grid < 0):
        raise MotorlabError(f"--vary {spec!r}: give at least two values, all zero or more, e.g. {EXAMPLE}.")
    if key == "latency" and not np.allclose(grid, np.round(grid)):
        raise MotorlabError(f"--vary {spec!r}: latency counts whole steps; give e.g. latency=0:4:5.")
    grid = np.unique(np.round(grid, 12))
    return Axis(key, tuple(float(v) for v in grid))


def parse_axes(specs: list[str]) -> list[Axis]:
    """Every `--vary`, each key once."""
    axes = [parse_axis(s) for s in specs]
    keys = [a.key for a in axes]
    if len(set(keys)) < len(keys):
        twice = next(k for k in keys if keys.count(k) > 1)
        raise MotorlabError(f"--vary names {twice.replace('_', '-')} twice; give each disturbance once.")
    return axes
