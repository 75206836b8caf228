"""Property tests (hypothesis) of the Python decoders and config loaders: on any input they
return a value or raise their own named error, never anything else (no traceback reaches a user),
and that error is one line naming what is wrong; a value they accept is the one they were given."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import lcm
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gen.synth.config import ConfigError, parse_config
from host_sim.drive_model import DriveModel
from host_sim.protocol import DriveProtocol, FastCodec
from host_sim.uncertainty import UncertaintyConfig
from tools.study.design_knobs import KnobError, dumps
from gen.lib.paths import REPO
from tools.study.config import StudyConfigError, load
from tools.run.telemetry_log import CHANNEL_TYPES, read_log

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
scalars = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                    st.text(max_size=12))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                        st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)


def _near(original: object, factor: float) -> object:
    """A value of the original's shape that a parser may well accept: its numbers scaled (whole
    numbers stay whole and move by at least one), strings and booleans as they are."""
    if isinstance(original, bool) or isinstance(original, str):
        return original
    if isinstance(original, int):
        return max(1, round(original * factor)) if round(original * factor) != original else original + 1
    if isinstance(original, float):
        return original * factor
    if isinstance(original, list):
        return [_near(x, factor) for x in original]
    if isinstance(original, dict):
        return {k: _near(v, factor) for k, v in original.items()}
    return original


def _mutations(doc: dict) -> st.SearchStrategy:
    """A path into the document (a top-level key, or a key of one of its tables) and a new value:
    anything at all, or the original's shape with its numbers moved (what a parser accepts, so
    that what it makes of an accepted value is tested too)."""
    paths = [(k,) for k in doc] + [(k, k2) for k, v in doc.items() if isinstance(v, dict) for k2 in v]

    def near(path: tuple) -> st.SearchStrategy:
        return st.sampled_from([0.5, 0.9, 1.5, 2.0]).map(lambda f: (path, _near(_get(doc, path), f)))
    return st.one_of(st.tuples(st.sampled_from(paths), values), st.sampled_from(paths).flatmap(near))


def _mutate(doc: dict, path: tuple, value: object) -> dict:
    import copy

    out = copy.deepcopy(doc)
    target = out
    for k in path[:-1]:
        target = target[k]
    target[path[-1]] = value
    return out


DESIGN = tomllib.loads((REPO / "gen" / "configs" / "paper.toml").read_text())


def _one_line_naming(exc: Exception, *names: str) -> None:
    """A user's error: one line, naming (one of) the settings that is wrong."""
    text = str(exc)
    assert text and "\n" not in text, repr(text)
    assert any(n in text for n in names), (names, text)


def _contains(value: object, pred) -> bool:  # noqa: ANN001 - a predicate
    if isinstance(value, dict):
        return any(_contains(v, pred) for v in value.values())
    if isinstance(value, list):
        return any(_contains(v, pred) for v in value)
    return pred(value)


BASE_DESIGN = parse_config(DESIGN)


@SETTINGS
@given(_mutations(DESIGN))
@example(m=(("arm",), {"\n": None}))  # a key of the user's with a line break, found by hypothesis in CI
def test_design_config_parser_raises_only_config_error(m: tuple) -> None:
    _parse_mutated_design(*m)


def _parse_mutated_design(path: tuple, value: object) -> None:
    try:
        cfg = parse_config(_mutate(DESIGN, path, value))
    except ConfigError as exc:
        _one_line_naming(exc, str(path[-1]))
        return
    assert type(cfg) is type(BASE_DESIGN)
    # what it accepted is what it was given: a value other than the original's gives another design
    # (a parser that dropped or defaulted the field would give the original's)
    # (a whole table replaced may fall back to defaults equal to the file's, and None is no TOML
    # value, so only a leaf given a TOML value is held to it)
    original = _get(DESIGN, path)
    if isinstance(original, dict) or _contains(value, lambda v: v is None):
        return
    assert not _same(cfg, BASE_DESIGN) or _equivalent(value, original), (path, value, original)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_design_config_parser_keeps_each_value_it_accepts(factor: float) -> None:
    """Each leaf of the design, its numbers moved (what hypothesis may not happen to draw)."""
    for path in _leaves(DESIGN):
        _parse_mutated_design(path, _near(_get(DESIGN, path), factor))


def _same(a: object, b: object) -> bool:
    """Equality through dataclasses, containers and numpy arrays (whose == is elementwise)."""
    if dataclasses.is_dataclass(a) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, (list, tuple)) and type(a) is type(b):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b, equal_nan=True))
    return a == b or (a != a and b != b)  # NaN is NaN


def _equivalent(a: object, b: object) -> bool:
    """The same value in TOML's terms: numbers by value (1 and 1.0), lists element by element."""
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_equivalent(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equivalent(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


def _get(doc: dict, path: tuple) -> object:
    for k in path:
        doc = doc[k]
    return doc


STUDY_TEXT = (REPO / "tools" / "studies" / "paper.toml").read_text()
STUDY = tomllib.loads(STUDY_TEXT)


def test_the_study_document_round_trips_through_dumps() -> None:
    """The property test below loads what dumps writes: it must be the study itself, unmutated
    (a scenario named realistic+friction once made every example a TOML syntax error)."""
    assert tomllib.loads(dumps(STUDY)) == STUDY
    assert load_text_of(dumps(STUDY)) is not None


def load_text_of(text: str, where: Path | None = None) -> object:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        f = (where or Path(tmp)) / "cfg.toml"
        f.write_text(text)
        return load(f)


BASE_STUDY = load_text_of(STUDY_TEXT)


@SETTINGS
@given(_mutations(STUDY))
@example(m=(("scenario",), {"\n": False}))
def test_study_config_loader_raises_only_study_config_error(tmp_path: Path, m: tuple) -> None:
    _load_mutated_study(tmp_path, *m)


def _leaves(doc: dict) -> list[tuple]:
    """Every path _mutations() reaches whose value is no table."""
    return [(k,) for k, v in doc.items() if not isinstance(v, dict)] + [
        (k, k2) for k, v in doc.items() if isinstance(v, dict) for k2, v2 in v.items() if not isinstance(v2, dict)]


@pytest.mark.parametrize("path", _leaves(STUDY), ids=".".join)
@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_study_config_loader_keeps_each_value_it_accepts(tmp_path: Path, path: tuple, factor: float) -> None:
    """Each leaf of the study, its numbers moved (what hypothesis may not happen to draw): loaded as
    given, or refused in one line naming it."""
    _load_mutated_study(tmp_path, path, _near(_get(STUDY, path), factor))


def _load_mutated_study(tmp_path: Path, path: tuple, value: object) -> None:
    doc = _mutate(STUDY, path, value)
    try:
        text = dumps(doc)
    except KnobError as exc:  # a value TOML cannot hold: nothing to load
        assert _contains(value, lambda v: v is None), (value, exc)
        return
    tomllib.loads(text)  # what dumps writes is TOML
    f = tmp_path / "cfg.toml"
    f.write_text(text)
    try:
        cfg = load(f)
    except StudyConfigError as exc:
        _one_line_naming(exc, *map(str, path), str(f))
        return
    assert type(cfg) is type(BASE_STUDY)
    # what it accepted is what it was given (as for the design config above): a leaf given another
    # TOML value gives another study (a loader that dropped or defaulted it would give the original)
    original = _get(STUDY, path)
    if isinstance(original, dict) or _contains(value, lambda v: v is None):
        return
    if path == ("study_tuning_cap",) and value >= cfg.cap:  # the study's cap is never above [tuning] cap
        assert cfg.study_cap == cfg.cap, cfg.study_cap
        return
    assert not _same(_loaded(cfg), _loaded(BASE_STUDY)) or _equivalent(value, original), (path, value, original)


def _loaded(cfg: object) -> object:
    """What the loader made of the study, without where it was read from and the document it read."""
    return dataclasses.replace(cfg, path=Path(), tuning_file=Path(cfg.tuning_file.name), raw={})


@SETTINGS
@given(st.dictionaries(st.sampled_from(["encoder_bits", "position_noise_counts", "motor_encoder_bits", "gear_ratio",
                                        "position_source", "velocity_source", "velocity_filter_hz",
                                        "torque_noise_nm", "current_loop_hz", "torque_latency_us", "ripple",
                                        "ripple_periods", "colour"]),
                       scalars | st.sampled_from(["joint", "motor"]) | st.integers(0, 24) | st.floats(0.0, 10.0),
                       max_size=5))
def test_drive_model_raises_only_value_error(d: dict) -> None:
    """A drive model accepts a dict of its fields or raises ValueError naming the field; what it
    accepts is what it was given, and it comes back the same from its own dict and arm_sim's options."""
    try:
        m = DriveModel.from_dict(d)
    except ValueError as exc:  # naming a field given, or one a given one needs
        _one_line_naming(exc, *(f.name for f in dataclasses.fields(DriveModel)), *d)
        return
    assert "colour" not in d  # not a field: refused
    for k, v in d.items():
        assert _equivalent(getattr(m, k), v), (k, v, getattr(m, k))
    assert DriveModel.from_dict(m.to_dict()) == m
    args = m.args()
    assert all(isinstance(a, str) for a in args) and len(args) % 2 == 0


@SETTINGS
@given(st.dictionaries(st.sampled_from(["seed", "paper_ratio", "paper_knot_s", "mass_error", "inertia_error",
                                        "com_error_m", "viscous", "coulomb", "wind"]), values, max_size=5))
def test_uncertainty_config_raises_only_value_error(d: dict) -> None:
    try:
        cfg = UncertaintyConfig.from_dict(d)
    except ValueError as exc:  # only a field that was given can be wrong: the defaults are valid
        _one_line_naming(exc, *d)
        return
    for k, v in d.items():
        assert getattr(cfg, k) == v, k
    assert UncertaintyConfig.from_dict(dataclasses.asdict(cfg)) == cfg


CODECS = [FastCodec.from_message(m) for m in DriveProtocol(6).state[:1] + DriveProtocol(6).cmd[:1]]


@SETTINGS
@given(st.one_of(st.binary(max_size=80), st.binary(min_size=8, max_size=8), st.binary(min_size=4, max_size=4)))
def test_frame_decoder_returns_signals_or_none(data: bytes) -> None:
    """The simulator's struct codec decodes a frame as cantools decodes it with the DBC (an
    independent decoder): the same signals, the same values; a payload of another length is None."""
    for c in CODECS:
        out = c.decode(data)
        if len(data) != c.message.length:
            assert out is None
            continue
        want = c.message.decode(data, decode_choices=False, scaling=True)
        assert out is not None and out.keys() == want.keys()
        for name, v in out.items():
            assert math.isfinite(v) and math.isclose(v, float(want[name]), rel_tol=1e-12, abs_tol=1e-12), name


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(sorted(CHANNEL_TYPES)), st.binary(max_size=300)), max_size=6))
def test_telemetry_log_reader_counts_what_it_cannot_decode(tmp_path: Path, events: list) -> None:
    path = tmp_path / "t.lcmlog"
    path.unlink(missing_ok=True)
    log = lcm.EventLog(str(path), "w", overwrite=True)
    for i, (ch, data) in enumerate(events):
        log.write_event(i, ch, data)
    log.close()
    out = read_log(path)
    assert sum(len(c.messages) + c.undecodable for c in out.values()) == len(events)


@pytest.mark.parametrize("text", ["", "model = 3", "[[buses]]\nname = 1", "model = 'x.xml'\njoints = [1]",
                                  "model = 'x.xml'\nhome = {a = 'b'}", "\x00\x01"])
def test_arm_file_loader_raises_only_arm_error(tmp_path: Path, text: str) -> None:
    from gen.arm import ArmError, load_arm_file

    f = tmp_path / "arm.toml"
    f.write_text(text)
    with pytest.raises(ArmError):
        load_arm_file(f)
