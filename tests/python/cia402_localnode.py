"""A CiA 402 drive for the CANopen tests: python-canopen's LocalNode with an EDS or DCF (anyone's),
keeping that file's rules in its SDO callbacks as a real drive of that file would:
- access (LocalNode: ro/const refused, 0x06010002) and length (0x06070010);
- the file's limits (0x06090030);
- PDO mapping: written only while the PDO is invalid (0x08000022), the count 0 before the entries,
  each entry an object the file marks PDOMapping=1 in the PDO's direction (rww: receive PDOs only,
  rwr: transmit PDOs only) and of its whole size (0x06040041), no more entries than the mapping
  object has and no more than 64 bits (0x06040042);
- modes: 0x6060 takes 0 and the modes 0x6502 lists (0x06090030), and 0x6061 shows it;
- the power state machine on the controlword, as the boot confirms each state over SDO.
A value the file gives none of reads 0 (a drive always has one)."""

from __future__ import annotations

import json
import struct
import subprocess
import threading
import time
from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import ODVariable
from canopen.sdo import SdoAbortedError
from canopen_network import loopback_network

RPDO_MAP, TPDO_MAP = range(0x1600, 0x1800), range(0x1A00, 0x1C00)


class FileDrive:
    """A LocalNode that behaves as the drive its file describes, as far as a boot needs."""

    def __init__(self, node_id: int, eds: Path, reject_mode: bool = False, device_type: int | None = None,
                 in_fault: bool = False, stuck_at: int | None = None,
                 late: tuple[int, int, float] | None = None,
                 commissioned: dict[tuple[int, int], int] | None = None) -> None:
        self.node = canopen.LocalNode(node_id, str(eds))
        self.od = self.node.object_dictionary
        for (index, sub), value in (commissioned or {}).items():  # set up for this arm before the master comes
            var = self.var(index, sub)
            assert var is not None, f"0x{index:04X}:{sub:02X} is not in {eds.name}"
            self.node.data_store.setdefault(index, {})[sub] = var.encode_raw(value)
        self.late = late  # (index, sub, seconds): the first read of it is answered that late
        self.id = node_id
        self.reject_mode = reject_mode
        self.device_type = device_type
        self.sw = 0x0008 if in_fault else 0x0040  # fault, or switch on disabled
        self.cw = 0
        self.stuck_at = stuck_at  # a statusword state the drive never leaves
        self.mode = 0
        self.writes: list[tuple[int, int, int]] = []  # (index, sub, value) in the order they came
        self.lock = threading.Lock()
        self.node.add_write_callback(self.on_write)
        self.node.add_read_callback(self.on_read)

    def var(self, index: int, sub: int = 0) -> ODVariable | None:
        if index not in self.od:
            return None
        obj = self.od[index]
        if isinstance(obj, ODVariable):
            return obj if sub == 0 else None
        return obj[sub] if sub in obj.subindices else None

    def stored(self, index: int, sub: int = 0) -> int:
        var = self.var(index, sub)
        assert var is not None, f"0x{index:04X}:{sub:02X} is not in the file"
        return var.decode_raw(self.node.get_data(index, sub))

    def has(self, index: int, sub: int = 0) -> bool:
        return self.var(index, sub) is not None

    def on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        if self.late is not None and (index, subindex) == self.late[:2]:
            time.sleep(self.late[2])  # the network's one receive thread: later requests wait too
            self.late = None
        if index == 0x6041:
            return self.sw
        if index == 0x6061:
            return self.mode
        if index == 0x1000 and self.device_type is not None:
            return self.device_type
        if (od.value is None and od.default is None and subindex not in self.node.data_store.get(index, {})
                and od.data_type in canopen.objectdictionary.NUMBER_TYPES):
            return 0
        return None

    def _mapping_rule(self, index: int, subindex: int, value: int) -> None:
        receive = index in RPDO_MAP
        comm = index - 0x200
        if not self.stored(comm, 1) & 0x80000000:
            raise SdoAbortedError(0x08000022)  # a mapping written while its PDO is valid
        mapping = self.od[index]
        if subindex != 0:
            if self.stored(index, 0) != 0:
                raise SdoAbortedError(0x08000022)  # CiA 301: the count 0 first
            self._entry_rule(value, receive)
            return
        capacity = max((s for s in mapping.subindices if s != 0), default=0)
        if value > capacity:
            raise SdoAbortedError(0x06040042)
        entries = [self.stored(index, s) for s in range(1, value + 1)]
        for e in entries:
            self._entry_rule(e, receive)
        if sum(e & 0xFF for e in entries) > 64:
            raise SdoAbortedError(0x06040042)

    def _entry_rule(self, entry: int, receive: bool) -> None:
        target = self.var(entry >> 16, entry >> 8 & 0xFF)
        if target is None:
            raise SdoAbortedError(0x06040041)
        access = target.access_type
        direction = (target.writable and access != "rwr") if receive else (target.readable and access != "rww")
        if not target.pdo_mappable or not direction or len(target) != entry & 0xFF:
            raise SdoAbortedError(0x06040041)

    def on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = od.decode_raw(data)
        if isinstance(value, (int, float)) and ((od.min is not None and value < od.min) or
                                                (od.max is not None and value > od.max)):
            raise SdoAbortedError(0x06090030)
        if index in RPDO_MAP or index in TPDO_MAP:
            self._mapping_rule(index, subindex, value)
        if index == 0x6060:
            modes = self.stored(0x6502) if self.has(0x6502) else 1 << 9
            if self.reject_mode or (value != 0 and not (1 <= value <= 16 and modes >> (value - 1) & 1)):
                raise SdoAbortedError(0x06090030)
            self.mode = value
        if index == 0x6040:
            rising_reset = value & 0x80 and not self.cw & 0x80
            self.cw = value
            if self.sw & 0x08:  # fault: only bit 7's rising edge leaves it (to switch on disabled)
                if rising_reset:
                    self.sw = 0x0040
            else:
                state = {0x00: 0x40, 0x06: 0x21, 0x07: 0x23, 0x0F: 0x27}.get(value & 0x8F)
                operational = self.node.nmt.state == "OPERATIONAL"
                if state is not None and (state != 0x27 or operational) and self.sw != self.stuck_at:
                    self.sw = state
        with self.lock:
            self.writes.append((index, subindex, value))



def controller_on_localnodes(ctl: Path, group: str, port: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                             drives: dict[int, FileDrive], emcy_at: tuple[int, int, int] | None = None,
                             duration: str = "0.5", args: list[str] | None = None,
                             positions: dict[int, int] | None = None) -> tuple[subprocess.CompletedProcess[str], dict]:
    """arm_controller --protocol canopen (extra args) on LocalNodes that answer each SYNC with
    TPDO1 (position: positions[node], else 1000 x node increments; velocity 0) and TPDO2 (the torque
    of the RPDO1 the drive applied at that SYNC, CiA 301's synchronous RPDO); emcy_at = (node, SYNC
    number, code): that node sends that EMCY then, and faults (statusword fault) unless the code is
    0x0000, CiA 301's "error reset or no error". The process and its summary."""
    net = loopback_network(monkeypatch, group, port)
    summary = tmp_path / "controller.json"
    syncs = [0]
    pending = {i: 0 for i in drives}  # the latest RPDO1 torque, applied at the next SYNC (type 1)
    try:
        for i, d in drives.items():
            net.add_node(d.node)

            def on_rpdo(can_id: int, data: bytes, ts: float, i: int = i) -> None:
                pending[i] = struct.unpack("<Hh", data)[1]

            net.subscribe(0x200 + i, on_rpdo)

        def on_sync(can_id: int, data: bytes, ts: float) -> None:
            syncs[0] += 1
            for i, d in drives.items():
                if d.node.nmt.state != "OPERATIONAL":
                    continue
                if emcy_at is not None and emcy_at[0] == i and syncs[0] == emcy_at[1]:
                    d.sw = 0x0008 if emcy_at[2] else d.sw  # fault, torque off
                    net.send_message(0x080 + i, struct.pack("<HB5x", emcy_at[2], 0x11))
                net.send_message(0x180 + i, struct.pack("<ii", (positions or {}).get(i, 1000 * i), 0))
                net.send_message(0x280 + i, struct.pack("<hH", 0 if d.sw & 0x08 else pending[i], d.sw))

        net.subscribe(0x080, on_sync)
        p = subprocess.run([str(ctl), "--protocol", "canopen", "--bus", f"udp:{group}:{port}", "--mode", "lockstep",
                            "--duration", duration, "--ref-hold", "0.1", "--lcm-url", "", "--boot-timeout", "5",
                            "--summary", str(summary), *(args or [])], capture_output=True, text=True, timeout=300)
    finally:
        for d in drives.values():
            d.node.nmt.stop_heartbeat()
        net.disconnect()
    return p, json.loads(summary.read_text())
