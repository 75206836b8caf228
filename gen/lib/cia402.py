"""The CiA 402 drives' PDOs as the firmware's codec packs them (firmware/canopen/include/arm/co_pdo.h):
one definition for the drive table's check (gen/drives.py), the bus load (gen/lib/busload.py),
the bus timing's frame lengths (host_sim/launch.py) and the derived DBC (gen/canopen_dbc.py)."""

from __future__ import annotations

# (index, sub, bits) per PDO, in frame order: the contract's mapping, which the codec packs
CODEC_MAPPING: dict[str, list[tuple[int, int, int]]] = {
    "rpdo1": [(0x6040, 0, 16), (0x6071, 0, 16)],  # controlword, target torque
    "tpdo1": [(0x6064, 0, 32), (0x606C, 0, 32)],  # position, velocity actual
    "tpdo2": [(0x6077, 0, 16), (0x6041, 0, 16)],  # torque actual, statusword
}
# CiA 301's predefined COB-IDs (+ node id), which the master's boot writes (firmware/canopen co_boot.c)
PDO_COB = {"tpdo1": 0x180, "rpdo1": 0x200, "tpdo2": 0x280}
# Every object the master reads, writes or maps (co_boot.c's sequence, the PDOs above): a mistake in
# any other object of a drive's file is a warning, not a refusal (gen/eds.py)
MASTER_OBJECTS = frozenset({
    0x1000, 0x1018, 0x6502, 0x6076, 0x608F, 0x6091, 0x6072, 0x6040, 0x6041,  # identity, modes, units, state
    0x1400, 0x1600, 0x1800, 0x1A00, 0x1801, 0x1A01,                            # RPDO1, TPDO1, TPDO2
    0x1006, 0x1017, 0x1016, 0x6060, 0x6061,                                    # cycle, heartbeats, mode
    *(index for mapping in CODEC_MAPPING.values() for index, _, _ in mapping),
})


def pdo_bytes(name: str) -> int:
    """The data bytes of a PDO as mapped."""
    return sum(bits for _, _, bits in CODEC_MAPPING[name]) // 8
