"""The model hash the controller and the simulator compare at boot: FNV-1a 64 of the prepared
arm.xml (arm_sim computes the same over the file it loads)."""

from __future__ import annotations


def fnv1a64(data: bytes) -> int:
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h
