"""Identification logs: Roboat II §VI-B's experiment simulated, and the folder format that holds it.

Roboat II §VI-B identifies ξ from five trials of about 150 s in which Roboat II was
remote-controlled
through sinusoidal motions coupling surge, sway and yaw, with the thrust and the velocity
recorded at 10 Hz. :func:`simulate_experiment` reproduces that experiment with a known ξ; its
output, or a real recording, is kept on disk as an *identification log*:

    LOG/meta.json      {"format": "usvdrake-identification-log", "version": 1,
                        "vessel": "roboat2", "rate_hz": 10.0,
                        "noise_std": {"u": 0.02, "v": 0.02, "r": 0.01, "thrust": 1.0},
                        "trials": ["trial_01.csv", ...], "seed": 0 | null,
                        "true_xi": {"m11": 172.0, ...} | null, "units": {...}}
    LOG/trial_01.csv   # comment lines (units, vessel), then the header and one row per sample
                       t,f1,f2,f3,f4,u,v,r
                       0.000,12.3,...

Columns: t [s] since the trial's start; f1..fn [N] the recorded force of each (fixed) thruster in
the vessel file's order; u, v [m/s] and r [rad/s] the measured body velocities (x forward,
y left, z up). ``noise_std`` are the measurement standard deviations (u, v [m/s], r [rad/s],
thrust [N]) from which the identification takes its default weight; ``true_xi`` is known only
for simulated logs.

The simulated experiment (our choices, Roboat II gives no more detail):

* the operator's sticks command a surge force, a sway force and a yaw moment, each a sum of three
  sinusoids (0.01-0.15 Hz, around the vessel's time constants m/d ≈ 1-5 s) with phases and a
  ±15 % frequency jitter drawn per trial; the surge force has a forward offset so the vessel
  makes way (≈ 0.5 m/s) and the Coriolis coupling of eq. (5) is excited;
* the thrusters receive the minimum-norm allocation f = B⁺ τ_cmd (B of Roboat II eq. 3 from
  ``configuration_matrix``), clipped to their limits (±50 N for Roboat II, eq. 14), and hold each
  command for one sample (the 10 Hz radio link); thruster dynamics are neglected;
* the vessel, starting at rest, follows eqs. (1)-(6) with the true ξ, integrated by RK4 at 0.01 s;
* the log holds the commanded forces plus N(0, 1 N²) (σ_f² = 1 of Roboat II eq. 16) and the true
  velocities plus white noise with σ_u = σ_v = 0.02 m/s (our choice: a GPS/SLAM-derived velocity)
  and σ_r = 0.01 rad/s (σ_r² = 0.0001 of Roboat II eq. 16).

Random numbers come from ``random_streams.generator(seed, stream, trial)``: stream 401 the
excitation, 402 the velocity noise, 403 the thrust noise.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usvdrake.random_streams import generator
from usvdrake.systems.vessel.thrusters import configuration_matrix
from usvdrake.systems.vessel.vessel_discrete import rk4
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import Hydrodynamics, VesselParams, load_vessel

LOG_FORMAT = "usvdrake-identification-log"
LOG_VERSION = 1
XI_NAMES = ("m11", "m22", "m33", "Xu", "Yv", "Nr")
XI_UNITS = ("kg", "kg", "kg m^2", "kg/s", "kg/s", "kg m^2/s")
VELOCITY_NAMES = ("u", "v", "r")
VELOCITY_UNITS = ("m/s", "m/s", "rad/s")
EXCITATION_STREAM, VELOCITY_NOISE_STREAM, THRUST_NOISE_STREAM = 401, 402, 403


class LogFormatError(ConfigError):
    """A malformed identification log; one line: file, where, what was expected, what was found."""

    def __init__(self, file: str | Path, where: str, expected: str, got: str):
        super().__init__(file, where, expected, got)
        self.args = (f"{file}: {where}: expected {expected}, got {got}",)


@dataclass
class Trial:
    """One recorded trial, sampled at the log's rate."""

    t: np.ndarray  # [s] (T,) sample times, strictly increasing
    thrust: np.ndarray  # [N] (T, n) recorded thruster forces, held until the next sample
    nu: np.ndarray  # (T, 3) measured [u v r] in [m/s, m/s, rad/s]


@dataclass
class IdentificationLog:
    """An identification log in memory (see the module docstring for the folder format)."""

    vessel: str  # vessel name or YAML path, for the thruster layout B
    rate_hz: float  # [Hz] nominal sample rate
    velocity_std: tuple[float, float, float]  # [m/s, m/s, rad/s] noise std of u, v, r
    thrust_std: float  # [N] noise std of each recorded thruster force
    trials: list[Trial] = field(default_factory=list)
    seed: int | None = None  # seed of a simulated log, None for a recording
    true_xi: Hydrodynamics | None = None  # the ξ a simulated log was made with


@dataclass
class ExcitationExperiment:
    """Settings of the simulated Roboat II §VI-B experiment (defaults: Roboat II, Roboat II's
    numbers)."""

    trials: int = 5  # number of trials (Roboat II: five)
    duration_s: float = 150.0  # [s] nominal trial length (Roboat II: around 150 s)
    duration_jitter: float = 0.03  # each trial lasts duration_s × U(1 − j, 1 + j)
    rate_hz: float = 10.0  # [Hz] recording rate (Roboat II: 10 Hz)
    integration_step_s: float = 0.01  # [s] RK4 step of the true motion (divides 1 / rate_hz)
    surge_offset_n: float = 20.0  # [N] mean surge force (makes way at ≈ Xu⁻¹ · 20 N)
    # [N], [N], [N m] amplitudes and [Hz] base frequencies of the three sinusoids per channel
    surge_amplitudes_n: list[float] = field(default_factory=lambda: [18.0, 12.0, 8.0])
    surge_frequencies_hz: list[float] = field(default_factory=lambda: [0.013, 0.031, 0.071])
    sway_amplitudes_n: list[float] = field(default_factory=lambda: [18.0, 12.0, 8.0])
    sway_frequencies_hz: list[float] = field(default_factory=lambda: [0.019, 0.047, 0.11])
    yaw_amplitudes_nm: list[float] = field(default_factory=lambda: [4.0, 3.0, 2.0])
    yaw_frequencies_hz: list[float] = field(default_factory=lambda: [0.023, 0.059, 0.13])
    frequency_jitter: float = 0.15  # each frequency × U(1 − j, 1 + j) per trial
    velocity_std: tuple[float, float, float] = (0.02, 0.02, 0.01)  # [m/s, m/s, rad/s] u, v, r
    thrust_std: float = 1.0  # [N] recorded-force noise (Roboat II eq. 16: σ_f² = 1)


def fixed_thruster_matrix(vessel: VesselParams, where: str | Path = "vessel") -> np.ndarray:
    """B (3 × n) with τ = B f for a vessel whose thrusters all have fixed directions (Roboat II eq.
    3).

    A log stores one force per thruster, which fixes τ only when no thruster is azimuthing."""
    if any(t.azimuth for t in vessel.thrusters):
        raise ConfigError(
            where, "thrusters", "fixed thrusters only (a log holds one force each)", "an azimuth"
        )
    return configuration_matrix(vessel.thrusters)


def _commanded_forces(
    exp: ExcitationExperiment, vessel: VesselParams, t: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Thruster forces [N] (T, n): the sticks' sinusoids mixed by B⁺ and clipped to the limits."""
    channels = (
        (exp.surge_amplitudes_n, exp.surge_frequencies_hz, exp.surge_offset_n),
        (exp.sway_amplitudes_n, exp.sway_frequencies_hz, 0.0),
        (exp.yaw_amplitudes_nm, exp.yaw_frequencies_hz, 0.0),
    )
    tau = np.zeros((len(t), 3))
    for i, (amplitudes, frequencies, offset) in enumerate(channels):
        tau[:, i] = offset
        for a, f in zip(amplitudes, frequencies, strict=True):
            f_trial = f * rng.uniform(1 - exp.frequency_jitter, 1 + exp.frequency_jitter)
            tau[:, i] += a * np.sin(2 * np.pi * f_trial * t + rng.uniform(0, 2 * np.pi))
    b = fixed_thruster_matrix(vessel)
    forces = tau @ np.linalg.pinv(b).T
    lo = np.array([th.min_force for th in vessel.thrusters])
    hi = np.array([th.max_force for th in vessel.thrusters])
    return np.clip(forces, lo, hi)


def simulate_experiment(
    vessel: VesselParams,
    seed: int = 0,
    experiment: ExcitationExperiment | None = None,
    xi: Hydrodynamics | None = None,
) -> IdentificationLog:
    """The simulated Roboat II §VI-B data set for ``vessel`` (true ξ: ``xi`` or the vessel file's).

    All trials are integrated together as one batch of ``vessel_discrete.rk4`` (eqs. 1-6, still
    water) at ``integration_step_s`` with each command held for one sample period."""
    exp = experiment if experiment is not None else ExcitationExperiment()
    xi = xi if xi is not None else vessel.hydrodynamics
    sample = 1.0 / exp.rate_hz
    substeps = round(sample / exp.integration_step_s)
    if substeps < 1 or abs(substeps * exp.integration_step_s - sample) > 1e-9:
        raise ConfigError(
            "experiment",
            "integration_step_s",
            f"a divisor of the sample period {sample} s",
            exp.integration_step_s,
        )
    lengths, forces = [], []
    for k in range(exp.trials):
        rng = generator(seed, EXCITATION_STREAM, k)
        jitter = rng.uniform(1 - exp.duration_jitter, 1 + exp.duration_jitter)
        lengths.append(int(round(exp.duration_s * jitter * exp.rate_hz)) + 1)
        forces.append(_commanded_forces(exp, vessel, np.arange(lengths[-1]) * sample, rng))
    t_max = np.arange(max(lengths)) * sample
    # Shorter trials are padded with zero force; the padding is cut off again below.
    forces = np.stack([np.pad(f, ((0, len(t_max) - len(f)), (0, 0))) for f in forces])
    tau = forces @ fixed_thruster_matrix(vessel).T  # (trials, T, 3)

    q = np.zeros((exp.trials, 6))  # at rest at the origin
    nu_true = np.empty((exp.trials, len(t_max), 3))
    nu_true[:, 0] = q[:, 3:]
    for i in range(len(t_max) - 1):
        for _ in range(substeps):
            q = rk4(xi, q, tau[:, i], exp.integration_step_s)
        nu_true[:, i + 1] = q[:, 3:]

    trials = []
    for k, n in enumerate(lengths):
        v_noise = generator(seed, VELOCITY_NOISE_STREAM, k).standard_normal((n, 3))
        f_noise = generator(seed, THRUST_NOISE_STREAM, k).standard_normal((n, forces.shape[2]))
        trials.append(
            Trial(
                t=t_max[:n].copy(),
                thrust=forces[k, :n] + exp.thrust_std * f_noise,
                nu=nu_true[k, :n] + np.asarray(exp.velocity_std) * v_noise,
            )
        )
    return IdentificationLog(
        vessel=vessel.name,
        rate_hz=exp.rate_hz,
        velocity_std=tuple(float(s) for s in exp.velocity_std),
        thrust_std=float(exp.thrust_std),
        trials=trials,
        seed=seed,
        true_xi=dataclasses.replace(xi),
    )


# --- the folder format -------------------------------------------------------------------------


def trial_file_name(k: int) -> str:
    """File name of the k-th trial (0-based): trial_01.csv, trial_02.csv, ..."""
    return f"trial_{k + 1:02d}.csv"


def _columns(n_thrusters: int) -> list[str]:
    return ["t", *(f"f{i + 1}" for i in range(n_thrusters)), *VELOCITY_NAMES]


def write_log(log: IdentificationLog, folder: str | Path) -> Path:
    """Write ``log`` as FOLDER/meta.json and FOLDER/trial_NN.csv; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for k, trial in enumerate(log.trials):
        n = trial.thrust.shape[1]
        name = trial_file_name(k)
        names.append(name)
        with open(folder / name, "w", newline="") as out:
            out.write(
                f"# usvdrake identification log v{LOG_VERSION}, trial {k + 1}, "
                f"vessel {log.vessel}, {log.rate_hz:g} Hz\n"
                "# t [s] since the trial start; "
                f"f1..f{n} [N] recorded thruster forces in the vessel file's order; "
                "u, v [m/s], r [rad/s] measured body velocities (x forward, y left, z up)\n"
            )
            writer = csv.writer(out, lineterminator="\n")
            writer.writerow(_columns(n))
            for t, f, nu in zip(trial.t, trial.thrust, trial.nu, strict=True):
                writer.writerow([f"{t:.3f}", *(f"{x:.4f}" for x in f), *(f"{x:.6f}" for x in nu)])
    meta = {
        "format": LOG_FORMAT,
        "version": LOG_VERSION,
        "vessel": log.vessel,
        "rate_hz": log.rate_hz,
        "noise_std": dict(
            zip(VELOCITY_NAMES, log.velocity_std, strict=True), thrust=log.thrust_std
        ),
        "trials": names,
        "seed": log.seed,
        "true_xi": dataclasses.asdict(log.true_xi) if log.true_xi is not None else None,
        "units": {
            "t": "s",
            "f": "N",
            **dict(zip(VELOCITY_NAMES, VELOCITY_UNITS, strict=True)),
            **dict(zip(XI_NAMES, XI_UNITS, strict=True)),
        },
    }
    (folder / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return folder


def _positive(file: Path, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise LogFormatError(file, f"key '{key}'", "a positive number", repr(value))
    return float(value)


def _read_meta(folder: Path) -> dict:
    file = folder / "meta.json"
    if not folder.is_dir():
        raise LogFormatError(folder, "folder", "an identification log folder", "no such folder")
    if not file.is_file():
        raise LogFormatError(folder, "meta.json", "the log's metadata file", "no such file")
    try:
        meta = json.loads(file.read_text())
    except json.JSONDecodeError as e:
        raise LogFormatError(file, f"line {e.lineno}", "valid JSON", e.msg) from None
    if not isinstance(meta, dict):
        raise LogFormatError(file, "document", "a JSON object", type(meta).__name__)
    if meta.get("format", LOG_FORMAT) != LOG_FORMAT:
        raise LogFormatError(file, "key 'format'", repr(LOG_FORMAT), repr(meta.get("format")))
    if not isinstance(meta.get("vessel"), str) or not meta["vessel"]:
        raise LogFormatError(file, "key 'vessel'", "a vessel name", repr(meta.get("vessel")))
    noise = meta.get("noise_std")
    if not isinstance(noise, dict):
        raise LogFormatError(file, "key 'noise_std'", "an object with u, v, r, thrust", repr(noise))
    meta["velocity_std"] = tuple(
        _positive(file, f"noise_std.{c}", noise.get(c)) for c in VELOCITY_NAMES
    )
    meta["thrust_std"] = _positive(file, "noise_std.thrust", noise.get("thrust"))
    meta["rate_hz"] = _positive(file, "rate_hz", meta.get("rate_hz"))
    true_xi = meta.get("true_xi")
    if true_xi is not None:
        if not isinstance(true_xi, dict):
            raise LogFormatError(file, "key 'true_xi'", "an object m11..Nr or null", "a value")
        values = {c: _positive(file, f"true_xi.{c}", true_xi.get(c)) for c in XI_NAMES}
        meta["true_xi"] = Hydrodynamics(**values)
    trials = meta.get("trials")
    if trials is None:
        trials = sorted(p.name for p in folder.glob("trial_*.csv"))
    if not isinstance(trials, list) or not trials or not all(isinstance(s, str) for s in trials):
        raise LogFormatError(file, "key 'trials'", "a non-empty list of CSV names", repr(trials))
    meta["trials"] = trials
    return meta


def read_trial(file: str | Path, n_thrusters: int) -> Trial:
    """One trial CSV (``#`` comment lines, the header ``t,f1..fn,u,v,r``, then numbers)."""
    file = Path(file)
    if not file.is_file():
        raise LogFormatError(file.parent, file.name, "a trial CSV", "no such file")
    columns = _columns(n_thrusters)
    header, rows = None, []
    with open(file, newline="") as f:
        for lineno, line in enumerate(f, start=1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            fields = [s.strip() for s in text.split(",")]
            if header is None:
                if fields != columns:
                    raise LogFormatError(
                        file, f"line {lineno}", "the header " + ",".join(columns), repr(text[:60])
                    )
                header = fields
                continue
            if len(fields) != len(columns):
                raise LogFormatError(
                    file,
                    f"line {lineno}",
                    f"{len(columns)} comma-separated numbers ({','.join(columns)})",
                    f"{len(fields)} fields",
                )
            try:
                row = [float(s) for s in fields]
            except ValueError:
                bad = next(s for s in fields if not _is_float(s))
                col = columns[fields.index(bad)]
                raise LogFormatError(
                    file, f"line {lineno}, column {col}", "a number", repr(bad)
                ) from None
            if not np.all(np.isfinite(row)):
                raise LogFormatError(file, f"line {lineno}", "finite numbers", "nan or inf")
            if rows and row[0] <= rows[-1][0]:
                raise LogFormatError(
                    file, f"line {lineno}, column t", f"a time after {rows[-1][0]} s", row[0]
                )
            rows.append(row)
    if header is None:
        raise LogFormatError(file, "header", ",".join(columns), "no header line")
    if len(rows) < 2:
        raise LogFormatError(file, "data", "at least two samples", f"{len(rows)}")
    data = np.array(rows)
    return Trial(t=data[:, 0], thrust=data[:, 1 : 1 + n_thrusters], nu=data[:, 1 + n_thrusters :])


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_log(folder: str | Path, vessel: VesselParams | None = None) -> IdentificationLog:
    """Read a log folder; ``vessel`` (default: the one meta.json names) fixes the column count.

    Raises LogFormatError (a ConfigError) naming the file and line on anything malformed."""
    folder = Path(folder)
    meta = _read_meta(folder)
    if vessel is None:
        try:
            vessel = load_vessel(meta["vessel"])
        except ConfigError as e:
            raise LogFormatError(
                folder / "meta.json", "key 'vessel'", "a known vessel", f"{meta['vessel']!r} ({e})"
            ) from None
    n = fixed_thruster_matrix(vessel, folder / "meta.json").shape[1]
    return IdentificationLog(
        vessel=meta["vessel"],
        rate_hz=meta["rate_hz"],
        velocity_std=meta["velocity_std"],
        thrust_std=meta["thrust_std"],
        trials=[read_trial(folder / name, n) for name in meta["trials"]],
        seed=meta.get("seed"),
        true_xi=meta.get("true_xi"),
    )
