"""A campaign's specification: the TOML file, checked whole before any run starts.

A campaign crosses routes × sensor set-ups × sensor parts (seeds); every run of it is one
co-simulation with all the campaign's estimators in the loop on the same samples. An
estimator entry stands for one estimator, or for one per parameter set of its ``grid``
(every combination) or of its ``random`` samples (drawn with their own seed)::

    name = "tilt and heading"
    routes = ["figure8", "slalom", { route = "my_route.toml", duration_s = 120 }]
    duration_s = 60            # the routes without their own (default: nominal + 10 s)
    parts = 20                 # sensor parts per route and set-up: seeds first_seed, first_seed + 1, ...
    keep = "summaries"         # or "logs": each run's log.csv and summary.json as well

    [[sensors]]                # default: one set-up, profile mpu9250_calibrated
    profile = "mpu9250"        # a built-in profile or a profile file
    registers = [{ dlpf_cfg = 2 }, { dlpf_cfg = 4 }]   # a table, or a list: one set-up each
    gyro_calibration_s = 2

    [[estimators]]
    name = "biso"
    grid = { cutoff_hz = [2.0, 5.0, 10.0] }

    [[estimators]]
    name = "biso_plus"
    random = { samples = 8, seed = 1, params = { tau_bias_s = [20.0, 200.0] } }

    [statistics]
    confidence = 0.95
    resamples = 2000
    baseline = "biso_plus"     # paired comparisons against it (default: every pair)

File paths are relative to the spec file. Every problem raises :class:`SpecError`, one line
naming the file and the field. A run's identity (``RunSpec.run_id``) is a hash of what
determines its result, so a resumed campaign recognises the runs it already has.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = ["SpecError", "CampaignSpec", "RouteEntry", "SensorSetup", "EstimatorEntry", "RunSpec",
           "StatisticsOptions", "load_spec", "parse_spec", "KEEP_CHOICES"]

KEEP_CHOICES = ("summaries", "logs")
_TOP_KEYS = {"name", "routes", "duration_s", "parts", "first_seed", "keep", "sensors", "estimators", "statistics"}
_SENSOR_KEYS = {"profile", "registers", "gyro_calibration_s", "label"}
_ESTIMATOR_KEYS = {"name", "label", "params", "grid", "random"}
_RANDOM_KEYS = {"samples", "seed", "params"}
_STATISTICS_KEYS = {"confidence", "resamples", "seed", "baseline"}
_DEFAULT_PROFILE = "mpu9250_calibrated"  # cosim.DEFAULT_SENSOR_PROFILE, without importing MuJoCo here


class SpecError(ValueError):
    """A campaign specification that cannot run: the message names the file and the field."""


@dataclass(frozen=True)
class RouteEntry:
    """A route of the campaign: a library name, or a route file with its text (a worker
    parses the text, so it needs no access to the file)."""

    route: str  # as the spec names it
    duration_s: float
    text: str | None = None  # a route file's content; None for a library route
    path: str | None = None  # the file's resolved path

    def load(self):
        """The :class:`biso_cosim.routes.Route`."""
        from biso_cosim.routes import load_route, parse_route

        if self.text is None:
            return load_route(self.route)
        return parse_route(tomllib.loads(self.text), source=self.path or self.route)


@dataclass(frozen=True)
class SensorSetup:
    """One MPU-9250 set-up: a profile (built-in name, or a file with its text), register
    values and the start-up gyro calibration."""

    label: str
    profile: str  # as the spec names it
    registers: tuple[tuple[str, Any], ...] = ()
    gyro_calibration_s: float = 0.0
    profile_text: str | None = None  # a profile file's content; None for a built-in profile
    profile_path: str | None = None

    def load_profile(self):
        """What :class:`biso_cosim.cosim.CoSimulation` takes as ``sensor_profile``."""
        from biso_cosim.sensors import Profile

        if self.profile_text is None:
            return self.profile
        path = Path(self.profile_path or self.profile)
        return Profile.from_dict(tomllib.loads(self.profile_text), origin=str(path), default_name=path.stem)


@dataclass(frozen=True)
class EstimatorEntry:
    """One estimator in the loop: registry name, parameter values and its label."""

    label: str
    name: str
    params: tuple[tuple[str, Any], ...] = ()

    def cosim_spec(self):
        """The :class:`biso_cosim.cosim.EstimatorSpec` of this estimator."""
        from biso_cosim.cosim import EstimatorSpec

        return EstimatorSpec(self.name, dict(self.params), label=self.label)


@dataclass(frozen=True)
class StatisticsOptions:
    """Bootstrap and comparison settings of the campaign's statistics."""

    confidence: float = 0.95
    resamples: int = 2000
    seed: int = 0
    baseline: str | None = None  # an estimator label: paired comparisons against it; None: every pair


@dataclass(frozen=True)
class RunSpec:
    """Everything one run needs, and nothing large: what a task carries to a worker."""

    route: RouteEntry
    sensor: SensorSetup
    seed: int
    estimators: tuple[EstimatorEntry, ...]
    log_dir: str | None = None  # where the run writes log.csv and summary.json (keep = "logs")

    @property
    def run_id(self) -> str:
        """A hash of what determines the run's result (not where its log goes)."""
        content = {"route": self.route.route, "route_text": self.route.text, "duration_s": self.route.duration_s,
                   "profile": self.sensor.profile, "profile_text": self.sensor.profile_text,
                   "registers": [list(item) for item in self.sensor.registers],
                   "gyro_calibration_s": self.sensor.gyro_calibration_s, "seed": self.seed,
                   "estimators": [[e.label, e.name, [list(p) for p in e.params]] for e in self.estimators]}
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class CampaignSpec:
    """A checked campaign: its routes, sensor set-ups, parts and estimators (grids expanded)."""

    name: str
    routes: tuple[RouteEntry, ...]
    sensors: tuple[SensorSetup, ...]
    parts: int
    first_seed: int
    estimators: tuple[EstimatorEntry, ...]
    keep: str = "summaries"
    statistics: StatisticsOptions = field(default_factory=StatisticsOptions)
    source: str = "<spec>"

    @property
    def seeds(self) -> range:
        return range(self.first_seed, self.first_seed + self.parts)

    def runs(self, log_root: str | Path | None = None) -> list[RunSpec]:
        """Every run, in the order route, sensor set-up, seed; with ``keep = "logs"`` each
        writes its log under ``log_root/<run_id>``."""
        runs = []
        for route, sensor, seed in itertools.product(self.routes, self.sensors, self.seeds):
            run = RunSpec(route, sensor, seed, self.estimators)
            if self.keep == "logs" and log_root is not None:
                run = RunSpec(route, sensor, seed, self.estimators, str(Path(log_root) / run.run_id))
            runs.append(run)
        return runs

    def canonical(self) -> dict:
        """A JSON-able form that two specs share exactly when they make the same campaign."""
        out = asdict(self)
        out.pop("source")
        return json.loads(json.dumps(out, default=str))


# ---------------------------------------------------------------- parsing
def load_spec(path: str | Path) -> CampaignSpec:
    """Read and check a campaign TOML file."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"campaign spec {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {exc}") from None
    return parse_spec(data, source=str(path), base_dir=path.parent)


def parse_spec(data: Mapping[str, Any], source: str = "<spec>", base_dir: str | Path = ".") -> CampaignSpec:
    """Check a campaign given as the parsed TOML structure; file paths relative to ``base_dir``."""
    base_dir = Path(base_dir)

    def fail(where: str, what: str) -> SpecError:
        return SpecError(f"{source}: {where}: {what}")

    if not isinstance(data, Mapping):
        raise SpecError(f"{source}: expected a table of campaign settings, got {type(data).__name__}")
    _unknown(data, _TOP_KEYS, "", fail)
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name.strip():
        raise fail("name", f"expected a non-empty string, got {name!r}")
    default_duration = data.get("duration_s")
    if default_duration is not None:
        default_duration = _positive_number(default_duration, "duration_s", fail)
    routes = _routes(data.get("routes"), default_duration, base_dir, fail)
    parts = _integer(data.get("parts", 1), "parts", 1, fail)
    first_seed = _integer(data.get("first_seed", 0), "first_seed", 0, fail)
    keep = data.get("keep", "summaries")
    if keep not in KEEP_CHOICES:
        raise fail("keep", f"expected one of {', '.join(map(repr, KEEP_CHOICES))}, got {keep!r}")
    sensors = _sensors(data.get("sensors", [{}]), base_dir, fail)
    estimators = _estimators(data.get("estimators"), sensors, fail)
    statistics = _statistics(data.get("statistics", {}), estimators, fail)
    return CampaignSpec(name=name.strip(), routes=routes, sensors=sensors, parts=parts, first_seed=first_seed,
                        estimators=estimators, keep=keep, statistics=statistics, source=source)


def _unknown(table: Mapping, known: set[str], where: str, fail) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        prefix = f"{where}." if where else ""
        raise fail(f"{prefix}{unknown[0]}", f"unknown key; expected one of {', '.join(sorted(known))}")


def _positive_number(value: Any, where: str, fail) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise fail(where, f"expected a positive number of seconds, got {value!r}")
    return float(value)


def _integer(value: Any, where: str, minimum: int, fail) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise fail(where, f"expected an integer >= {minimum}, got {value!r}")
    return value


def _list(value: Any, where: str, fail) -> list:
    if value is None:
        raise fail(where, "missing; give at least one")
    if not isinstance(value, list):
        raise fail(where, f"expected a list, got {value!r}")
    if not value:
        raise fail(where, "empty list; give at least one")
    return value


def _routes(value: Any, default_duration: float | None, base_dir: Path, fail) -> tuple[RouteEntry, ...]:
    from biso_cosim.routes import load_route, parse_route

    entries = []
    for i, item in enumerate(_list(value, "routes", fail)):
        where = f"routes[{i}]"
        duration = default_duration
        if isinstance(item, Mapping):
            _unknown(item, {"route", "duration_s"}, where, fail)
            if "duration_s" in item:
                duration = _positive_number(item["duration_s"], f"{where}.duration_s", fail)
            item = item.get("route")
            where += ".route"
        if not isinstance(item, str) or not item.strip():
            raise fail(where, f"expected a library route name or a route file, got {item!r}")
        text = path = None
        try:
            if item.endswith(".toml") or "/" in item or "\\" in item:
                file = base_dir / item
                if not file.is_file():
                    raise fail(where, f"route file {str(file)!r} does not exist")
                text, path = file.read_text(), str(file.resolve())
                route = parse_route(tomllib.loads(text), source=str(file))
            else:
                route = load_route(item)
        except (ValueError, TypeError, tomllib.TOMLDecodeError) as exc:
            if isinstance(exc, SpecError):
                raise
            raise fail(where, str(exc)) from None
        if duration is None:  # the co-simulation's default: the nominal duration and 10 s at rest
            duration = float(math.ceil(route.nominal_duration_s + 10.0))
        entries.append(RouteEntry(item, duration, text, path))
    names = [e.route for e in entries]
    if len(set(names)) != len(names):
        raise fail("routes", f"route {next(n for n in names if names.count(n) > 1)!r} named twice")
    return tuple(entries)


def _sensors(value: Any, base_dir: Path, fail) -> tuple[SensorSetup, ...]:
    from biso_cosim.sensors import Profile, Registers

    setups = []
    for i, item in enumerate(_list(value, "sensors", fail)):
        where = f"sensors[{i}]"
        if not isinstance(item, Mapping):
            raise fail(where, f"expected a table (profile, registers, gyro_calibration_s, label), got {item!r}")
        _unknown(item, _SENSOR_KEYS, where, fail)
        profile = item.get("profile", _DEFAULT_PROFILE)
        if not isinstance(profile, str) or not profile.strip():
            raise fail(f"{where}.profile", f"expected a profile name or file, got {profile!r}")
        text = path = None
        try:
            if profile.endswith(".toml") or "/" in profile or "\\" in profile:
                file = base_dir / profile
                if not file.is_file():
                    raise fail(f"{where}.profile", f"profile file {str(file)!r} does not exist")
                text, path = file.read_text(), str(file.resolve())
                Profile.from_dict(tomllib.loads(text), origin=str(file), default_name=file.stem)
            else:
                Profile.load(profile)
        except (ValueError, TypeError, tomllib.TOMLDecodeError) as exc:
            if isinstance(exc, SpecError):
                raise
            raise fail(f"{where}.profile", str(exc)) from None
        calibration = item.get("gyro_calibration_s", 0.0)
        if isinstance(calibration, bool) or not isinstance(calibration, (int, float)) or not 0.0 <= calibration <= 60.0:
            raise fail(f"{where}.gyro_calibration_s", f"expected seconds in [0, 60], got {calibration!r}")
        registers = item.get("registers", {})
        register_sets = registers if isinstance(registers, list) else [registers]
        if not register_sets:
            raise fail(f"{where}.registers", "empty list; give at least one table of register values")
        for j, regs in enumerate(register_sets):
            at = f"{where}.registers" + (f"[{j}]" if isinstance(registers, list) else "")
            if not isinstance(regs, Mapping):
                raise fail(at, f"expected a table of register values, got {regs!r}")
            try:
                Registers.coerce(dict(regs))
            except (ValueError, TypeError) as exc:
                raise fail(at, str(exc)) from None
            values = tuple(sorted(regs.items()))
            label = item.get("label", profile)
            if not isinstance(label, str) or not label.strip():
                raise fail(f"{where}.label", f"expected a non-empty string, got {label!r}")
            if len(register_sets) > 1 or ("label" not in item and values):
                label += "[" + ",".join(f"{k}={_format_value(v)}" for k, v in values) + "]"
            setups.append(SensorSetup(label, profile, values, float(calibration), text, path))
    labels = [s.label for s in setups]
    if len(set(labels)) != len(labels):
        raise fail("sensors", f"two set-ups share the label {next(n for n in labels if labels.count(n) > 1)!r} "
                              f"(give each a label, or different registers)")
    return tuple(setups)


def _format_value(value: Any) -> str:
    return value if isinstance(value, str) else repr(value)


def _param_value(value: Any) -> Any:
    """TOML arrays become tuples (the estimators' vector parameters)."""
    return tuple(_param_value(v) for v in value) if isinstance(value, list) else value


def _estimators(value: Any, sensors: tuple[SensorSetup, ...], fail) -> tuple[EstimatorEntry, ...]:
    from biso_cosim.estimators import make_estimator
    from biso_cosim.sensors import Registers

    rates = sorted({Registers.coerce(dict(s.registers)).output_rate_hz for s in sensors})
    entries: list[EstimatorEntry] = []
    for i, item in enumerate(_list(value, "estimators", fail)):
        where = f"estimators[{i}]"
        if not isinstance(item, Mapping):
            raise fail(where, f"expected a table (name, label, params, grid or random), got {item!r}")
        _unknown(item, _ESTIMATOR_KEYS, where, fail)
        name = item.get("name")
        if not isinstance(name, str) or not name:
            raise fail(f"{where}.name", f"expected an estimator name, got {name!r}")
        label = item.get("label", name)
        if not isinstance(label, str) or not label.strip():
            raise fail(f"{where}.label", f"expected a non-empty string, got {label!r}")
        fixed = item.get("params", {})
        if not isinstance(fixed, Mapping):
            raise fail(f"{where}.params", f"expected a table of parameter values, got {fixed!r}")
        if "grid" in item and "random" in item:
            raise fail(where, "give grid or random, not both")
        if "grid" in item:
            sets = [(f"{label}[" + ",".join(f"{k}={_format_value(v)}" for k, v in values.items()) + "]", values)
                    for values in _grid(item["grid"], f"{where}.grid", fail)]
        elif "random" in item:
            drawn = _random(item["random"], f"{where}.random", fail)
            sets = [(f"{label}#{j}", values) for j, values in enumerate(drawn)]
        else:
            sets = [(label, {})]
        for set_label, values in sets:
            params = {k: _param_value(v) for k, v in (dict(fixed) | values).items()}
            for rate in rates:  # unknown names, unknown parameters and bad values, before any run
                try:
                    make_estimator(name, rate, **params)
                except (ValueError, TypeError) as exc:
                    raise fail(where, f"{set_label}: {exc}") from None
            entries.append(EstimatorEntry(set_label, name, tuple(sorted(params.items()))))
    labels = [e.label for e in entries]
    if len(set(labels)) != len(labels):
        raise fail("estimators", f"label {next(n for n in labels if labels.count(n) > 1)!r} used twice "
                                 f"(give each entry its own label)")
    return tuple(entries)


def _grid(grid: Any, where: str, fail) -> list[dict[str, Any]]:
    if not isinstance(grid, Mapping) or not grid:
        raise fail(where, f"expected a non-empty table of parameter = [values], got {grid!r}")
    axes = []
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise fail(f"{where}.{key}", f"expected a non-empty list of values, got {values!r}")
        axes.append([(key, v) for v in values])
    return [dict(combo) for combo in itertools.product(*axes)]


def _random(random: Any, where: str, fail) -> list[dict[str, Any]]:
    """Parameter sets drawn with the entry's own seed: ``[low, high]`` uniform (integers
    when both ends are), ``{ log = [low, high] }`` log-uniform, ``{ choice = [...] }``."""
    if not isinstance(random, Mapping):
        raise fail(where, f"expected a table (samples, seed, params), got {random!r}")
    _unknown(random, _RANDOM_KEYS, where, fail)
    samples = _integer(random.get("samples"), f"{where}.samples", 1, fail)
    seed = _integer(random.get("seed", 0), f"{where}.seed", 0, fail)
    params = random.get("params")
    if not isinstance(params, Mapping) or not params:
        raise fail(f"{where}.params", f"expected a non-empty table of parameter ranges, got {params!r}")
    draws = []
    for key, rule in params.items():
        at = f"{where}.params.{key}"
        if isinstance(rule, list):
            low, high = _range(rule, at, fail)
            draws.append((key, "int" if all(isinstance(v, int) for v in rule) else "uniform", (low, high)))
        elif isinstance(rule, Mapping) and set(rule) == {"log"}:
            low, high = _range(rule["log"], f"{at}.log", fail)
            if low <= 0:
                raise fail(f"{at}.log", f"expected positive bounds, got {rule['log']!r}")
            draws.append((key, "log", (low, high)))
        elif isinstance(rule, Mapping) and set(rule) == {"choice"}:
            if not isinstance(rule["choice"], list) or not rule["choice"]:
                raise fail(f"{at}.choice", f"expected a non-empty list, got {rule['choice']!r}")
            draws.append((key, "choice", rule["choice"]))
        else:
            raise fail(at, f"expected [low, high], {{ log = [low, high] }} or {{ choice = [...] }}, got {rule!r}")
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(samples):
        values = {}
        for key, kind, arg in draws:
            if kind == "int":
                values[key] = int(rng.integers(arg[0], arg[1] + 1))
            elif kind == "uniform":
                values[key] = float(rng.uniform(arg[0], arg[1]))
            elif kind == "log":
                values[key] = float(math.exp(rng.uniform(math.log(arg[0]), math.log(arg[1]))))
            else:
                values[key] = arg[int(rng.integers(len(arg)))]
        out.append(values)
    return out


def _range(rule: Any, where: str, fail) -> tuple[float, float]:
    if (not isinstance(rule, list) or len(rule) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in rule)
            or rule[0] > rule[1]):
        raise fail(where, f"expected [low, high] with low <= high, got {rule!r}")
    return rule[0], rule[1]


def _statistics(value: Any, estimators: tuple[EstimatorEntry, ...], fail) -> StatisticsOptions:
    if not isinstance(value, Mapping):
        raise fail("statistics", f"expected a table, got {value!r}")
    _unknown(value, _STATISTICS_KEYS, "statistics", fail)
    confidence = value.get("confidence", 0.95)
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) or not 0.0 < confidence < 1.0:
        raise fail("statistics.confidence", f"expected a level in (0, 1), got {confidence!r}")
    resamples = _integer(value.get("resamples", 2000), "statistics.resamples", 100, fail)
    seed = _integer(value.get("seed", 0), "statistics.seed", 0, fail)
    baseline = value.get("baseline")
    labels = [e.label for e in estimators]
    if baseline is not None and baseline not in labels:
        raise fail("statistics.baseline", f"no estimator labelled {baseline!r}; labels: {', '.join(labels)}")
    return StatisticsOptions(float(confidence), resamples, seed, baseline)
