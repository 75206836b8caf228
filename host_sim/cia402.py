"""CiA 402 power state machine of one drive: statusword values and controlword transitions."""

from __future__ import annotations

from enum import Enum


class PowerState(Enum):
    SWITCH_ON_DISABLED = 0x0250
    READY_TO_SWITCH_ON = 0x0231
    SWITCHED_ON = 0x0233
    OPERATION_ENABLED = 0x0237
    FAULT = 0x0218

    @property
    def statusword(self) -> int:
        return self.value


CW_FAULT_RESET = 0x0080


def next_state(state: PowerState, controlword: int, prev_controlword: int) -> PowerState:
    """The transition a controlword causes (CiA 402 device control, the subset drives use)."""
    if state is PowerState.FAULT:
        rising_reset = controlword & CW_FAULT_RESET and not prev_controlword & CW_FAULT_RESET
        return PowerState.SWITCH_ON_DISABLED if rising_reset else state
    if controlword & 0x0082 == 0x0000:  # disable voltage
        return PowerState.SWITCH_ON_DISABLED
    if controlword & 0x0086 == 0x0002:  # quick stop (this drive stops at once: torque off)
        return PowerState.SWITCH_ON_DISABLED
    if controlword & 0x0087 == 0x0006:  # shutdown
        return PowerState.READY_TO_SWITCH_ON
    if controlword & 0x008F == 0x0007:  # switch on / disable operation
        if state in (PowerState.READY_TO_SWITCH_ON, PowerState.SWITCHED_ON, PowerState.OPERATION_ENABLED):
            return PowerState.SWITCHED_ON
        return state
    if controlword & 0x008F == 0x000F:  # enable operation
        if state in (PowerState.SWITCHED_ON, PowerState.OPERATION_ENABLED):
            return PowerState.OPERATION_ENABLED
        return state
    return state
