"""The 33-byte attachment rmw_zenoh puts on every sample (and drops a sample without):
int64 sequence number, int64 source timestamp (ns since the UNIX epoch), both little-endian,
then the 16-byte publisher GID behind its length byte (0x10), as zenoh-ext serializes
`(int64, int64, std::array<uint8_t, 16>)`."""

from __future__ import annotations

import struct

import xxhash

GID_LEN = 16
SIZE = 8 + 8 + 1 + GID_LEN  # 33
_HEAD = struct.Struct("<qqB")


def attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    """The attachment of the sample number `seq` (rmw_zenoh counts from 1) sent at `stamp_ns`."""
    if len(gid) != GID_LEN:
        raise ValueError(f"a GID is {GID_LEN} bytes, not {len(gid)}")
    try:
        return _HEAD.pack(seq, stamp_ns, GID_LEN) + bytes(gid)
    except struct.error as e:
        raise ValueError(f"attachment: seq {seq} or stamp {stamp_ns} is not an int64") from e


def parse_attachment(b: bytes) -> tuple[int, int, bytes]:
    """(seq, stamp_ns, gid) of an attachment; ValueError unless it is exactly the 33-byte layout."""
    if len(b) != SIZE:
        raise ValueError(f"an rmw_zenoh attachment is {SIZE} bytes, not {len(b)}")
    seq, stamp_ns, n = _HEAD.unpack_from(b)
    if n != GID_LEN:
        raise ValueError(f"attachment: GID length byte is {n}, not {GID_LEN}")
    return seq, stamp_ns, bytes(b[_HEAD.size :])


def gid_for(key: str) -> bytes:
    """The GID of the entity whose liveliness token is `key`, as rmw_zenoh (Jazzy and later) makes
    it: XXH3-128 of the whole key, its low 64 bits then its high 64 bits, little-endian. `ros2 topic
    info -v` shows it, and the attachment of every sample carries it: a subscriber that knows a
    publisher's token can tell its samples from anyone else's."""
    return xxhash.xxh3_128_digest(key.encode())[::-1]  # xxHash's canonical digest is big-endian
