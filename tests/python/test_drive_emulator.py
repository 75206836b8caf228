"""The emulated drive behaves like a CiA 402 drive: state machine, limits, command timeout."""

from __future__ import annotations

from host_sim.cia402 import PowerState, next_state
from host_sim.drive import EMCY_RPDO_TIMEOUT, Drive
from host_sim.protocol import NMT_START, NMT_STATE_OPERATIONAL, NMT_STOP


def enabled_drive() -> Drive:
    d = Drive(node_id=1, torque_limit=28.0, command_timeout_periods=3)
    d.on_nmt(NMT_START)
    for cw in (0x06, 0x07, 0x0F):
        d.on_command(cw, 0.0)
    return d


def test_enable_sequence_reaches_operation_enabled() -> None:
    s = PowerState.SWITCH_ON_DISABLED
    assert next_state(s, 0x0F, 0) is s  # enable operation from disabled is not a transition
    s = next_state(s, 0x06, 0)
    assert s is PowerState.READY_TO_SWITCH_ON
    s = next_state(s, 0x07, 0x06)
    assert s is PowerState.SWITCHED_ON
    s = next_state(s, 0x0F, 0x07)
    assert s is PowerState.OPERATION_ENABLED
    assert s.statusword & 0x006F == 0x0027


def test_torque_only_in_operation_enabled_and_clamped() -> None:
    d = Drive(node_id=2, torque_limit=28.0)
    d.on_command(0x0F, 10.0)
    assert d.applied_torque == 0.0  # NMT pre-operational: PDOs ignored
    d = enabled_drive()
    d.on_command(0x0F, 100.0)
    assert d.applied_torque == 28.0
    d.on_command(0x06, 5.0)  # shutdown
    assert d.power is PowerState.READY_TO_SWITCH_ON and d.applied_torque == 0.0


def test_missing_commands_fault_the_drive_with_emcy() -> None:
    d = enabled_drive()
    d.on_command(0x0F, 3.0)
    d.on_period_end(got_command=True)
    for _ in range(2):
        d.on_period_end(got_command=False)
        assert d.power is PowerState.OPERATION_ENABLED
    d.on_period_end(got_command=False)
    assert d.power is PowerState.FAULT and d.applied_torque == 0.0
    assert d.emcy_pending == [EMCY_RPDO_TIMEOUT]
    assert d.power.statusword & 0x0008


def test_fault_reset_needs_a_rising_edge() -> None:
    s = PowerState.FAULT
    assert next_state(s, 0x80, 0x80) is PowerState.FAULT
    assert next_state(s, 0x80, 0x00) is PowerState.SWITCH_ON_DISABLED


def test_nmt_stop_removes_torque() -> None:
    d = enabled_drive()
    d.on_command(0x0F, 5.0)
    assert d.nmt_state == NMT_STATE_OPERATIONAL and d.applied_torque == 5.0
    d.on_nmt(NMT_STOP)
    assert d.applied_torque == 0.0
