"""Property tests (hypothesis) of the Python decoders and config loaders: on any input they
return a value or raise their own named error, never anything else (no traceback reaches a user)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import lcm
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gen.synth.config import ConfigError, parse_config
from host_sim.drive_model import DriveModel
from host_sim.protocol import DriveProtocol, FastCodec
from host_sim.uncertainty import UncertaintyConfig
from tools.design_knobs import dumps
from gen.lib.paths import REPO
from tools.study_config import StudyConfigError, load
from tools.telemetry_log import CHANNEL_TYPES, read_log

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
scalars = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                    st.text(max_size=12))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                        st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)


def _mutations(doc: dict) -> st.SearchStrategy:
    """A path into the document (a top-level key, or a key of one of its tables) and a new value."""
    paths = [(k,) for k in doc] + [(k, k2) for k, v in doc.items() if isinstance(v, dict) for k2 in v]
    return st.tuples(st.sampled_from(paths), values)


def _mutate(doc: dict, path: tuple, value: object) -> dict:
    import copy

    out = copy.deepcopy(doc)
    target = out
    for k in path[:-1]:
        target = target[k]
    target[path[-1]] = value
    return out


DESIGN = tomllib.loads((REPO / "gen" / "configs" / "paper.toml").read_text())


@SETTINGS
@given(_mutations(DESIGN))
def test_design_config_parser_raises_only_config_error(m: tuple) -> None:
    try:
        parse_config(_mutate(DESIGN, *m))
    except ConfigError:
        pass


STUDY_TEXT = (REPO / "tools" / "studies" / "paper.toml").read_text()
STUDY = tomllib.loads(STUDY_TEXT)


@SETTINGS
@given(_mutations(STUDY))
def test_study_config_loader_raises_only_study_config_error(tmp_path: Path, m: tuple) -> None:
    path, value = m
    doc = _mutate(STUDY, path, value)
    f = tmp_path / "cfg.toml"
    try:
        f.write_text(dumps(doc))
    except Exception:  # noqa: BLE001 - a value TOML cannot hold (None): nothing to load
        return
    try:
        load(f)
    except StudyConfigError:
        pass


@SETTINGS
@given(st.dictionaries(st.sampled_from(["encoder_bits", "position_noise_counts", "velocity_filter_hz",
                                        "torque_noise_nm", "current_loop_hz", "torque_latency_us", "ripple",
                                        "ripple_periods", "colour"]), scalars, max_size=5))
def test_drive_model_raises_only_value_error(d: dict) -> None:
    try:
        m = DriveModel.from_dict(d)
    except ValueError:
        return
    assert all(isinstance(a, str) for a in m.args())


@SETTINGS
@given(st.dictionaries(st.sampled_from(["seed", "paper_ratio", "paper_knot_s", "mass_error", "inertia_error",
                                        "com_error_m", "viscous", "coulomb", "wind"]), values, max_size=5))
def test_uncertainty_config_raises_only_value_error(d: dict) -> None:
    try:
        UncertaintyConfig.from_dict(d)
    except ValueError:
        pass


CODECS = [FastCodec.from_message(m) for m in DriveProtocol(6).state[:1] + DriveProtocol(6).cmd[:1]]


@SETTINGS
@given(st.binary(max_size=80))
def test_frame_decoder_returns_signals_or_none(data: bytes) -> None:
    for c in CODECS:
        out = c.decode(data)
        assert out is None or all(math.isfinite(v) for v in out.values())


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
