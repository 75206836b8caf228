"""The drive protocol: the DBC is the one definition; the fast Python codec agrees with cantools."""

from __future__ import annotations

import numpy as np
import pytest

from host_sim.protocol import DriveProtocol, FastCodec


@pytest.fixture(scope="module")
def proto() -> DriveProtocol:
    return DriveProtocol(6)


def test_frame_ids_follow_canopen_cob_ids(proto: DriveProtocol) -> None:
    assert proto.sync.frame_id == 0x080 and proto.nmt.frame_id == 0x000
    for i in range(6):
        assert proto.state[i].frame_id == 0x181 + i
        assert proto.cmd[i].frame_id == 0x201 + i
        assert proto.heartbeat[i].frame_id == 0x701 + i
        assert proto.emcy[i].frame_id == 0x081 + i
    ids = [m.frame_id for m in proto.db.messages]
    assert len(ids) == len(set(ids))


def test_state_frames_are_can_fd_and_commands_classic(proto: DriveProtocol) -> None:
    assert all(m.is_fd and m.length == 16 for m in proto.state)
    assert all(not m.is_fd and m.length <= 8 for m in proto.cmd)


@pytest.mark.parametrize("kind", ["state", "cmd"])
def test_fast_codec_matches_cantools(proto: DriveProtocol, kind: str) -> None:
    rng = np.random.default_rng(3)
    for i in range(6):
        msg = getattr(proto, kind)[i]
        codec = FastCodec.from_message(msg)
        for _ in range(200):
            values = {}
            for sig in msg.signals:
                if sig.scale == 1:
                    values[sig.name] = int(rng.integers(0, 2 ** min(sig.length, 16)))
                else:
                    values[sig.name] = round(float(rng.uniform(-100, 100)) / sig.scale) * sig.scale
            fast = codec.encode(values)
            assert fast == msg.encode(values)
            decoded = codec.decode(fast)
            for k, v in msg.decode(fast).items():
                assert decoded[k] == pytest.approx(v, abs=1e-12)


def test_torque_resolution_is_a_micro_newton_metre(proto: DriveProtocol) -> None:
    sig = proto.cmd[5].get_signal_by_name("target_torque")
    assert sig.scale == pytest.approx(1e-6)
    # The last wrist (about 1e-4 kg m^2) then sees at most 0.005 rad/s^2 from rounding.
    assert 0.5 * sig.scale / 1e-4 <= 0.01


def test_out_of_range_values_saturate_instead_of_crashing(proto: DriveProtocol) -> None:
    codec = FastCodec.from_message(proto.state[0])
    data = codec.encode({"position": 1e9, "velocity": -1e9, "torque": 0.0, "statusword": 0x237,
                         "sync_counter": 1, "error_code": 0})
    v = codec.decode(data)
    assert v["position"] == pytest.approx(2147.483647) and v["velocity"] == pytest.approx(-2147.483648)
