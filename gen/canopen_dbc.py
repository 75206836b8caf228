"""The CiA 402 drives' frames as a DBC, derived, never hand-kept: the PDOs' layouts from the drive
table's mapping (gen/drives.py, the codec's), their signals' names and types from the EDS, and each
drive's scaling from its encoder, gear, the motor's rated torque and the gear's efficiency, so that
cantools (or any DBC reader) decodes a capture of a `--protocol canopen` run in the core's SI units
at the joint: rad, rad/s, N m.

    python -m gen.canopen_dbc --arm-json build/release/generated/arm/arm.json [--drive-config F] --out F

armctl hil writes one next to every CANopen run's results (DIR/canopen.dbc). Node id = drive number
on the predefined COB-IDs of CiA 301: SYNC 0x080, EMCY 0x080+n, TPDO1 0x180+n, RPDO1 0x200+n,
TPDO2 0x280+n, SDO 0x580+n (drive) and 0x600+n (master), NMT 0x000, heartbeat 0x700+n."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import cantools
from cantools.database.can import Database, Message, Signal
from cantools.database.conversion import BaseConversion

from gen import drives as drives_mod
from gen import eds as eds_mod
from gen.lib.atomic_output import exit_on_output_error, write_text_atomic
from gen.lib.cia402 import CODEC_MAPPING, PDO_COB
from gen.lib.escape import EscapeError, Identifiers, dbc_string
from gen.lib.one_line import one_line

POSITION_OBJECTS = {0x6064, 0x606C}  # increments, increments/s: at the joint through encoder and gear
TORQUE_OBJECTS = {0x6071, 0x6077}    # per mille of the motor's rated torque 0x6076: at the joint through the gear


class DbcError(ValueError):
    pass




def _scaling(index: int, d: drives_mod.Drive) -> tuple[float, str | None]:
    if index in POSITION_OBJECTS:
        rad = 2.0 * math.pi * d.gear[1] * d.encoder_revs / (d.encoder_increments * d.gear[0])
        return rad, "rad" if index == 0x6064 else "rad/s"
    if index in TORQUE_OBJECTS:
        return d.joint_rated_torque_nm / 1000, "N.m"
    return 1.0, None


def _sig(name: str, start: int, bits: int, signed: bool, scale: float = 1.0, unit: str | None = None,
         comment: str | None = None) -> Signal:
    return Signal(name, start, bits, is_signed=signed, unit=unit, comment=comment,
                  conversion=BaseConversion.factory(scale=scale, offset=0, is_float=False))


def build(cfg: drives_mod.DriveConfig) -> Database:
    """Every frame the master and the drives of this drive table send."""
    objects = {(e.index, e.sub): e for e in eds_mod.entries(Path(cfg.eds))}
    msgs = [Message(0x080, "SYNC", 0, [], senders=["master"]),
            Message(0x000, "NMT", 2, [_sig("command", 0, 8, False), _sig("node", 8, 8, False)], senders=["master"]),
            Message(0x700 + cfg.master_id, "HEARTBEAT_master", 1, [_sig("nmt_state", 0, 8, False)], senders=["master"])]
    for d in sorted(cfg.drives, key=lambda x: x.node):
        n = d.node
        for pdo, mapping in CODEC_MAPPING.items():
            sigs, start = [], 0
            names = Identifiers(f"{pdo.upper()}_node{n}")
            for index, sub, bits in mapping:
                e = objects.get((index, sub))
                if e is None:
                    raise DbcError(f"{cfg.eds}: PDO {pdo} maps 0x{index:04X}:{sub:02X}, which the EDS does not define")
                scale, unit = _scaling(index, d)
                try:  # the EDS's name made an identifier (its index where no letter is left); the name itself kept
                    # beside it, as the comment
                    ident = names.add(e.name, f"{cfg.eds}: 0x{index:04X}:{sub:02X} ParameterName",
                                      fallback=f"object_{index:04x}_{sub:02x}")
                except EscapeError as exc:
                    raise DbcError(str(exc)) from None
                sigs.append(_sig(ident, start, bits, e.type.kind == "int", scale, unit,
                                 comment=dbc_string(f"0x{index:04X}:{sub:02X} {e.name}")))
                start += bits
            msgs.append(Message(PDO_COB[pdo] + n, f"{pdo.upper()}_node{n}", start // 8, sigs,
                                senders=["master" if pdo.startswith("r") else f"node{n}"],
                                comment=dbc_string(f"joint {d.joint}: transmission type {cfg.transmission[pdo]}")))
        msgs.append(Message(0x080 + n, f"EMCY_node{n}", 8, [_sig("error_code", 0, 16, False),
                                                             _sig("error_register", 16, 8, False),
                                                             _sig("manufacturer", 24, 40, False)], senders=[f"node{n}"]))
        for cob, who in ((0x580, f"node{n}"), (0x600, "master")):
            msgs.append(Message(cob + n, f"SDO_{'tx' if cob == 0x580 else 'rx'}_node{n}", 8,
                                [_sig("command", 0, 8, False), _sig("index", 8, 16, False), _sig("sub", 24, 8, False),
                                 _sig("data", 32, 32, False)], senders=[who]))
        msgs.append(Message(0x700 + n, f"HEARTBEAT_node{n}", 1, [_sig("nmt_state", 0, 8, False)], senders=[f"node{n}"]))
    ids = sorted(m.frame_id for m in msgs)
    dup = next((a for a, b in zip(ids, ids[1:]) if a == b), None)
    if dup is not None:
        raise DbcError(f"frame id 0x{dup:03X} twice: the master id {cfg.master_id} or a node id collides")
    return Database(msgs)


def dbc_text(cfg: drives_mod.DriveConfig) -> str:
    return build(cfg).as_dbc_string()


@exit_on_output_error("gen.canopen_dbc")
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m gen.canopen_dbc", description=__doc__.split("\n\n")[0])
    p.add_argument("--arm-json", type=Path, required=True, help="the arm's arm.json (a build's generated/arm/)")
    p.add_argument("--drive-config", type=Path, default=None, help="the drive table [the arm's]")
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args(argv)
    try:
        arm = json.loads(ns.arm_json.read_text())
        text = dbc_text(drives_mod.load(arm, ns.drive_config))
    except (OSError, ValueError, KeyError) as exc:
        print(f"gen.canopen_dbc: {one_line(str(exc))}", file=sys.stderr)
        return 2
    write_text_atomic(ns.out, text)
    cantools.database.load_string(text, database_format="dbc")  # what readers will do with it
    return 0


if __name__ == "__main__":
    sys.exit(main())
