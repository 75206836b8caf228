"""One emulated motor drive: NMT node, CiA 402 state machine, torque limit, command timeout."""

from __future__ import annotations

from dataclasses import dataclass, field

from host_sim.cia402 import PowerState, next_state
from host_sim.protocol import NMT_START, NMT_STATE_OPERATIONAL, NMT_STATE_PRE_OPERATIONAL, NMT_STATE_STOPPED, NMT_STOP

EMCY_RPDO_TIMEOUT = 0x8250  # CiA 301: RPDO timeout
ERR_NONE = 0
ERR_COMMAND_TIMEOUT = 1


@dataclass
class Drive:
    node_id: int
    torque_limit: float
    command_timeout_periods: int = 3
    nmt_state: int = NMT_STATE_PRE_OPERATIONAL
    power: PowerState = PowerState.SWITCH_ON_DISABLED
    controlword: int = 0
    target_torque: float = 0.0
    periods_without_command: int = 0
    error_code: int = ERR_NONE
    emcy_pending: list[int] = field(default_factory=list)
    commands_received: int = 0
    commands_missed: int = 0

    def on_nmt(self, command: int) -> bool:
        """Returns True if the NMT state changed (the caller then sends a heartbeat)."""
        before = self.nmt_state
        if command == NMT_START:
            self.nmt_state = NMT_STATE_OPERATIONAL
        elif command == NMT_STOP:
            self.nmt_state = NMT_STATE_STOPPED
            self.target_torque = 0.0
        return self.nmt_state != before

    def on_command(self, controlword: int, torque: float) -> None:
        if self.nmt_state != NMT_STATE_OPERATIONAL:
            return  # PDOs are only processed in NMT operational
        self.power = next_state(self.power, controlword, self.controlword)
        self.controlword = controlword
        self.target_torque = max(-self.torque_limit, min(self.torque_limit, torque))
        self.periods_without_command = 0
        self.commands_received += 1

    def on_period_end(self, got_command: bool) -> None:
        """Called once per simulated period; a silent controller trips the drive into fault."""
        if got_command or self.power is not PowerState.OPERATION_ENABLED:
            return
        self.commands_missed += 1
        self.periods_without_command += 1
        if self.periods_without_command >= self.command_timeout_periods:
            self.fault(ERR_COMMAND_TIMEOUT, EMCY_RPDO_TIMEOUT)

    def fault(self, error_code: int, emcy_code: int) -> None:
        if self.power is not PowerState.FAULT:
            self.power = PowerState.FAULT
            self.error_code = error_code
            self.emcy_pending.append(emcy_code)

    @property
    def applied_torque(self) -> float:
        enabled = self.power is PowerState.OPERATION_ENABLED and self.nmt_state == NMT_STATE_OPERATIONAL
        return self.target_torque if enabled else 0.0
