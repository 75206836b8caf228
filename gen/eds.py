"""Read a CANopen EDS or DCF (CiA 306) as a drive's object dictionary, and write it as the
emulated drive's table: `python -m gen.eds --eds F --out DIR` (the build's compiled-in table, the
project's own drive) or `--table FILE` (a table arm_sim loads with --od: any drive's file).

What a real file may hold, and how it is read:
- every CiA 301 basic data type (0x0001-0x001B): booleans, integers of 8 to 64 bits, REAL32 and
  REAL64, VISIBLE_STRING, OCTET_STRING, UNICODE_STRING, DOMAIN, TIME_OF_DAY, TIME_DIFFERENCE;
- a DCF's ParameterValue (the configured value) over the DefaultValue;
- `$NODEID` in a value or limit: `$NODEID`, `$NODEID+N` or `N+$NODEID`, relative to the node id;
- ARRAY objects written whole (`CompactSubObj=N`, names from [XXXXName], values from [XXXXValue]);
- objects the profiles make optional may be missing: the file lists what it has
  ([MandatoryObjects], [OptionalObjects], [ManufacturerObjects]).
A broken file (an unknown type, a broken $NODEID, a default PDO mapping longer than 64 bits, no
[MandatoryObjects], a value its type cannot hold, ...) is one line naming the section and the key,
exit 2. Vendors' files as they are: a mistake in an object the CANopen master never uses
(gen/lib/cia402.py MASTER_OBJECTS) leaves that object out, and a limit its data type cannot hold,
or one that cuts into the values CiA 301's definition of the object needs (0x1016's node id, a PDO
COB-ID's valid bit), is ignored; each is a warning naming the file's line (Dictionary.warnings),
not a refusal. Parsed with configparser as python-canopen does (the file is an INI file)."""

from __future__ import annotations

import argparse
import configparser
import math
import re
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from gen.lib.atomic_output import exit_on_output_error, write_files_atomically, write_text_atomic
from gen.lib.cia402 import MASTER_OBJECTS
from gen.lib.escape import c_comment, c_string
from gen.lib.one_line import one_line


@dataclass(frozen=True)
class DataType:
    name: str
    size: int   # bytes; 0: a string or domain (its length is its value's)
    kind: str   # bool, int, uint, float, text (VISIBLE/UNICODE_STRING), bytes (OCTET_STRING, DOMAIN)


# CiA 301 Table 44, the basic data types (0x000E and 0x0017 are reserved).
TYPES: dict[int, DataType] = {
    0x0001: DataType("BOOLEAN", 1, "bool"), 0x0002: DataType("INTEGER8", 1, "int"),
    0x0003: DataType("INTEGER16", 2, "int"), 0x0004: DataType("INTEGER32", 4, "int"),
    0x0005: DataType("UNSIGNED8", 1, "uint"), 0x0006: DataType("UNSIGNED16", 2, "uint"),
    0x0007: DataType("UNSIGNED32", 4, "uint"), 0x0008: DataType("REAL32", 4, "float"),
    0x0009: DataType("VISIBLE_STRING", 0, "text"), 0x000A: DataType("OCTET_STRING", 0, "bytes"),
    0x000B: DataType("UNICODE_STRING", 0, "text"), 0x000C: DataType("TIME_OF_DAY", 6, "uint"),
    0x000D: DataType("TIME_DIFFERENCE", 6, "uint"), 0x000F: DataType("DOMAIN", 0, "bytes"),
    0x0010: DataType("INTEGER24", 3, "int"), 0x0011: DataType("REAL64", 8, "float"),
    0x0012: DataType("INTEGER40", 5, "int"), 0x0013: DataType("INTEGER48", 6, "int"),
    0x0014: DataType("INTEGER56", 7, "int"), 0x0015: DataType("INTEGER64", 8, "int"),
    0x0016: DataType("UNSIGNED24", 3, "uint"), 0x0018: DataType("UNSIGNED40", 5, "uint"),
    0x0019: DataType("UNSIGNED48", 6, "uint"), 0x001A: DataType("UNSIGNED56", 7, "uint"),
    0x001B: DataType("UNSIGNED64", 8, "uint"),
}
# CiA 306 access types: rww/rwr are rw seen from the PDOs' side (mappable to an RPDO / a TPDO).
ACCESS = {"ro": "RO", "rw": "RW", "wo": "WO", "const": "CONST", "rww": "RW", "rwr": "RW"}
OBJECT_TYPES = {0x2: "DOMAIN", 0x5: "DEFTYPE", 0x6: "DEFSTRUCT", 0x7: "VAR", 0x8: "ARRAY", 0x9: "RECORD"}
LISTS = ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects")
PDO_MAPPINGS = (range(0x1600, 0x1800), range(0x1A00, 0x1C00))
MAX_PDO_BITS = 64  # a classic CAN frame's payload

Value = int | float | str | bytes


class EdsError(ValueError):
    """A broken file: one line naming the section and the key (section, key: where, if known)."""

    def __init__(self, message: str, section: str | None = None, key: str | None = None) -> None:
        super().__init__(message)
        self.section, self.key = section, key


def _defined_range(index: int, sub: int) -> tuple[int, str] | None:
    """For an object whose values CiA 301 defines field by field: the highest value its definition
    needs a HighLimit to allow, and why. A file's HighLimit below it contradicts the object."""
    if index == 0x1016 and 1 <= sub <= 127:
        return 0x007FFFFF, "the consumer heartbeat's node id is in bits 16-23 and its time in ms in bits 0-15"
    if (0x1400 <= index <= 0x15FF or 0x1800 <= index <= 0x19FF) and sub == 1:
        return 0x800007FF, "a PDO COB-ID's bit 31 marks it invalid, and the master sets it while mapping"
    return None


@dataclass(frozen=True)
class Entry:
    """One variable: an object (VAR) or a sub-index of an ARRAY or RECORD."""
    index: int
    sub: int
    name: str
    dtype: int
    access: str            # RO, RW, WO, CONST
    access_raw: str        # as the file says (rww, rwr: which PDO direction it maps to)
    default: Value         # ParameterValue if the file has one (a DCF), else DefaultValue; nodeid_rel: + node id
    nodeid_rel: bool
    low: int | float | None
    high: int | float | None
    pdo: bool
    configured: bool       # the value is a DCF's ParameterValue

    @property
    def type(self) -> DataType:
        return TYPES[self.dtype]

    @property
    def readable(self) -> bool:
        return self.access != "WO"

    @property
    def writable(self) -> bool:
        return self.access in ("RW", "WO")

    def value(self, node_id: int) -> Value:
        """The entry's value on node node_id."""
        return self.default + node_id if self.nodeid_rel and isinstance(self.default, int) else self.default

    def bits(self) -> int:
        return 8 * self.type.size


@dataclass
class Dictionary:
    """A drive's object dictionary as its EDS or DCF describes it."""
    path: Path
    entries: list[Entry]
    object_names: dict[int, str]
    listed: dict[str, set[int]]                  # [MandatoryObjects] ...: the indices each lists
    device: dict[str, str] = field(default_factory=dict)  # [DeviceInfo]
    node_id: int | None = None                   # a DCF's [DeviceComissioning] NodeID
    # the file's harmless mistakes, "FILE:LINE: ...": an object left out, a limit ignored
    warnings: list[str] = field(default_factory=list)
    _by_key: dict[tuple[int, int], Entry] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._by_key = {(e.index, e.sub): e for e in self.entries}

    def get(self, index: int, sub: int = 0) -> Entry | None:
        return self._by_key.get((index, sub))

    def has(self, index: int) -> bool:
        return index in self.object_names

    def subs(self, index: int) -> list[Entry]:
        return [e for e in self.entries if e.index == index]


def _where(section: str, key: str, text: str) -> str:
    return one_line(f"[{section}] {key}={text}")


def _fail(section: str, key: str, text: str, why: str) -> EdsError:
    return EdsError(f"{_where(section, key, text)}: {why}", section, key)


def _int(section: str, key: str, text: str) -> int:
    t = text.strip()
    try:
        if re.fullmatch(r"[+-]?0[0-7]+", t):  # CiA 306: a leading 0 is octal
            return int(t, 8)
        return int(t, 0)
    except ValueError:
        raise _fail(section, key, text, "not an integer") from None


def _nodeid(section: str, key: str, text: str) -> tuple[str, bool]:
    """A value without its $NODEID term, and whether it had one (the value is then node-relative)."""
    if "$" not in text:
        return text, False
    t = text.replace(" ", "").replace("\t", "")
    m = re.fullmatch(r"\$NODEID(?:\+(.+))?", t, re.IGNORECASE) or re.fullmatch(r"(.+)\+\$NODEID", t, re.IGNORECASE)
    if m is None or (m.group(1) is not None and "$" in m.group(1)):
        raise _fail(section, key, text, "a $NODEID value is $NODEID, $NODEID+N or N+$NODEID")
    return m.group(1) or "0", True


def _number(section: str, key: str, text: str, dtype: int) -> int | float:
    """A number of type dtype: integers within the type's range (hex beyond a signed type's maximum
    is its two's complement, as python-canopen reads limits), floats as written."""
    t = TYPES[dtype]
    if t.kind == "float":
        try:
            x = float(text)
        except ValueError:
            raise _fail(section, key, text, f"not a {t.name} number") from None
        if math.isnan(x) or (t.size == 4 and abs(x) > 3.4028235e38 and not math.isinf(x)):
            raise _fail(section, key, text, f"not a finite {t.name}")
        return x
    v = _int(section, key, text)
    lo, hi = _type_range(dtype)
    if t.kind == "int" and text.strip().lower().startswith("0x") and hi < v <= 2 * hi + 1:
        v -= 2 * hi + 2
    if not lo <= v <= hi:
        raise _fail(section, key, text, f"out of range for {t.name} ({lo}..{hi})")
    return v


def _type_range(dtype: int) -> tuple[int, int]:
    """The values an integer data type holds."""
    t = TYPES[dtype]
    bits = 8 * t.size
    if t.kind == "int":
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    return 0, (1 << bits) - 1 if t.kind != "bool" else 1


def _value(section: str, key: str, text: str, dtype: int) -> tuple[Value, bool]:
    t = TYPES[dtype]
    if t.kind == "text":
        return text, False
    if t.kind == "bytes":
        try:
            return bytes.fromhex(text), False
        except ValueError:
            if dtype == 0x000F:  # a DOMAIN's default is the tool's (python-canopen's datatypes.eds: "@ABCD")
                return text.encode("utf-8"), False
            raise _fail(section, key, text, f"not hexadecimal bytes ({t.name})") from None
    if text.strip() == "":
        return (0.0 if t.kind == "float" else 0), False
    raw, rel = _nodeid(section, key, text)
    if rel and t.kind not in ("int", "uint"):
        raise _fail(section, key, text, f"$NODEID in a {t.name}")
    return _number(section, key, raw, dtype), rel


Warn = Callable[[str, str, str], None]  # (section, key, what): a warning at the key's line


def _limit(section: str, key: str, text: str, dtype: int, warn: Warn) -> int | float | None:
    """A LowLimit or HighLimit; one its type cannot hold limits nothing the type allows: ignored,
    with a warning."""
    if text.strip() == "" or TYPES[dtype].kind in ("text", "bytes"):
        return None
    raw, _rel = _nodeid(section, key, text)  # a node-relative limit is taken at node 0: the widest
    if TYPES[dtype].kind != "float":
        v, (lo, hi) = _int(section, key, raw), _type_range(dtype)
        wraps = TYPES[dtype].kind == "int" and raw.strip().lower().startswith("0x") and hi < v <= 2 * hi + 1
        if not wraps and not lo <= v <= hi:
            warn(section, key, f"{_where(section, key, text)}: out of range for {TYPES[dtype].name} ({lo}..{hi}): "
                               "the limit is ignored")
            return None
    return _number(section, key, raw, dtype)


class _File:
    """The INI sections of one file, looked up without regard to case (CiA 306 names them
    [1018sub1] or [1018Sub1]), every key a section has."""

    def __init__(self, path: Path) -> None:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise EdsError(f"{path}: {exc.strerror or exc}") from None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("cp1252", errors="replace")  # vendors' tools write Windows-1252
        cp = configparser.RawConfigParser(inline_comment_prefixes=(";",), strict=True, interpolation=None)
        cp.optionxform = str  # type: ignore[assignment,method-assign]  # keys keep their case
        try:
            cp.read_string(text, source=str(path))
        except configparser.Error as exc:
            raise EdsError(one_line(f"{path}: {str(exc).splitlines()[0]}")) from None
        self.path = path
        self.sections: dict[str, dict[str, str]] = {}
        self.names: dict[str, str] = {}
        self.lines: dict[tuple[str, str], int] = {}  # (section, key; "" the header) -> its line, 1-based
        section = ""
        for number, line in enumerate(text.splitlines(), 1):
            t = line.strip()
            if t.startswith("[") and "]" in t:
                section = t[1:t.index("]")].strip().lower()
                self.lines.setdefault((section, ""), number)
            elif "=" in t and not t.startswith((";", "#")):
                self.lines.setdefault((section, t.split("=", 1)[0].strip()), number)
        for s in cp.sections():
            if s.lower() in self.sections:
                raise EdsError(one_line(f"{path}: section [{s}] appears twice"))
            self.sections[s.lower()] = {k: v.strip() for k, v in cp[s].items()}
            self.names[s.lower()] = s

    def get(self, section: str) -> dict[str, str] | None:
        return self.sections.get(section.lower())

    def name(self, section: str) -> str:
        return self.names.get(section.lower(), section)

    def line(self, section: str | None, key: str | None = None) -> str:
        """FILE:LINE of a key (else of its section's header)."""
        s = (section or "").lower()
        n = self.lines.get((s, key or "")) or self.lines.get((s, ""))
        return f"{self.path}:{n}" if n else str(self.path)


def _entry(f: _File, section: str, index: int, sub: int, s: dict[str, str], warn: Warn, name: str | None = None,
           value: str | None = None) -> Entry:
    where = f.name(section)
    for key in ("DataType", "AccessType"):
        if key not in s:
            raise EdsError(f"[{where}] has no {key}", where)
    dtype = _int(where, "DataType", s["DataType"])
    if dtype not in TYPES:
        raise _fail(where, "DataType", s["DataType"], "not a CiA 301 basic data type (0x0001-0x001B; 0x000E and "
                    "0x0017 are reserved)")
    access_raw = s["AccessType"].strip().lower()
    if access_raw not in ACCESS:
        raise _fail(where, "AccessType", s["AccessType"], "expected ro, rw, wo, rww, rwr or const")
    # an empty ParameterValue is a DCF's "not configured": the DefaultValue stands
    configured = value is not None or s.get("ParameterValue", "") != ""
    key = "ParameterValue" if configured else "DefaultValue"
    text = value if value is not None else s.get(key, "")
    default, rel = _value(where, key, text, dtype)
    low = _limit(where, "LowLimit", s.get("LowLimit", ""), dtype, warn)
    high = _limit(where, "HighLimit", s.get("HighLimit", ""), dtype, warn)
    defined = _defined_range(index, sub)
    if defined is not None and high is not None and high < defined[0]:
        warn(where, "HighLimit", f"{_where(where, 'HighLimit', s['HighLimit'])}: below 0x{defined[0]:X}, which CiA "
                                 f"301's definition of 0x{index:04X} needs ({defined[1]}): the limit is ignored")
        high = None
    if low is not None and high is not None and low > high:
        raise EdsError(f"[{where}] LowLimit={s['LowLimit']} is above HighLimit={s['HighLimit']}", where, "LowLimit")
    pdo = _int(where, "PDOMapping", s.get("PDOMapping", "0") or "0") != 0
    return Entry(index, sub, one_line(name if name is not None else s.get("ParameterName", "")), dtype,
                 ACCESS[access_raw], access_raw, default, rel, low, high, pdo, configured)


def _lists(f: _File) -> dict[str, set[int]]:
    out: dict[str, set[int]] = {}
    for lst in LISTS:
        s = f.get(lst)
        if s is None:
            if lst == "MandatoryObjects":
                raise EdsError(f"{f.path}: no [MandatoryObjects] section (CiA 306: every EDS lists its mandatory "
                               "objects, 0x1000, 0x1001 and 0x1018)")
            out[lst] = set()
            continue
        # the entries, not SupportedObjects: vendors' files miscount it (python-canopen's e35.eds)
        out[lst] = {_int(lst, k, v) for k, v in s.items() if k.isdigit()}
    return out


def _compact(f: _File, section: str, index: int, s: dict[str, str], warn: Warn) -> list[Entry]:
    """An ARRAY written whole: sub 0 is its length, 1..N share the object's type and limits."""
    where = f.name(section)
    n = _int(where, "CompactSubObj", s["CompactSubObj"])
    if not 1 <= n <= 254:
        raise _fail(where, "CompactSubObj", s["CompactSubObj"], "expected 1..254 sub-indices")
    names = f.get(f"{section}Name") or {}
    values = f.get(f"{section}Value") or {}
    out = [Entry(index, 0, "Number of entries", 0x0005, "RO", "ro", n, False, None, None, False, False)]
    base = s.get("ParameterName", "")
    for k in range(1, n + 1):
        name = names.get(str(k), f"{base}{k}")
        out.append(_entry(f, section, index, k, s, warn, name=name, value=values.get(str(k))))
    return out


def _long_mappings(d: Dictionary, node_id: int) -> list[tuple[int, str]]:
    """The default PDO mappings longer than a frame: (mapping index, why)."""
    out = []
    for e in d.entries:
        if e.sub != 0 or not any(e.index in r for r in PDO_MAPPINGS) or not isinstance(e.default, int):
            continue
        count = e.value(node_id)
        entries = [d.get(e.index, k) for k in range(1, int(count) + 1)]
        bits = sum(int(m.value(node_id)) & 0xFF for m in entries if m is not None and isinstance(m.default, int))
        if bits > MAX_PDO_BITS:
            out.append((e.index, f"[{e.index:04X}] its mapping of {count} entries is {bits} bits, more than the "
                                 f"{MAX_PDO_BITS} of a CAN frame"))
    return out


def _leave_out(where: str, index: int, names: dict[int, str]) -> str:
    return f"{where}: 0x{index:04X} ({names.get(index, '')}) is left out: the master never uses it"



def _object(f: _File, low: str, s: dict[str, str], warn: Warn) -> list[Entry]:
    """The entries of one object (the section [low] and its [lowsubN])."""
    where = f.name(low)
    index = int(low, 16)
    otype = _int(where, "ObjectType", s.get("ObjectType", "0x7") or "0x7")
    if otype not in OBJECT_TYPES:
        raise _fail(where, "ObjectType", s["ObjectType"],
                    f"expected one of {', '.join(f'0x{k:X} ({v})' for k, v in OBJECT_TYPES.items())}")
    if otype in (0x2, 0x5, 0x7):
        return [_entry(f, low, index, 0, s, warn)]
    if "CompactSubObj" in s:  # CiA 306 says ARRAY; Lely's dcfgen writes it for records too
        return _compact(f, low, index, s, warn)
    subs = sorted(k for k in f.sections if re.fullmatch(rf"{low}sub[0-9a-f]+", k))
    if not subs:
        raise EdsError(f"[{where}] is an ARRAY/RECORD with no [{where}subN] sections", where)
    return [_entry(f, k, index, int(k[len(low) + 3:], 16), f.sections[k], warn) for k in subs]


def load(path: Path) -> Dictionary:
    """Every object of the EDS or DCF, its entries sorted by index and sub-index. A mistake in an
    object the master uses is an EdsError; in another object, or a limit that limits nothing or
    contradicts the object's definition, a warning (Dictionary.warnings)."""
    f = _File(path)
    listed = _lists(f)
    entries: list[Entry] = []
    names: dict[int, str] = {}
    warnings: list[str] = []

    def warn(section: str, key: str, what: str) -> None:
        warnings.append(one_line(f"{f.line(section, key)}: {what}"))

    for low, s in f.sections.items():
        if not re.fullmatch(r"[0-9a-f]{4}", low):
            continue
        index = int(low, 16)
        names[index] = one_line(s.get("ParameterName", ""))
        try:
            entries.extend(_object(f, low, s, warn))
        except EdsError as exc:
            if index in MASTER_OBJECTS:
                raise
            del names[index]  # a vendor's harmless mistake: the object no one here uses is left out
            warnings.append(one_line(_leave_out(f"{f.line(exc.section or low, exc.key)}: {exc}", index,
                                                {index: s.get('ParameterName', '')})))
    if not entries:
        raise EdsError(f"{path}: no objects")
    dummies = f.get("DummyUsage") or {}
    for k in range(1, 8):  # CiA 306: the dummy objects a mapping may name to skip bytes (an RPDO's padding)
        if _int("DummyUsage", f"Dummy{k:04d}", dummies.get(f"Dummy{k:04d}", "0") or "0") and k not in names:
            names[k] = f"Dummy{k:04d}"
            entries.append(Entry(k, 0, names[k], k, "CONST", "const", 0, False, None, None, True, False))
    entries.sort(key=lambda e: (e.index, e.sub))
    for a, b in zip(entries, entries[1:]):
        if (a.index, a.sub) == (b.index, b.sub):
            raise EdsError(f"{path}: object 0x{a.index:04X} sub {a.sub} is defined twice")
    commissioning = f.get("DeviceComissioning") or {}
    node_id = None
    if commissioning.get("NodeID", "").strip():
        node_id = _int("DeviceComissioning", "NodeID", commissioning["NodeID"])
    d = Dictionary(path, entries, names, listed, dict(f.get("DeviceInfo") or {}), node_id)
    for mapping, why in _long_mappings(d, node_id or 1):
        if mapping in MASTER_OBJECTS:
            raise EdsError(why, f"{mapping:04X}")
        comm = mapping - 0x200  # the PDO goes whole: its communication object with its mapping
        warnings.append(one_line(_leave_out(f"{f.line(f'{mapping:04X}', 'SubNumber')}: {why}", mapping, names)
                                 + f"; nor its PDO's 0x{comm:04X}"))
        d = Dictionary(path, [e for e in d.entries if e.index not in (mapping, comm)],
                       {i: n for i, n in names.items() if i not in (mapping, comm)}, listed, d.device, node_id)
        names = d.object_names
    d.warnings = warnings
    return d


def entries(path: Path) -> list[Entry]:
    """Every variable of the file, sorted by index and sub-index."""
    return load(path).entries


# ---- the emulated drive's table (arm_sim --od, host_sim/native/sim_canopen_od.c) --------------
TABLE_MAGIC = "arm_sim od 1"
KIND_CODE = {"bool": 0, "int": 1, "uint": 2, "float": 3, "text": 4, "bytes": 5}  # sim_co_kind_t
ACCESS_CODE = {"ro": 0, "rw": 1, "wo": 2, "const": 3, "rww": 4, "rwr": 5}       # sim_co_access_t


def _raw(e: Entry, v: Value) -> str:
    """A value as the table keeps it: a number's bits (two's complement, IEEE 754) in hex, a
    string's bytes in hex ('-' for none)."""
    t = e.type
    if t.kind in ("text", "bytes"):
        b = v.encode("utf-8") if isinstance(v, str) else bytes(v)  # type: ignore[arg-type]
        return b.hex() or "-"
    if t.kind == "float":
        fmt = "<f" if t.size == 4 else "<d"
        return f"{int.from_bytes(struct.pack(fmt, float(v)), 'little'):x}"  # type: ignore[arg-type]
    return f"{int(v) & ((1 << (8 * t.size)) - 1):x}"  # type: ignore[arg-type]


def table_text(d: Dictionary) -> str:
    """The table arm_sim reads (host_sim/native/sim_canopen_od.c): one line per entry, sorted:
    index, sub, data type, its kind and size, access, PDO mapping, node-relative, value, low and
    high limit ('-': none), numbers hex. A node-relative value is kept without the node id."""
    lines = [f"{TABLE_MAGIC} {len(d.entries)}"]
    for e in d.entries:
        lo = "-" if e.low is None else _raw(e, e.low)
        hi = "-" if e.high is None else _raw(e, e.high)
        lines.append(f"{e.index:x} {e.sub:x} {e.dtype:x} {KIND_CODE[e.type.kind]} {e.type.size} "
                     f"{ACCESS_CODE[e.access_raw]} {int(e.pdo)} {int(e.nodeid_rel)} {_raw(e, e.default)} {lo} {hi}")
    return "\n".join(lines) + "\n"


def builtin_c(d: Dictionary) -> dict[str, str]:
    """The project's own drive's table compiled into arm_sim (its default without --od)."""
    head = f"/* Generated by gen/eds.py from {c_comment(d.path.name)}. Do not edit. */\n"
    body = "".join(f"    {c_string(line + chr(10), f'{d.path.name}: the table line of {line[:12]}')}\n"
                   for line in table_text(d).splitlines())
    return {"sim_co_od_builtin.c": f"{head}#include \"sim_canopen_od.h\"\n\nconst char SIM_CO_OD_BUILTIN[] =\n{body};\n"}


@exit_on_output_error("gen.eds")
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gen.eds", description=__doc__.split("\n\n")[0])
    ap.add_argument("--eds", type=Path, required=True, help="the drive's EDS or DCF")
    out = ap.add_mutually_exclusive_group(required=True)
    out.add_argument("--out", type=Path, help="write DIR/sim_co_od_builtin.c (the build's own drive)")
    out.add_argument("--table", type=Path, help="write the table arm_sim --od reads")
    ns = ap.parse_args(argv)
    try:
        d = load(ns.eds)
    except EdsError as exc:
        print(f"gen.eds: {exc}", file=sys.stderr)
        return 2
    for w in d.warnings:  # the file's harmless mistakes: said, not refused
        print(f"gen.eds: warning: {w}", file=sys.stderr)
    if ns.out is not None:
        write_files_atomically(ns.out, builtin_c(d))
    else:
        write_text_atomic(ns.table, table_text(d))
    return 0


if __name__ == "__main__":
    sys.exit(main())
