"""ArduPilot DataFlash (.BIN) logs, written as the simulated autopilot runs.

The binary format of `AP_Logger` (libraries/AP_Logger/LogStructure.h): every record is the
header 0xA3 0x95, a message type byte and the packed little-endian fields. The file describes
itself: FMT (type 128, "BBnNZ" Type,Length,Name,Format,Columns) first for itself and then for
every message type, UNIT and MULT name the unit and multiplier characters, and FMTU gives each
type's units and multipliers field by field. Format characters as ArduPilot's: b B h H i I
(integers), f d (float, double), n N Z (char[4], [16], [64]), c C (int16/uint16 * 100),
e E (int32/uint32 * 100), L (int32 latitude/longitude * 1e7), M (uint8 flight mode),
q Q (int64, uint64). pymavlink's DFReader reads it (and so do MAVExplorer and UAV Log Viewer).

The messages are those a boat's identification needs, with ArduPilot's names, formats and
columns: PARM, MODE, ARM, MSG, ORGN, XKF1, ATT, POS, GPS, IMU, RCIN and RCOU. Records are
written and flushed as they come, so a log is readable while it grows and complete up to the
last record if the program is killed.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

HEAD = b"\xa3\x95"
FMT_TYPE = 128

STRUCT_CODES = {
    "a": "32h", "b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f",
    "d": "d", "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I",
    "L": "i", "M": "B", "q": "q", "Q": "Q",
}
SCALE = {"c": 100.0, "C": 100.0, "e": 100.0, "E": 100.0, "L": 1e7}
"""Stored value = physical value * SCALE (centi-units, 1e7 degrees)."""

UNITS = {  # AP_Logger's log_Units (the ones used here)
    "-": "", "#": "instance", "d": "deg", "h": "degheading", "D": "deglatitude",
    "U": "deglongitude", "m": "m", "n": "m/s", "o": "m/s/s", "s": "s", "E": "rad/s",
    "k": "deg/s", "O": "degC", "S": "satellites", "Y": "us", "z": "Hz", "%": "%",
}
MULTIPLIERS = {"-": 0.0, "?": 1.0, "0": 1.0, "B": 1e-2, "C": 1e-3, "F": 1e-6, "G": 1e-7}


@dataclass(frozen=True)
class MessageFormat:
    """One message type: its id, name, format characters, columns, units and multipliers."""

    type: int
    name: str
    format: str
    columns: str
    units: str
    multipliers: str

    def __post_init__(self):
        n = len(self.format)
        if not (len(self.columns.split(",")) == len(self.units) == len(self.multipliers) == n):
            raise ValueError(f"{self.name}: format, columns, units and multipliers differ in length")

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(STRUCT_CODES[c] for c in self.format))

    @property
    def length(self) -> int:
        """Bytes of a record, the 3-byte header included (FMT's Length)."""
        return 3 + self.struct.size


_RC14 = ",".join(f"C{i}" for i in range(1, 15))
MESSAGES = {f.name: f for f in (
    MessageFormat(129, "UNIT", "QbZ", "TimeUS,Id,Label", "s--", "F--"),
    MessageFormat(130, "MULT", "Qbd", "TimeUS,Id,Mult", "s--", "F--"),
    MessageFormat(131, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds", "s---", "F---"),
    MessageFormat(132, "PARM", "QNff", "TimeUS,Name,Value,Default", "s---", "F---"),
    MessageFormat(133, "MODE", "QMBB", "TimeUS,Mode,ModeNum,Rsn", "s---", "F---"),
    MessageFormat(134, "ARM", "QBIBB", "TimeUS,ArmState,ArmChecks,Forced,Method", "s----",
                  "F----"),
    MessageFormat(135, "MSG", "QZ", "TimeUS,Message", "s-", "F-"),
    MessageFormat(136, "ORGN", "QBLLe", "TimeUS,Type,Lat,Lng,Alt", "s#DUm", "F-GGB"),
    MessageFormat(137, "XKF1", "QBccCfffffffccce",
                  "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
                  "s#ddhnnnnmmmkkkm", "F-BBB0000000BBBB"),
    MessageFormat(138, "ATT", "QccccCCCCB",
                  "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF",
                  "sddddhhdh-", "FBBBBBBBB-"),
    MessageFormat(139, "POS", "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt",
                  "sDUmmm", "FGG000"),
    MessageFormat(140, "GPS", "QBBIHBcLLeffffB",
                  "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
                  "s#-s-S-DUmnhnh-", "F--C-0BGGB0000-"),
    MessageFormat(141, "IMU", "QBffffffIIfBBHH",
                  "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
                  "s#EEEooo--O--zz", "F-000000-----00"),
    MessageFormat(142, "RCIN", "Q" + "H" * 14, "TimeUS," + _RC14, "s" + "Y" * 14, "F" + "-" * 14),
    MessageFormat(143, "RCOU", "Q" + "H" * 14, "TimeUS," + _RC14, "s" + "Y" * 14, "F" + "-" * 14),
)}
FMT = MessageFormat(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", "-b---",
                    "-----")


def _pack_value(code: str, value):
    if code in "nNZ":
        data = value.encode("ascii", "replace") if isinstance(value, str) else bytes(value)
        return data
    if code in SCALE:
        return int(round(float(value) * SCALE[code]))
    if code in "fd":
        return float(value)
    return int(value)


def _clamp(code: str, value):
    """Integers that would overflow their field saturate (as the firmware's casts do not,
    but a log must never fail to be written)."""
    limits = {"b": (-128, 127), "B": (0, 255), "M": (0, 255), "h": (-32768, 32767),
              "c": (-32768, 32767), "H": (0, 65535), "C": (0, 65535),
              "i": (-2**31, 2**31 - 1), "e": (-2**31, 2**31 - 1), "L": (-2**31, 2**31 - 1),
              "I": (0, 2**32 - 1), "E": (0, 2**32 - 1), "q": (-2**63, 2**63 - 1), "Q": (0, 2**64 - 1)}
    if code in limits and isinstance(value, int):
        lo, hi = limits[code]
        return min(hi, max(lo, value))
    return value


def pack(fmt: MessageFormat, values) -> bytes:
    """One record of `fmt` with `values` in physical units (degrees, metres, ...)."""
    values = list(values)
    if len(values) != len(fmt.format):
        raise ValueError(f"{fmt.name} takes {len(fmt.format)} values, got {len(values)}")
    packed = [_clamp(c, _pack_value(c, v)) for c, v in zip(fmt.format, values)]
    return HEAD + bytes([fmt.type]) + fmt.struct.pack(*packed)


def _fmt_record(fmt: MessageFormat) -> bytes:
    return pack(FMT, (fmt.type, fmt.length, fmt.name, fmt.format, fmt.columns))


class DataFlashWriter:
    """Writes a .BIN log: the self-description first, then records as they come."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fh = self.path.open("wb")
        self.records = 0
        out = [_fmt_record(FMT)]
        out += [_fmt_record(f) for f in MESSAGES.values()]
        out += [pack(MESSAGES["UNIT"], (0, ord(k), v)) for k, v in UNITS.items()]
        out += [pack(MESSAGES["MULT"], (0, ord(k), v)) for k, v in MULTIPLIERS.items()]
        out += [pack(MESSAGES["FMTU"], (0, f.type, f.units, f.multipliers))
                for f in MESSAGES.values()]
        self._fh.write(b"".join(out))
        self._fh.flush()

    def write(self, name: str, time_us: int, *values) -> None:
        """A record of message `name`: TimeUS then the other fields, physical units."""
        if self._fh is None:
            return
        self._fh.write(pack(MESSAGES[name], (int(time_us), *values)))
        self.records += 1

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def next_log_path(directory: str | Path) -> Path:
    """The next log file as ArduPilot numbers them: 00000001.BIN, ... (LASTLOG.TXT says
    which was last)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    last = directory / "LASTLOG.TXT"
    n = 0
    try:
        n = int(last.read_text().strip() or 0)
    except (OSError, ValueError):
        n = max((int(p.stem) for p in directory.glob("*.BIN") if p.stem.isdigit()), default=0)
    n += 1
    last.write_text(f"{n}\n")
    return directory / f"{n:08d}.BIN"
