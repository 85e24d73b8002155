"""EMG in: raw surface EMG from a CSV file as muscle activation envelopes in [0, 1], the signal a
synergy analysis of recorded muscles starts from (`motorlab synergies import-emg`).

The envelope is the field's linear envelope: band-pass, full-wave rectify, low-pass, each filter a
Butterworth run forward and backward (`scipy.signal.sosfiltfilt`: zero phase, so no muscle's envelope
lags another's), within each trial only (a filter run across a trial boundary would smear one trial's
end into the next's start). Each muscle is then divided by its largest envelope value, or by its MVC
(maximum voluntary contraction) envelope value where one is given.

The CSV: a header row naming one column per muscle, then one row per sample at one rate; an optional
column named `trial` gives each row's trial (whole numbers, each trial's rows together; without it
the recording is one trial), and a column named `time` (time stamps, as exports often begin with) is
ignored: the rate is the one given. Everything a user can get wrong is refused in one line naming it and the
fix (`MotorlabError`)."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from motorlab.errors import MotorlabError

if TYPE_CHECKING:
    import pandas as pd

# Band-pass corners, Hz. Surface EMG's power lies between ~20 and ~450 Hz: below 20 Hz are movement
# artefacts and cable motion (De Luca et al. 2010, J Biomech 43:1573, recommend a 20 Hz high-pass corner),
# above ~450 Hz little but noise (SENIAM's recommendations, Hermens et al. 2000, band-limit to 10-500 Hz).
BAND = (20.0, 450.0)
# Envelope low-pass cut-off, Hz. Synergy studies smooth the rectified EMG at a few Hz (4-10 Hz envelopes
# are usual; musclesyneRgies, for fast locomotion, uses 20 Hz): 6 Hz follows a muscle's activation, not
# its single motor-unit potentials.
LOWPASS = 6.0
# Butterworth order of each filter (the common choice); run forward and backward, its effective order doubles.
ORDER = 4
# Envelope rate after the low-pass, Hz. A 6 Hz envelope has almost nothing left above ~20 Hz (the
# 4th-order filter, run twice, is down by ~150 dB at 50 Hz), so 100 Hz samples lose nothing of it while
# a 2 kHz recording becomes 20 times fewer samples: synergy fits and their cross-validation scale with them.
DOWNSAMPLE = 100.0
TRIAL_COLUMN = "trial"  # the optional column of each row's trial index (in any case)
TIME_COLUMN = "time"  # an optional column of time stamps (in any case), ignored: --rate gives the rate


@dataclass(frozen=True)
class EnvelopeFilters:
    """How the envelope is made: band-pass corners and low-pass cut-off (Hz), each a Butterworth of
    `order` run forward and backward; `downsample`: the envelope's rate afterwards (Hz; None, or a rate
    at or above the recording's, keeps every sample: nothing is upsampled)."""

    band: tuple[float, float] = BAND
    lowpass: float = LOWPASS
    order: int = ORDER
    downsample: float | None = DOWNSAMPLE


@dataclass(frozen=True)
class EmgRecording:
    """Raw EMG as read from a CSV: `emg` (samples, muscles) float64, `trial` (samples,) each row's trial
    label as the file gives it, `names` one per muscle column."""

    emg: np.ndarray = field(repr=False)
    trial: np.ndarray = field(repr=False)
    names: tuple[str, ...]
    source: str = ""


@dataclass(frozen=True, eq=False)
class EmgEnvelopes:
    """Normalized EMG envelopes: what `synergies import-emg` writes as activations.npz.

    Attributes:
        activations: (samples, muscles) float64 in [0, 1], at `rate`.
        episode: (samples,) each sample's trial, numbered 0, 1, ... in the file's order.
        names: each column's muscle name.
        rate: the envelopes' rate, Hz (after downsampling).
        recorded_rate: the recording's rate, Hz.
        recorded_samples: the recording's rows.
        filters: the filters that made the envelope.
        normalization: "max" (each muscle over its largest envelope value) or "mvc".
        scale: (muscles,) what each muscle's envelope was divided by (in the recording's units).
        trials: the file's trial label of each episode index.
        clipped: envelope values outside [0, 1] set to the nearest bound: above an MVC, or the
            low-pass filter's small undershoot below 0.
    """

    activations: np.ndarray = field(repr=False)
    episode: np.ndarray = field(repr=False)
    names: tuple[str, ...]
    rate: float
    recorded_rate: float
    recorded_samples: int
    filters: EnvelopeFilters
    normalization: str
    scale: np.ndarray = field(repr=False)
    trials: tuple[int, ...]
    clipped: int


def import_emg(path: Path | str, rate: float, filters: EnvelopeFilters = EnvelopeFilters(),
               mvc: Path | str | None = None) -> EmgEnvelopes:
    """The normalized envelopes of the raw EMG in the CSV at `path`, recorded at `rate` Hz; `mvc`: a CSV
    with the same header and one row of each muscle's MVC envelope value (default: each muscle's maximum).

    Raises:
        MotorlabError: a bad rate or filter, an unreadable or malformed file (see `read_emg_csv`,
            `read_mvc`), too few samples in a trial for the filters.
    """
    check_filters(rate, filters)
    recording = read_emg_csv(Path(path))
    mvc_values = None if mvc is None else read_mvc(Path(mvc), recording.names, Path(path))
    return envelopes(recording, rate, filters, mvc_values)


def check_filters(rate: float, filters: EnvelopeFilters) -> None:
    """Refuse filters the rate cannot carry: every corner must lie below the Nyquist frequency (rate / 2).

    Raises:
        MotorlabError: naming the rate needed or the setting to give.
    """
    low, high = filters.band
    if not (np.isfinite(rate) and rate > 0):
        raise MotorlabError(f"--rate {rate:g}: give the recording's sampling rate in Hz, a positive number.")
    if not 0 < low < high:
        raise MotorlabError(f"--band {low:g},{high:g}: give LOW,HIGH in Hz with 0 < LOW < HIGH, e.g. --band 20,450.")
    if filters.lowpass <= 0 or filters.order < 1:
        raise MotorlabError(f"--lowpass {filters.lowpass:g} (order {filters.order}): give a cut-off above 0 Hz.")
    nyquist = rate / 2
    if high >= nyquist:
        fit = 0.9 * nyquist
        fix = f"give --band {low:g},{fit:g} (below half the rate)" if fit > low else "record at a higher rate"
        raise MotorlabError(f"--rate {rate:g} Hz is not above twice the band's upper edge ({high:g} Hz), so the "
                            f"band-pass cannot be made: give the recording's true rate if it is above {2 * high:g} Hz, "
                            f"or {fix}.")
    if filters.lowpass >= nyquist:
        raise MotorlabError(f"--lowpass {filters.lowpass:g} Hz is not below half the rate ({nyquist:g} Hz); "
                            f"give a lower --lowpass, e.g. {LOWPASS:g}.")
    if filters.downsample is not None and filters.downsample < 2 * filters.lowpass:
        raise MotorlabError(f"--downsample {filters.downsample:g} Hz is below twice the low-pass cut-off "
                            f"({filters.lowpass:g} Hz), so the envelope would alias; give --downsample "
                            f"{2 * filters.lowpass:g} or more (e.g. {DOWNSAMPLE:g}).")


def read_emg_csv(path: Path) -> EmgRecording:
    """Raw EMG from a CSV: a header naming each muscle's column (and optionally `trial`, `time`), a row per sample.

    Raises:
        MotorlabError: missing or unreadable file, no header, empty or duplicate column names, no muscle
            column, no rows, a cell that is not a number, NaN or infinity (its column and first row), a
            constant column, trial labels that are not whole numbers or whose rows are not together.
    """
    names, frame = _read_table(path, "the raw EMG", f"write a header row naming each muscle's column, e.g. "
                               f"`{TRIAL_COLUMN},TA,SOL,GM`, then one row of samples per time step")
    trial_column = next((n for n in names if n.lower() == TRIAL_COLUMN), None)
    muscles = tuple(n for n in names if not _bookkeeping(n))
    if not muscles:
        raise MotorlabError(f"{path} has no muscle columns (only {', '.join(map(repr, names))}); add one column of "
                            "raw EMG per muscle, named in the header.")
    emg = frame[list(muscles)].to_numpy(dtype=np.float64)
    flat = np.ptp(emg, axis=0) == 0
    if flat.any():
        i = int(np.argmax(flat))
        raise MotorlabError(f"{path}: column {muscles[i]!r} is constant ({emg[0, i]:g} in every row), so it has no "
                            "EMG to make an envelope of; remove the column (an unplugged or saturated electrode?).")
    if trial_column is None:
        return EmgRecording(emg, np.zeros(len(emg), dtype=np.int64), muscles, str(path))
    trial = frame[trial_column].to_numpy(dtype=np.float64)
    if np.any(trial != np.round(trial)):
        i = int(np.argmax(trial != np.round(trial)))
        raise MotorlabError(f"{path}: the {trial_column!r} column holds {trial[i]:g} {_at(i)}; label each row's "
                            "trial with a whole number.")
    trial = trial.astype(np.int64)
    labels, bounds = _trials(trial)
    seen: set[int] = set()
    for label, start in zip(labels, bounds):
        if label in seen:
            raise MotorlabError(f"{path}: trial {label}'s rows are not together (it starts again {_at(start)}); "
                                "sort the rows by trial, each trial's samples in time order.")
        seen.add(int(label))
    return EmgRecording(emg, trial, muscles, str(path))


def read_mvc(path: Path, names: tuple[str, ...], emg_path: Path | None = None) -> np.ndarray:
    """Each muscle's MVC envelope value, in the order of `names`, from a CSV with one header naming the
    same muscles (in any order; `trial` and `time` columns are ignored) and one row of values, in the units of the
    EMG's envelope (the raw EMG's units, band-passed, rectified and low-passed alike).

    Raises:
        MotorlabError: the file is missing or malformed, its names differ from `names` (naming those that
            differ), it has not exactly one row, or a value is not above 0.
    """
    header, frame = _read_table(path, "MVC values", "write the EMG file's header, then one row with each "
                                "muscle's MVC envelope value")
    given = [n for n in header if not _bookkeeping(n)]
    if set(given) != set(names):
        missing = [n for n in names if n not in given]
        extra = [n for n in given if n not in names]
        said = "; ".join(part for part in (f"missing {', '.join(missing)}" if missing else "",
                                           f"not in the EMG {', '.join(extra)}" if extra else "") if part)
        raise MotorlabError(f"{path} names other muscles than {emg_path or 'the EMG file'} ({said}); give one MVC "
                            "value per muscle under the EMG file's names.")
    if len(frame) != 1:
        raise MotorlabError(f"{path} has {len(frame)} rows of values; give exactly one: each muscle's MVC envelope "
                            "value.")
    values = frame[list(names)].to_numpy(dtype=np.float64)[0]
    if np.any(values <= 0):
        i = int(np.argmax(values <= 0))
        raise MotorlabError(f"{path}: the MVC value of {names[i]!r} is {values[i]:g}; an MVC envelope value must "
                            "be above 0 (the envelope of that muscle's maximum voluntary contraction).")
    return values


def envelopes(recording: EmgRecording, rate: float, filters: EnvelopeFilters = EnvelopeFilters(),
              mvc: np.ndarray | None = None) -> EmgEnvelopes:
    """The normalized envelopes of `recording` (see the module's docstring), trial by trial.

    Raises:
        MotorlabError: filters the rate cannot carry, a trial too short for them, a muscle with no
            envelope to normalize by.
    """
    from scipy.signal import butter, sosfiltfilt

    check_filters(rate, filters)
    band = butter(filters.order, filters.band, btype="bandpass", fs=rate, output="sos")
    smooth = butter(filters.order, filters.lowpass, btype="lowpass", fs=rate, output="sos")
    pad = max(_padlen(band), _padlen(smooth))
    labels, bounds = _trials(recording.trial)
    lengths = np.diff(bounds)
    if lengths.min() <= pad:
        k = int(np.argmin(lengths))
        which = "the recording" if len(labels) == 1 else f"trial {labels[k]}"
        raise MotorlabError(f"{recording.source or 'the EMG'}: {which} has {lengths[k]} samples, too few for the "
                            f"filters, which need at least {pad + 1} per trial (scipy's sosfiltfilt pads "
                            f"{pad}); record longer trials, or join or drop the short ones.")
    out_rate = rate if filters.downsample is None else min(rate, float(filters.downsample))
    parts, episode = [], []
    for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        # zero phase both times; the rectified signal's own mean is its envelope, so it is not removed
        env = sosfiltfilt(smooth, np.abs(sosfiltfilt(band, recording.emg[a:b], axis=0, padlen=pad)), axis=0,
                          padlen=pad)
        env = _resample(env, rate, out_rate)
        parts.append(env)
        episode.append(np.full(len(env), k, dtype=np.int64))
    env = np.concatenate(parts)
    scale = env.max(axis=0) if mvc is None else np.asarray(mvc, dtype=np.float64)
    if np.any(scale <= 0):
        i = int(np.argmax(scale <= 0))
        raise MotorlabError(f"{recording.source or 'the EMG'}: column {recording.names[i]!r} has no EMG in the "
                            f"{filters.band[0]:g}-{filters.band[1]:g} Hz band; remove it or widen --band.")
    scaled = env / scale
    activations = np.clip(scaled, 0.0, 1.0)
    return EmgEnvelopes(activations=activations, episode=np.concatenate(episode), names=recording.names,
                        rate=out_rate, recorded_rate=float(rate), recorded_samples=len(recording.emg),
                        filters=filters, normalization="max" if mvc is None else "mvc", scale=scale,
                        trials=tuple(int(t) for t in labels), clipped=int(np.sum(activations != scaled)))


def _padlen(sos: np.ndarray) -> int:
    """The padding scipy's sosfiltfilt uses by default (its `padlen=None`), given explicitly so that the
    samples a trial needs (more than this) are known before filtering."""
    taps = 2 * len(sos) + 1 - min(int(np.sum(sos[:, 2] == 0)), int(np.sum(sos[:, 5] == 0)))
    return 3 * taps


def _trials(trial: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each trial's label and the row bounds of its rows (rows of one trial are together)."""
    starts = np.flatnonzero(np.diff(trial)) + 1
    bounds = np.concatenate(([0], starts, [len(trial)]))
    return trial[bounds[:-1]], bounds


def _resample(x: np.ndarray, rate: float, new: float) -> np.ndarray:
    """`x` (samples, muscles) sampled at `rate` Hz, at `new` Hz (<= rate) by linear interpolation: the
    envelope's low-pass is the anti-aliasing filter, and at the recording's rate (above twice the band,
    so ~100 samples per period of a 6 Hz envelope) linear interpolation between its samples errs by
    less than 1e-3 of the envelope's range; at a whole ratio (2000 -> 100 Hz) it picks samples."""
    if new >= rate:
        return x
    t = np.arange(len(x)) / rate
    t_new = np.arange(int(np.floor(t[-1] * new)) + 1) / new
    return np.stack([np.interp(t_new, t, column) for column in x.T], axis=1)


def _read_table(path: Path, what: str, layout: str) -> tuple[list[str], pd.DataFrame]:
    """A CSV's header (names stripped of spaces) and its rows as a pandas DataFrame of numbers.

    Raises:
        MotorlabError: see `read_emg_csv`.
    """
    import pandas as pd

    if not path.is_file():
        raise MotorlabError(f"{path} {'is a folder' if path.is_dir() else 'does not exist'}; give the CSV file of "
                            f"{what}.")
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:  # utf-8-sig: a spreadsheet's byte-order mark
            header = next(csv.reader(f), None)
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise MotorlabError(f"{path} cannot be read as a CSV text file ({e}); give a CSV of {what}.") from None
    if header is None or not any(h.strip() for h in header):
        raise MotorlabError(f"{path} is empty; {layout}.")
    names = [h.strip() for h in header]
    if all(_number(n) for n in names if n):
        raise MotorlabError(f"{path} has no header row (its first line holds numbers); {layout}.")
    if "" in names:
        raise MotorlabError(f"{path}: column {names.index('') + 1} of the header has no name; name every column "
                            "(each muscle's, and `trial` if there is one).")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise MotorlabError(f"{path}: the header names {', '.join(map(repr, twice))} more than once; give each "
                            "column its own name.")
    try:
        frame = pd.read_csv(path, header=0, names=names, index_col=False, skipinitialspace=True,
                            encoding="utf-8-sig")
    except (pd.errors.ParserError, ValueError, OSError) as e:
        raise MotorlabError(f"{path} is not a CSV of {what} ({str(e).strip() or type(e).__name__}); give every "
                            "row one value per header column.") from None
    if frame.empty:
        raise MotorlabError(f"{path} has a header but no rows of samples; {layout}.")
    for name in names:
        column = frame[name]
        numbers = pd.to_numeric(column, errors="coerce").to_numpy(dtype=np.float64)
        text = np.asarray(column.notna()) & np.isnan(numbers)
        if text.any():
            i = int(np.argmax(text))
            raise MotorlabError(f"{path}: column {name!r} holds {str(column.iloc[i]).strip()!r} {_at(i)}, not "
                                "a number; every cell below the header must be a number.")
        if np.isnan(numbers).any():
            i = int(np.argmax(np.isnan(numbers)))
            raise MotorlabError(f"{path}: column {name!r} has a missing value (empty or NaN), first {_at(i)}; "
                                "fill the gaps (interpolate) or cut those rows out before importing.")
        if np.isinf(numbers).any():
            i = int(np.argmax(np.isinf(numbers)))
            raise MotorlabError(f"{path}: column {name!r} holds an infinite value {_at(i)}; give finite "
                                "numbers.")
        frame[name] = numbers
    return names, frame


def _bookkeeping(name: str) -> bool:
    """A column of the trial index or of time stamps, not a muscle's."""
    return name.lower() in (TRIAL_COLUMN, TIME_COLUMN)


def _at(i: int) -> str:
    """Where the data row of index `i` is, as a user finds it in the file."""
    return f"at row {i + 1} below the header"


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
