"""MAVLink 2 signing keys from a file, and how a message failing them is counted: one rule for
the bridge and the simulated autopilot.

The file holds either exactly 32 bytes (the key itself), or 64 hexadecimal characters (the
key in hex), or any other text: a passphrase whose SHA-256 is the key, as MAVProxy's
`signing setup PASSPHRASE` does. Text is stripped of surrounding whitespace first, so a
trailing newline does not matter; a 32-byte file is always taken as the raw key.
"""

from __future__ import annotations

import hashlib
import string
from pathlib import Path

from controller.errors import InputError

KEY_LEN = 32


def key_from_bytes(data: bytes, source: str = "signing key") -> bytes:
    """The 32-byte key that `data` (a key file's content) stands for."""
    if len(data) == KEY_LEN:
        return bytes(data)
    try:
        text = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise InputError(f"{source}: neither a 32-byte key, 64 hex characters nor a text "
                         f"passphrase ({len(data)} bytes of binary data)") from None
    if not text:
        raise InputError(f"{source}: the signing key file is empty")
    if len(text) == 2 * KEY_LEN and all(c in string.hexdigits for c in text):
        return bytes.fromhex(text)
    return hashlib.sha256(text.encode("utf-8")).digest()


def load_signing_key(path: str | Path) -> bytes:
    """Read a signing key file (see the module's rule); InputError names the file if unusable."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such signing key file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a signing key file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the signing key file: {exc.strerror}") from None
    return key_from_bytes(data, str(path))


def rejected_for_signature(bad_data_msg) -> bool:
    """Whether pymavlink's BAD_DATA stands for a missing or wrong signature (not garbage)."""
    return "signature" in str(getattr(bad_data_msg, "reason", "")).lower()


def counted_as_bad_data(msg, counters) -> bool:
    """Whether `msg` is pymavlink's BAD_DATA; if so it is counted on `counters` (both ends'
    LinkCounters) as a rejected signature or as garbage."""
    if msg.get_type() != "BAD_DATA":
        return False
    if rejected_for_signature(msg):
        counters.rejected_signature += 1
    else:
        counters.bad_data += 1
    return True
