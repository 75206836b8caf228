"""The study configuration (tools/studies/*.toml), validated field by field.

A study runs every method in every scenario on the same trajectory and seeds. A scenario is
what the arm and its drives are like: the model uncertainty (host_sim.uncertainty), the drives'
sensing and torque path (host_sim.drive_model) and whether the buses' bit timing is emulated.
Every method is tuned, per scenario, by the same optimiser with the same trial budget, tuning
seeds and tuning trajectory ([tuning]); the search space of each is [tuning.space.METHOD].
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from gen.lib import toml_input
from gen.lib.escape import EscapeError, file_stem, path_component
from gen.lib.one_line import one_line
from gen.lib.params import param
from host_sim.drive_model import REALISTIC, DriveModel
from host_sim.uncertainty import UncertaintyConfig

# method -> (the firmware's --method, how it is tuned: "design" = LMI synthesis weights,
# "gains" = controller gains, None = not tuned)
METHODS: dict[str, tuple[str, str | None]] = {
    "pm": ("pm", "design"),
    "pm-paper-weights": ("pm", None),  # the paper's own weights (gen/configs/paper.toml), as published
    "pm-paper": ("pm-paper", "design"),
    "gh2": ("gh2", "design"),
    "pd": ("pd", "gains"),
    "tde": ("tde", "gains"),
    "usde-smc": ("usde-smc", "gains"),
}
TUNED = tuple(m for m, (_, how) in METHODS.items() if how is not None)
# The methods that estimate the disturbance: the ones with an estimation error to compare, and the
# synthesised ones whose design has an estimator (gh2's has none).
ESTIMATING = ("pm", "pm-paper-weights", "pm-paper", "tde", "usde-smc")
# The synthesis knobs: the estimator's weight F(s) = f_bw / (s + f_bw) and H, the controller's
# z_o = E1 e + E2 e_dot + D12 u_o ("single") or [E1 e + E2 e_dot; D12 u_o] ("split", which keeps
# the generalized-H2 problem non-degenerate). gh2 has no estimator: only the controller's.
# Both forms depend only on E1/D12 and E2/D12 (scaling z_o scales the norm, not the optimum), so
# the search gives them as a bandwidth and a damping ratio, as every other method's:
# E1/D12 = wn^2, E2/D12 = 2 zeta wn, D12 = 1 (tools/study/design_knobs.py). E1, E2, D12 still name a
# design directly (an older tuning, --knobs).
DESIGN_KNOBS = ("wn", "zeta", "H", "f_bw")
LEGACY_DESIGN_KNOBS = ("E1", "E2", "D12", "H", "f_bw")
# The gain methods, in the same terms: a bandwidth wn and a damping ratio zeta of the PD part.
#   pd:       kp = wn^2, kd = 2 zeta wn
#   tde:      the same PD, and its time-delay estimate low-passed at cutoff_hz
#   usde-smc: u_o = -lambda e_dot - eta sat(s/phi) - ks s, s = e_dot + lambda e: its linear part is a
#             PD with kp = ks lambda, kd = lambda + ks; lambda and ks are the roots of
#             x^2 - 2 zeta wn x + wn^2 (lambda the slower: the sliding surface's bandwidth), which are
#             real only for zeta >= 1: its structure cannot be underdamped, so its zeta range starts
#             at 1 (USDE_SMC_MIN_ZETA). k: the USDE filter's time constant. eta and phi: the
#             controller's defaults (the registry's), not tuned.
GAIN_KNOBS = {"pd": ("wn", "zeta"), "tde": ("wn", "zeta", "cutoff_hz"), "usde-smc": ("wn", "zeta", "k")}
USDE_SMC_MIN_ZETA = 1.0
# A knob's floor where the method's structure ends (widening never goes past it).
KNOB_FLOOR = {("usde-smc", "zeta"): USDE_SMC_MIN_ZETA}
MAX_JOINTS = 16
DRIVE_PRESETS = {"ideal": DriveModel(), "realistic": REALISTIC}

# A scenario's drives speak this unless it says `protocol = "arm"`: CiA 402, what every real drive
# and armctl hil speak, with its units and per-mille torque resolution; its tuning keys leave it out.
STUDY_PROTOCOL = "canopen"
PROTOCOLS = ("arm", "canopen")
# A search range's top may be the arm's first joint resonance (arm.json first_resonance_hz, in
# rad/s): no gain is searched past what the gears let a real arm take, and no widening passes it.
FIRST_RESONANCE = "first_resonance"
# A scenario's payload: "rated" is uniform from 0 to the arm's rated payload (arm.json), per seed.
RATED = "rated"


class StudyConfigError(ValueError):
    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


@dataclass
class Trajectory:
    amp: list[float]
    freq_hz: list[float]
    arm: str | None = None  # the arm (by name, arm.json) these are for; None: any arm given them

    def args(self) -> list[str]:
        return ["--ref-amp", ",".join(f"{a:g}" for a in self.amp), "--ref-freq", ",".join(f"{f:g}" for f in self.freq_hz)]


# The uncertainty's per-joint values (host_sim.uncertainty), and the rules that give them for an
# arm of any joint count: a list is one value per joint; a table is a rule, optionally with lists
# for arms by name (`for_arm`), which take precedence for that arm.
PER_JOINT_FIELDS = ("viscous", "coulomb")
PER_JOINT_RULES = {"each": "the same value for every joint",
                   "torque_limit_fraction": "this fraction of each joint's torque limit (viscous: per rad/s)"}
RULE_HINT = ("give one value per joint, or a rule: { each = x }, { torque_limit_fraction = f }, "
             "optionally with for_arm = { ARM = [...] }")


@dataclass
class Scenario:
    name: str
    description: str
    uncertainty: dict[str, Any]  # without the seed: each run adds its own; per-joint values once for_arm ran
    drives: DriveModel
    bus_timing: bool
    # per-joint fields of the uncertainty as the config gives them (a list or a rule); for_arm()
    # turns them into the arm's values in `uncertainty`, and keeps them here for the report
    per_joint: dict[str, Any] = field(default_factory=dict)
    resolved: bool = False
    protocol: str = STUDY_PROTOCOL  # what the drives speak (tools/run/hil.py PROTOCOLS)

    def as_dict(self) -> dict[str, Any]:
        """The scenario as it runs (what the tuning key and the report hold): only for an arm."""
        if self.per_joint and not self.resolved:
            raise RuntimeError(f"scenario.{self.name}: its per-joint values are for an arm: study_config.for_arm first")
        d = {"name": self.name, "description": self.description, "uncertainty": self.uncertainty,
             "drives": self.drives.to_dict(), "bus_timing": self.bus_timing}
        # only another protocol is recorded: the tuning keys of arm-protocol scenarios stay as they were
        return d if self.protocol == STUDY_PROTOCOL else {**d, "protocol": self.protocol}


@dataclass
class Space:
    """One method's search space: log-uniform ranges, and categorical choices. A range whose top
    is the arm's first resonance is in `to_resonance` until for_arm() makes it a number and a
    ceiling that widening never passes."""
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    choices: dict[str, list[str]] = field(default_factory=dict)
    to_resonance: set[str] = field(default_factory=set)
    ceilings: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        if self.to_resonance:
            raise RuntimeError(f"the range of {sorted(self.to_resonance)} reaches the arm's first resonance: "
                               "study_config.for_arm first")
        return {**{k: list(v) for k, v in self.ranges.items()}, **self.choices}

    def for_resonance(self, omega: float) -> "Space":
        ranges = dict(self.ranges)
        for k in self.to_resonance:
            if not ranges[k][0] < omega:
                raise StudyConfigError(f"tuning.space: {k}'s range [{ranges[k][0]:g}, {FIRST_RESONANCE}] is empty on "
                                       f"this arm, whose first resonance is {omega:g} rad/s")
            ranges[k] = (ranges[k][0], omega)
        return replace(self, ranges=ranges, to_resonance=set(), ceilings={k: omega for k in self.to_resonance})


@dataclass
class StudyConfig:
    path: Path
    description: str
    duration_s: float
    hold_s: float
    seed: int                     # the first seed; --seeds N runs seed .. seed + N - 1
    seeds: int
    methods: list[str]
    scenarios: dict[str, Scenario]
    trajectory: Trajectory
    tuning_seeds: list[int]
    tuning_duration_s: float
    tuning_trajectory: Trajectory
    tuning_objective: str
    cap: int                      # at most this many trials per method and scenario (every round), the same for all
    study_cap: int                # the cap when a study must tune first (study_tuning_cap, never above cap)
    plateau: int                  # converged: the best improved by no more than `tolerance` over this many trials
    tolerance: float              # relative (0.01: 1 %)
    batch: int                    # trials asked of the optimiser at once (at most --jobs)
    widen: int                    # rounds of widening a range whose best value sits at its edge
    startup: int                  # TPE's random trials before it models (per round)
    validation_seeds: list[int]   # a pick must run ok on each (held out: neither tuned on nor the study's)
    validation_tries: int         # the best this many trials are tried in turn on the validation seeds
    robust_stiffness: list[float]  # a pick must also run ok with the gears this stiff (flexible scenarios)
    spaces: dict[str, Space]
    tuning_file: Path             # the tuning record (for the bundled arm; other arms: their build folder)
    raw: dict[str, Any] = field(default_factory=dict)

    def seed_list(self, n: int | None = None) -> list[int]:
        out = [self.seed + i for i in range(n or self.seeds)]
        clash = sorted(set(out) & set(self.tuning_seeds + self.validation_seeds))
        if clash:
            raise StudyConfigError(f"--seeds {len(out)}: seeds {out[0]}..{out[-1]} include tuning seed(s) or "
                                   f"validation seed(s) {clash}; the study never runs on the seeds it was tuned on")
        return out


def _get(d: dict[str, Any], key: str, where: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
    if key not in d:
        if default is not ...:
            return default
        raise StudyConfigError(f"{where}.{key}: missing")
    v = d[key]
    if not isinstance(v, kind) or isinstance(v, bool) and kind is not bool:
        raise StudyConfigError(f"{where}.{key}: expected {getattr(kind, '__name__', kind)}, got {v!r}")
    return v


def _number(d: dict[str, Any], key: str, where: str, lo: float, hi: float, default: Any = ...) -> float:
    v = _get(d, key, where, (int, float), default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise StudyConfigError(f"{where}.{key}: must be a number in [{lo:g}, {hi:g}], got {v!r}")
    return float(v)


def _whole(d: dict[str, Any], key: str, where: str, lo: int, hi: int, default: Any = ...) -> int:
    v = _get(d, key, where, int, default)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise StudyConfigError(f"{where}.{key}: must be a whole number in [{lo}, {hi}], got {v!r}")
    return v


def _trajectory(d: dict[str, Any], where: str) -> Trajectory:
    amp = _get(d, "amp", where, list)
    freq = _get(d, "freq_hz", where, list)
    for name, vals, lo, hi in (("amp", amp, -3.2, 3.2), ("freq_hz", freq, 0.0, 50.0)):
        if not 1 <= len(vals) <= MAX_JOINTS or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and lo <= x <= hi for x in vals):
            raise StudyConfigError(f"{where}.{name}: need one number per joint, each in [{lo:g}, {hi:g}], "
                                   f"got {vals!r}")
    if len(amp) != len(freq):
        raise StudyConfigError(f"{where}.amp: {len(amp)} values, but freq_hz has {len(freq)} (one of each per joint)")
    arm = d.get("arm")
    if arm is not None and (not isinstance(arm, str) or not arm):
        raise StudyConfigError(f"{where}.arm: the name of the arm these amplitudes are for (arm.json name), got {arm!r}")
    return Trajectory([float(a) for a in amp], [float(f) for f in freq], arm)


def _scenario(name: str, d: Any) -> Scenario:
    where = f"scenario.{name}"
    try:  # a scenario's name names its runs' folder and its figures' files, as it is
        path_component(name, "scenario")
    except EscapeError as exc:
        raise StudyConfigError(str(exc)) from None
    if not isinstance(d, dict):
        raise StudyConfigError(f"{where}: expected a table")
    unknown = set(d) - {"description", "uncertainty", "drives", "bus_timing", "protocol"}
    if unknown:
        raise StudyConfigError(f"{where}: unknown field(s) {sorted(unknown)} (known: bus_timing, description, "
                               "drives, protocol, uncertainty)")
    unc = dict(_get(d, "uncertainty", where, dict, {}))
    if "seed" in unc:
        raise StudyConfigError(f"{where}.uncertainty.seed: the study's seeds set it")
    per_joint = {k: _per_joint(unc.pop(k), f"{where}.uncertainty.{k}") for k in PER_JOINT_FIELDS if k in unc}
    if unc.get("payload_kg") == RATED:
        per_joint["payload_kg"] = unc.pop("payload_kg")
    try:
        UncertaintyConfig.from_dict({**unc, "seed": 0}, f"{where}.uncertainty")
    except (TypeError, ValueError) as exc:
        raise StudyConfigError(str(exc)) from exc
    drives_v = d.get("drives", "ideal")
    if isinstance(drives_v, str):
        if drives_v not in DRIVE_PRESETS:
            raise StudyConfigError(f"{where}.drives: '{drives_v}' is not one of {', '.join(DRIVE_PRESETS)} "
                                   "(or give a table of host_sim.drive_model.DriveModel fields)")
        drives = DRIVE_PRESETS[drives_v]
    else:
        try:
            drives = DriveModel.from_dict(drives_v, f"{where}.drives")
        except ValueError as exc:
            raise StudyConfigError(str(exc)) from exc
    bus_timing = _get(d, "bus_timing", where, bool, False)
    protocol = _get(d, "protocol", where, str, STUDY_PROTOCOL)
    if protocol not in PROTOCOLS:
        raise StudyConfigError(f"{where}.protocol: '{protocol}' is not {' or '.join(PROTOCOLS)}")
    return Scenario(name, str(d.get("description", "")), unc, drives, bus_timing, per_joint, protocol=protocol)


def _coefficients(v: Any, where: str) -> list[Any]:
    if not isinstance(v, list) or not v or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and 0 <= x <= 1e6 for x in v):
        raise StudyConfigError(f"{where}: expected a list of friction coefficients in [0, 1e6], one per joint, "
                               f"got {v!r}")
    return list(v)


def _per_joint(v: Any, where: str) -> list[Any] | dict[str, Any]:
    """A per-joint field as the config gives it: a list (one value per joint of the arm it is
    for) or a rule table (PER_JOINT_RULES, and lists for arms by name in for_arm)."""
    if isinstance(v, list):
        return _coefficients(v, where)
    if not isinstance(v, dict):
        raise StudyConfigError(f"{where}: {RULE_HINT}; got {v!r}")
    unknown = set(v) - {*PER_JOINT_RULES, "for_arm"}
    rules = [k for k in v if k in PER_JOINT_RULES]
    if unknown or len(rules) > 1 or not v:
        raise StudyConfigError(f"{where}: " + (f"unknown field(s) {sorted(unknown)}" if unknown else
                                               f"one rule, not {rules}" if rules else "empty") + f"; {RULE_HINT}")
    out: dict[str, Any] = {}
    for k in rules:
        x = v[k]
        hi = 1.0 if k == "torque_limit_fraction" else 1e6
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or not 0 <= x <= hi:
            raise StudyConfigError(f"{where}.{k}: must be a number in [0, {hi:g}], got {x!r}")
        out[k] = float(x)
    if "for_arm" in v:
        if not isinstance(v["for_arm"], dict) or not v["for_arm"]:
            raise StudyConfigError(f"{where}.for_arm: expected a table of arm name = [one value per joint]")
        out["for_arm"] = {a: _coefficients(x, f"{where}.for_arm.{a}") for a, x in v["for_arm"].items()}
    return out


def _values_for_arm(spec: list[Any] | dict[str, Any], info: dict[str, Any], where: str) -> list[Any]:
    """One per-joint field's values on this arm (arm.json), or an error naming the field and
    both lengths."""
    name, n = info["name"], info["n_joints"]
    if isinstance(spec, dict) and name in spec.get("for_arm", {}):
        spec, where = spec["for_arm"][name], f"{where}.for_arm.{name}"
    if isinstance(spec, list):
        if len(spec) != n:
            raise StudyConfigError(f"{where}: {len(spec)} values, but arm '{name}' has {n} joints; {RULE_HINT}")
        return spec
    if "each" in spec:
        return [spec["each"]] * n
    if "torque_limit_fraction" in spec:
        # rounded: a value the report prints as it is (no 2.2499999999999996)
        return [round(spec["torque_limit_fraction"] * j["torque_limit"], 9) for j in info["joints"]]
    raise StudyConfigError(f"{where}: no values for arm '{name}' (for_arm has {', '.join(spec['for_arm'])}); "
                           f"add it, or a rule ({', '.join(PER_JOINT_RULES)})")


def for_arm(cfg: "StudyConfig", info: dict[str, Any]) -> "StudyConfig":
    """The config with every scenario's per-joint values made for this arm (its arm.json): called
    before anything runs, so a list of the wrong length stops the study at once."""
    scenarios = {}
    for name, sc in cfg.scenarios.items():
        unc = dict(sc.uncertainty)
        for k, spec in sc.per_joint.items():
            unc[k] = ([0.0, float(info["payload"]["rated_kg"])] if spec == RATED else
                      _values_for_arm(spec, info, f"scenario.{name}.uncertainty.{k}"))
        scenarios[name] = replace(sc, uncertainty=unc, resolved=True)
    omega = 2.0 * math.pi * float(info["first_resonance_hz"])
    spaces = {m: sp.for_resonance(omega) for m, sp in cfg.spaces.items()}
    return replace(cfg, scenarios=scenarios, spaces=spaces)


def _space(method: str, d: Any) -> Space:
    where = f"tuning.space.{method}"
    if method not in TUNED:
        raise StudyConfigError(f"{where}: {method} is not tuned (tuned: {', '.join(TUNED)})")
    if not isinstance(d, dict):
        raise StudyConfigError(f"{where}: expected a table of knob = [low, high]")
    how = METHODS[method][1]
    knobs = set(GAIN_KNOBS[method]) if how == "gains" else {*DESIGN_KNOBS}
    if how == "design" and {"E1", "E2", "D12"} & set(d):
        knobs = {*LEGACY_DESIGN_KNOBS}
    if how == "design" and method not in ESTIMATING:  # no estimator: no estimator weights
        knobs -= {"H", "f_bw"}
    known = knobs | ({"form"} if how == "design" else set())
    unknown = set(d) - known
    missing = known - set(d) - {"form"}
    if unknown or missing:
        raise StudyConfigError(f"{where}: " + (f"unknown knob(s) {sorted(unknown)}" if unknown else
                                               f"missing knob(s) {sorted(missing)}") + f" (knobs: {', '.join(sorted(known))})")
    sp = Space()
    for k, v in d.items():
        if k == "form":
            if not isinstance(v, list) or not v or not set(v) <= {"single", "split"}:
                raise StudyConfigError(f"{where}.form: a list of \"single\" and/or \"split\", got {v!r}")
            sp.choices["form"] = list(v)
            continue
        to_resonance = isinstance(v, list) and len(v) == 2 and v[1] == FIRST_RESONANCE
        if to_resonance:
            v = [v[0], math.inf]
        if (not isinstance(v, list) or len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                              and x > 0 for x in v) or not math.isfinite(v[0])
                or not v[0] < v[1] or (math.isinf(v[1]) and not to_resonance)):
            raise StudyConfigError(f"{where}.{k}: expected [low, high] with 0 < low < high (searched on a log scale; "
                                   f"high may be \"{FIRST_RESONANCE}\", the arm's, in rad/s), got {v!r}")
        if to_resonance:
            sp.to_resonance.add(k)
        floor = KNOB_FLOOR.get((method, k))
        if floor is not None and v[0] < floor:
            raise StudyConfigError(f"{where}.{k}: its structure reaches no lower than {floor:g} "
                                   f"(tools/study/config.py GAIN_KNOBS), got {v!r}")
        sp.ranges[k] = (float(v[0]), float(v[1]))
    if how == "design" and "form" not in sp.choices:
        sp.choices["form"] = ["single"]
    return sp


def _names(items: list, where: str) -> None:
    """A list of names is a list of strings (a nested list is a mistake, not a TypeError)."""
    odd = [x for x in items if not isinstance(x, str)]
    if odd:
        raise StudyConfigError(f"{where}: expected names (strings), got {odd[0]!r}")


STUDY_FIELDS = {"description", "duration_s", "hold_s", "seed", "seeds", "methods", "scenarios", "trajectory",
                "study_tuning_cap", "scenario", "tuning"}
TUNING_FIELDS = {"seeds", "duration_s", "amp", "freq_hz", "arm", "objective", "cap", "plateau", "tolerance", "batch",
                 "widen", "startup", "validation_seeds", "validation_tries", "robust_stiffness", "file", "space"}


def _known_fields(table: dict[str, Any], known: set[str], where: str) -> None:
    unknown = set(table) - known
    if unknown:
        raise StudyConfigError(f"{where}: unknown field(s) {sorted(unknown)} (known: {', '.join(sorted(known))})")


def _methods(data: dict[str, Any]) -> list[str]:
    methods = _get(data, "methods", "study", list)
    _names(methods, "study.methods")
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods or len(set(methods)) != len(methods):
        raise StudyConfigError(f"study.methods: unknown or repeated {bad or methods} (known: {', '.join(METHODS)})")
    return methods


def _chosen_scenarios(data: dict[str, Any]) -> dict[str, Scenario]:
    """The scenarios the study runs ([study] scenarios, default all), in its order."""
    tables = _get(data, "scenario", "study", dict)
    scenarios = {name: _scenario(name, d) for name, d in tables.items()}
    stems: dict[str, str] = {}
    for name in scenarios:  # each scenario's figures are files of their own (fig_KIND_STEM.png)
        other = stems.setdefault(file_stem(name).lower(), name)
        if other != name:
            raise StudyConfigError(f"scenario.{name}: its figures would be the files of scenario.{other} "
                                   f"(fig_*_{file_stem(name)}.png): rename one")
    chosen = _get(data, "scenarios", "study", list, list(scenarios))
    _names(chosen, "study.scenarios")
    missing = [s for s in chosen if s not in scenarios]
    if missing or not chosen:
        raise StudyConfigError(f"study.scenarios: {missing or 'none'} not defined (defined: {', '.join(scenarios)})")
    return {k: scenarios[k] for k in chosen}


def _seed_list(table: dict[str, Any], key: str, where: str, default: Any = ..., empty_ok: bool = True) -> list[int]:
    seeds = _get(table, key, where, list, default)
    if not (seeds or empty_ok) or not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2**63 for s in seeds):
        raise StudyConfigError(f"{where}.{key}: a list of whole numbers >= 0, got {seeds!r}")
    return seeds


def _seeds(data: dict[str, Any], tuning: dict[str, Any]) -> tuple[list[int], int, int, list[int]]:
    """The tuning seeds, the study's first seed and count, and the validation seeds: none shared."""
    tseeds = _seed_list(tuning, "seeds", "tuning", empty_ok=False)
    seed = _whole(data, "seed", "study", 0, 2**62)
    seeds = _whole(data, "seeds", "study", 1, 1000, 1)
    if set(tseeds) & set(range(seed, seed + seeds)):
        raise StudyConfigError(f"tuning.seeds {tseeds}: must differ from the study's seeds ({seed}..{seed + seeds - 1})")
    vseeds = _seed_list(tuning, "validation_seeds", "tuning", [])
    if set(vseeds) & (set(tseeds) | set(range(seed, seed + seeds))):
        raise StudyConfigError(f"tuning.validation_seeds {vseeds}: held out: must differ from the tuning seeds "
                               f"{tseeds} and the study's ({seed}..{seed + seeds - 1})")
    return tseeds, seed, seeds, vseeds


def _spaces(tuning: dict[str, Any], methods: list[str]) -> dict[str, Space]:
    spaces = {m: _space(m, d) for m, d in _get(tuning, "space", "tuning", dict).items()}
    untuned = [m for m in methods if METHODS[m][1] is not None and m not in spaces]
    if untuned:
        raise StudyConfigError(f"tuning.space: no search space for {untuned}: every tuned method needs one")
    return spaces


def _tuning_file_name(tuning: dict[str, Any]) -> str:
    file_name = _get(tuning, "file", "tuning", str)
    if "/" in file_name or not file_name.endswith(".json"):
        raise StudyConfigError(f"tuning.file: a file name next to the config ending .json, got {file_name!r}")
    return file_name


def load(path: Path) -> StudyConfig:
    try:
        data = toml_input.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise StudyConfigError(f"{path}: {exc}") from exc
    _known_fields(data, STUDY_FIELDS, "study")
    methods = _methods(data)
    scenarios = _chosen_scenarios(data)
    tuning = _get(data, "tuning", "study", dict)
    _known_fields(tuning, TUNING_FIELDS, "tuning")
    tseeds, seed, seeds, vseeds = _seeds(data, tuning)
    spaces = _spaces(tuning, methods)
    file_name = _tuning_file_name(tuning)
    return StudyConfig(
        path=path,
        description=str(data.get("description", "")),
        duration_s=_number(data, "duration_s", "study", 0.001, 86400),
        hold_s=_number(data, "hold_s", "study", 0.0, 3600),
        seed=seed,
        seeds=seeds,
        methods=list(methods),
        scenarios=scenarios,
        trajectory=_trajectory(_get(data, "trajectory", "study", dict), "trajectory"),
        tuning_seeds=list(tseeds),
        tuning_duration_s=_number(tuning, "duration_s", "tuning", 0.001, 3600),
        tuning_trajectory=_trajectory(tuning, "tuning"),
        tuning_objective=str(tuning.get("objective", "")),
        cap=_whole(tuning, "cap", "tuning", 1, 100000, 400),
        study_cap=min(_whole(data, "study_tuning_cap", "study", 1, 100000, 400), _whole(tuning, "cap", "tuning", 1, 100000, 400)),
        plateau=_whole(tuning, "plateau", "tuning", 1, 100000, 50),
        tolerance=_number(tuning, "tolerance", "tuning", 0.0, 1.0, 0.01),
        batch=_whole(tuning, "batch", "tuning", 1, 64, 4),
        widen=_whole(tuning, "widen", "tuning", 0, 10, 2),
        startup=_whole(tuning, "startup", "tuning", 1, 10000, 8),
        validation_seeds=list(vseeds),
        validation_tries=_whole(tuning, "validation_tries", "tuning", 1, 1000, 5),
        robust_stiffness=_stiffness_scales(tuning.get("robust_stiffness", [])),
        spaces=spaces,
        tuning_file=path.parent / file_name,
        raw=data,
    )


def _stiffness_scales(v: Any) -> list[float]:
    """[tuning] robust_stiffness: the gear stiffness scales a pick must also run ok at."""
    p = param("simulator", "gear-stiffness-scale")
    if not isinstance(v, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise StudyConfigError(f"tuning.robust_stiffness: a list of gear stiffness scales, got {v!r}")
    for i, x in enumerate(v):
        try:
            p.check(x, f"tuning.robust_stiffness[{i}]")
        except ValueError as exc:
            raise StudyConfigError(str(exc)) from exc
    return [float(x) for x in v]


def usde_smc_gains(wn: float, zeta: float) -> tuple[float, float]:
    """(lambda, ks) whose linear part is the PD kp = wn^2, kd = 2 zeta wn (zeta >= 1; below, the
    structure cannot reach it and zeta 1 is used)."""
    z = max(zeta, USDE_SMC_MIN_ZETA)
    lam = wn * (z - math.sqrt(z * z - 1.0))
    return lam, wn * wn / lam


def gain_args(method: str, gains: dict[str, float]) -> list[str]:
    """Controller arguments for one method's gains (the search space's knob names; an older
    tuning's pd/tde {wn} is critically damped, usde-smc's {k, lambda} has ks = lambda)."""
    if method in ("pd", "tde"):
        wn = gains["wn"]
        zeta = gains.get("zeta", 1.0)
        args = ["--kp", f"{wn * wn:g}", "--kd", f"{2 * zeta * wn:g}"]
        if method == "tde":
            args += ["--tde-cutoff", f"{gains['cutoff_hz']:g}"]
        return args
    if method == "usde-smc":
        if "wn" in gains:
            lam, ks = usde_smc_gains(gains["wn"], gains.get("zeta", 1.0))
        else:
            lam = ks = gains["lambda"]
        return ["--usde-k", f"{gains['k']:g}", "--smc-lambda", f"{lam:g}", "--smc-ks", f"{ks:g}",
                "--smc-eta", f"{param('controller', 'smc-eta').default:g}",
                "--smc-phi", f"{param('controller', 'smc-phi').default:g}"]
    return []
