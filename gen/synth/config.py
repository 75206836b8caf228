"""Design config: TOML in, a validated DesignConfig out, or a ConfigError that names the field.

Every weight can be given for one joint (it then applies to every joint, i.e. kron(W, I_n)) or
for the whole arm. Validation happens here, once, so the numerical code downstream can assume
shapes, signs, strict properness and invertibility.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gen.lib import toml_input
from gen.lib.one_line import one_line

STRUCTURES = ("auto", "coupled")
DEFAULT_LADDER = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
_COND_MAX = 1e12  # beyond this a weight is singular for every practical purpose


class ConfigError(ValueError):
    """A config field is missing or invalid; `field` is its dotted TOML path."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.message = message
        super().__init__(one_line(f"{field}: {message}"))


@dataclass(frozen=True)
class TransferFunction:
    """num(s)/den(s), coefficients in descending powers of s."""

    num: tuple[float, ...]
    den: tuple[float, ...]

    def to_json(self) -> dict[str, list[float]]:
        return {"num": list(self.num), "den": list(self.den)}


@dataclass(frozen=True, eq=False)
class DesignConfig:
    n_joints: int
    loop_rate_hz: int
    F: tuple[TransferFunction, ...]  # one per joint (F(s) is diagonal)
    H: np.ndarray  # n x n
    allow_biproper_F: bool
    E1: np.ndarray  # p x n
    E2: np.ndarray  # p x n
    D12: np.ndarray  # p x n
    structure: str
    backoff_ladder: tuple[float, ...]
    delay_margin_samples: int
    residualise_above: float
    e_max: float
    e_dot_max: float
    description: str = ""

    @property
    def period_s(self) -> float:
        return 1.0 / self.loop_rate_hz

    def to_json(self) -> dict[str, Any]:
        """The fully expanded inputs, as recorded in the manifest."""
        return {
            "description": self.description,
            "arm": {"n_joints": self.n_joints, "loop_rate_hz": self.loop_rate_hz},
            "estimator": {
                "F": [f.to_json() for f in self.F],
                "H": self.H.tolist(),
                "allow_biproper_F": self.allow_biproper_F,
            },
            "controller": {"E1": self.E1.tolist(), "E2": self.E2.tolist(), "D12": self.D12.tolist()},
            "design": {
                "structure": self.structure,
                "backoff_ladder": list(self.backoff_ladder),
                "delay_margin_samples": self.delay_margin_samples,
                "residualise_above": self.residualise_above,
            },
            "ranges": {"e_max": self.e_max, "e_dot_max": self.e_dot_max},
        }


# ---------------------------------------------------------------- field readers


def _is_number(v: Any) -> bool:
    # TOML booleans are Python bools, which are ints: never accept them as numbers.
    return isinstance(v, (int, float)) and not isinstance(v, bool)


MAX_MAGNITUDE = 1e9  # weights and coefficients beyond this only make the LMIs ill-conditioned
MAX_JOINTS = 16      # the firmware's bound (firmware/core/include/arm/robot_model.h)


def _number(v: Any, field: str) -> float:
    if not _is_number(v) or not math.isfinite(float(v)):
        raise ConfigError(field, f"must be a finite number, got {v!r}")
    if abs(float(v)) > MAX_MAGNITUDE:
        raise ConfigError(field, f"must be within +-{MAX_MAGNITUDE:g} (scale the weights), got {v!r}")
    return float(v)


def _positive(v: Any, field: str) -> float:
    x = _number(v, field)
    if x <= 0:
        raise ConfigError(field, f"must be > 0, got {x:g}")
    return x


def _integer(v: Any, field: str, minimum: int, maximum: int) -> int:
    if _is_number(v) and math.isfinite(float(v)) and float(v).is_integer():
        i = int(v)
        if minimum <= i <= maximum:
            return i
    raise ConfigError(field, f"must be an integer in [{minimum}, {maximum}], got {v!r}")


def _matrix(v: Any, field: str) -> np.ndarray:
    """A scalar or a list of equal-length rows of finite numbers."""
    if _is_number(v):
        v = [[v]]
    if not isinstance(v, list) or not v or not all(isinstance(r, list) for r in v):
        raise ConfigError(field, "must be a number or a non-empty list of rows, e.g. [[0.5]]")
    width = len(v[0])
    if width == 0 or any(len(r) != width for r in v):
        raise ConfigError(field, "rows must be non-empty and of equal length")
    for r in v:
        for x in r:
            if not _is_number(x) or not math.isfinite(float(x)) or abs(float(x)) > MAX_MAGNITUDE:
                raise ConfigError(field, f"entries must be finite numbers within +-{MAX_MAGNITUDE:g}, got {x!r}")
    return np.array(v, dtype=float)


def _coeffs(v: Any, field: str) -> tuple[float, ...]:
    if not isinstance(v, list) or not v:
        raise ConfigError(field, "must be a non-empty list of coefficients (descending powers of s)")
    return tuple(_number(x, f"{field}[{i}]") for i, x in enumerate(v))


def _table(doc: dict[str, Any], key: str, allowed: set[str], required: bool = True) -> dict[str, Any]:
    t = doc.get(key)
    if t is None:
        if required:
            raise ConfigError(key, "section is missing")
        return {}
    if not isinstance(t, dict):
        raise ConfigError(key, "must be a table")
    for k in t:
        if k not in allowed:
            raise ConfigError(f"{key}.{k}", f"unknown field (allowed: {', '.join(sorted(allowed))})")
    return t


def _require(t: dict[str, Any], section: str, key: str) -> Any:
    if key not in t:
        raise ConfigError(f"{section}.{key}", "is missing")
    return t[key]


# ---------------------------------------------------------------- weights


def _transfer_function(v: Any, field: str, allow_biproper: bool) -> TransferFunction:
    if not isinstance(v, dict) or set(v) != {"num", "den"}:
        raise ConfigError(field, "must be a table {num = [...], den = [...]}")
    num = list(_coeffs(v["num"], f"{field}.num"))
    den = list(_coeffs(v["den"], f"{field}.den"))
    if den[0] == 0.0:
        raise ConfigError(f"{field}.den", "leading coefficient must be nonzero")
    while num and num[0] == 0.0:
        num.pop(0)
    if not num:
        raise ConfigError(f"{field}.num", "F must not be identically zero")
    deg_n, deg_d = len(num) - 1, len(den) - 1
    if deg_n > deg_d:
        raise ConfigError(field, f"is improper (numerator degree {deg_n} > denominator degree {deg_d})")
    if deg_n == deg_d and not allow_biproper:
        raise ConfigError(
            field,
            "must be strictly proper (Theorem 2: a feedthrough F(inf) bounds gamma below by |F(inf)|); "
            "set estimator.allow_biproper_F = true to design anyway",
        )
    if deg_d >= 1:
        poles = np.roots(den)
        if np.any(poles.real >= 0):
            raise ConfigError(field, f"must be stable, poles {np.round(poles, 6).tolist()}")
    return TransferFunction(tuple(num), tuple(den))


def _per_joint_or_full(M: np.ndarray, field: str, n: int, square: bool) -> np.ndarray:
    """One joint's matrix (kron with I_n) or the whole arm's."""
    r, c = M.shape
    if square:
        if (r, c) == (1, 1):
            return M[0, 0] * np.eye(n)
        if (r, c) == (n, n):
            return M
        raise ConfigError(field, f"must be square 1x1 or {n}x{n}, got {r}x{c}")
    if c == n:
        return M
    if c == 1:
        return np.kron(M, np.eye(n))
    raise ConfigError(field, f"must have 1 column (one joint) or {n} columns (whole arm), got {r}x{c}")


def _check_invertible(M: np.ndarray, field: str, why: str) -> None:
    s = np.linalg.svd(M, compute_uv=False)
    if s[-1] == 0.0 or s[0] / s[-1] > _COND_MAX or M.shape[0] < M.shape[1]:
        raise ConfigError(field, f"must have full column rank ({why}); singular values {np.round(s, 9).tolist()}")


# ---------------------------------------------------------------- entry points


def parse_config(doc: dict[str, Any]) -> DesignConfig:
    """Validate a parsed TOML document; raise ConfigError naming the first bad field."""
    for k in doc:
        if k not in {"description", "arm", "estimator", "controller", "design", "ranges"}:
            raise ConfigError(k, "unknown section")
    description = doc.get("description", "")
    if not isinstance(description, str):
        raise ConfigError("description", "must be a string")

    arm = _table(doc, "arm", {"n_joints", "loop_rate_hz"})
    n = _integer(_require(arm, "arm", "n_joints"), "arm.n_joints", 1, MAX_JOINTS)
    rate = _integer(_require(arm, "arm", "loop_rate_hz"), "arm.loop_rate_hz", 1, 100000)

    est = _table(doc, "estimator", {"F", "H", "allow_biproper_F"})
    allow_bp = est.get("allow_biproper_F", False)
    if not isinstance(allow_bp, bool):
        raise ConfigError("estimator.allow_biproper_F", "must be true or false")
    f_raw = _require(est, "estimator", "F")
    if isinstance(f_raw, dict):
        F = (_transfer_function(f_raw, "estimator.F", allow_bp),) * n
    elif isinstance(f_raw, list) and len(f_raw) == n:
        F = tuple(_transfer_function(f, f"estimator.F[{j}]", allow_bp) for j, f in enumerate(f_raw))
    else:
        raise ConfigError("estimator.F", f"must be one {{num, den}} table (every joint) or a list of {n} of them")
    H = _per_joint_or_full(_matrix(_require(est, "estimator", "H"), "estimator.H"), "estimator.H", n, square=True)
    _check_invertible(H, "estimator.H", "H = 0 makes the H-infinity estimator high-gain, Sec. 3.2")

    ctl = _table(doc, "controller", {"E1", "E2", "D12"})
    mats = {}
    for name in ("E1", "E2", "D12"):
        field = f"controller.{name}"
        mats[name] = _per_joint_or_full(_matrix(_require(ctl, "controller", name), field), field, n, square=False)
    p = mats["E1"].shape[0]
    for name in ("E2", "D12"):
        if mats[name].shape[0] != p:
            raise ConfigError(
                f"controller.{name}",
                f"has {mats[name].shape[0]} rows after expansion but controller.E1 has {p} (z_o = E1 e + E2 e_dot + D12 u_o)",
            )
    _check_invertible(mats["D12"], "controller.D12", "the control effort must be penalised in z_o")

    des = _table(doc, "design", {"structure", "backoff_ladder", "delay_margin_samples", "residualise_above"}, required=False)
    structure = des.get("structure", "auto")
    if structure not in STRUCTURES:
        raise ConfigError("design.structure", f"must be one of {', '.join(STRUCTURES)}, got {structure!r}")
    ladder_raw = des.get("backoff_ladder", list(DEFAULT_LADDER))
    if not isinstance(ladder_raw, list) or not ladder_raw:
        raise ConfigError("design.backoff_ladder", "must be a non-empty list of relative back-offs, e.g. [1e-3, 1e-2]")
    ladder = tuple(_positive(x, f"design.backoff_ladder[{i}]") for i, x in enumerate(ladder_raw))
    if any(b <= a for a, b in zip(ladder, ladder[1:])):
        raise ConfigError("design.backoff_ladder", "must be strictly increasing")
    delay = _integer(des.get("delay_margin_samples", 1), "design.delay_margin_samples", 0, 50)
    resid = _positive(des.get("residualise_above", 10.0), "design.residualise_above")

    rng = _table(doc, "ranges", {"e_max", "e_dot_max"})
    e_max = _positive(_require(rng, "ranges", "e_max"), "ranges.e_max")
    e_dot_max = _positive(_require(rng, "ranges", "e_dot_max"), "ranges.e_dot_max")
    for name, v, hi in (("ranges.e_max", e_max, 100.0), ("ranges.e_dot_max", e_dot_max, 1e4)):
        if v > hi:  # the fixed-point format of the inputs spends a bit per doubling of the range
            raise ConfigError(name, f"must be <= {hi:g} (the fixed-point inputs would have no resolution left), got {v:g}")

    return DesignConfig(
        n_joints=n,
        loop_rate_hz=rate,
        F=F,
        H=H,
        allow_biproper_F=allow_bp,
        E1=mats["E1"],
        E2=mats["E2"],
        D12=mats["D12"],
        structure=structure,
        backoff_ladder=ladder,
        delay_margin_samples=delay,
        residualise_above=resid,
        e_max=e_max,
        e_dot_max=e_dot_max,
        description=description,
    )


def load_config(path: Path) -> DesignConfig:
    try:
        doc = toml_input.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError("config", f"file not found: {path}") from None
    except IsADirectoryError:
        raise ConfigError("config", f"{path} is a directory: give the design config file (TOML)") from None
    except OSError as exc:
        raise ConfigError("config", f"{path}: cannot read it ({exc.strerror})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError("config", f"{path}: not valid TOML ({exc})") from None
    return parse_config(doc)
