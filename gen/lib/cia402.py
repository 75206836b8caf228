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


def pdo_bytes(name: str) -> int:
    """The data bytes of a PDO as mapped."""
    return sum(bits for _, _, bits in CODEC_MAPPING[name]) // 8
