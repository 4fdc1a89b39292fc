"""CDR payloads of the four message types, with `struct` only (byte-identical to rosbags'
`serialize_cdr`, checked in tests/pure/test_ros2_wire.py).

A payload is the 4-byte encapsulation header `00 01 00 00` (CDR little-endian, no options) and
an XCDR1 body whose alignment counts from the body's first byte: a primitive aligns to its
size, a string is a uint32 length (NUL included), its UTF-8 bytes and the NUL. Stamps are
nanoseconds here and `builtin_interfaces/Time` (int32 sec, uint32 nanosec) on the wire.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

HEADER = b"\x00\x01\x00\x00"
NS = 1_000_000_000
COVARIANCE = 36  # float64[36], a fixed array: no length on the wire


class CdrError(ValueError):
    """A payload that is not a valid CDR message of the expected type: too short, another
    encapsulation, a bad string."""


@dataclass(frozen=True)
class Pose2D:
    stamp_ns: int
    x: float
    y: float
    yaw: float  # rad, in (-pi, pi]
    frame_id: str = ""


class _Writer:
    def __init__(self) -> None:
        self.body = bytearray()

    def _align(self, n: int) -> None:
        self.body += b"\0" * (-len(self.body) % n)

    def stamp(self, stamp_ns: int) -> None:
        sec, nanosec = divmod(stamp_ns, NS)
        if not -(2**31) <= sec < 2**31:
            raise ValueError(f"stamp {stamp_ns} ns does not fit a builtin_interfaces/Time (int32 seconds)")
        self._align(4)
        self.body += struct.pack("<iI", sec, nanosec)

    def string(self, s: str) -> None:
        data = s.encode()
        if b"\0" in data:
            raise ValueError(f"a CDR string cannot hold a NUL: {s!r}")
        self._align(4)
        self.body += struct.pack("<I", len(data) + 1) + data + b"\0"

    def f64(self, *values: float) -> None:
        self._align(8)
        self.body += struct.pack(f"<{len(values)}d", *values)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        self.stamp(stamp_ns)
        self.string(frame_id)

    def payload(self) -> bytes:
        return HEADER + bytes(self.body)


class _Reader:
    def __init__(self, b: bytes) -> None:
        if len(b) < 4:
            raise CdrError(f"a CDR payload has a 4-byte header; got {len(b)} bytes")
        if b[:2] != HEADER[:2]:
            raise CdrError(f"not little-endian CDR: encapsulation {bytes(b[:2]).hex()} (want 0001)")
        self.body = memoryview(b)[4:]
        self.pos = 0

    def _take(self, size: int, align: int) -> int:
        self.pos += -self.pos % align
        start = self.pos
        if start + size > len(self.body):
            raise CdrError(f"CDR payload too short: {len(self.body)} body bytes, need {start + size}")
        self.pos = start + size
        return start

    def stamp(self) -> int:
        sec, nanosec = struct.unpack_from("<iI", self.body, self._take(8, 4))
        if nanosec >= NS:
            raise CdrError(f"nanosec {nanosec} out of range")
        return sec * NS + nanosec

    def string(self) -> str:
        (n,) = struct.unpack_from("<I", self.body, self._take(4, 4))
        if n == 0:  # some writers send an empty string as length 0
            return ""
        at = self._take(n, 1)
        raw = self.body[at : at + n]
        if raw[-1] != 0:
            raise CdrError("CDR string without its NUL terminator")
        try:
            return bytes(raw[:-1]).decode()
        except UnicodeDecodeError as e:
            raise CdrError(f"CDR string is not UTF-8: {e}") from None

    def f64(self, count: int) -> tuple[float, ...]:
        return struct.unpack_from(f"<{count}d", self.body, self._take(8 * count, 8))

    def header(self) -> tuple[int, str]:
        return self.stamp(), self.string()


def _yaw(qx: float, qy: float, qz: float, qw: float) -> float:
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _pose(w: _Writer, x: float, y: float, yaw: float) -> None:
    w.f64(x, y, 0.0, 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def _read_pose(r: _Reader) -> tuple[float, float, float]:
    x, y, _z, qx, qy, qz, qw = r.f64(7)
    return x, y, _yaw(qx, qy, qz, qw)


def encode_twist(vx: float, wz: float) -> bytes:
    """geometry_msgs/msg/Twist with linear.x = vx, angular.z = wz, the rest 0."""
    w = _Writer()
    w.f64(vx, 0.0, 0.0, 0.0, 0.0, wz)
    return w.payload()


def encode_twist_stamped(stamp_ns: int, frame_id: str, vx: float, wz: float) -> bytes:
    w = _Writer()
    w.header(stamp_ns, frame_id)
    w.f64(vx, 0.0, 0.0, 0.0, 0.0, wz)
    return w.payload()


def decode_twist(b: bytes) -> tuple[float, float]:
    """(linear.x, angular.z) of a Twist."""
    v = _Reader(b).f64(6)
    return v[0], v[5]


def decode_twist_stamped(b: bytes) -> tuple[int, str, float, float]:
    """(stamp_ns, frame_id, linear.x, angular.z) of a TwistStamped."""
    r = _Reader(b)
    stamp_ns, frame_id = r.header()
    v = r.f64(6)
    return stamp_ns, frame_id, v[0], v[5]


def encode_odometry(
    stamp_ns: int,
    frame_id: str,
    child_frame_id: str,
    x: float,
    y: float,
    yaw: float,
    vx: float = 0.0,
    wz: float = 0.0,
) -> bytes:
    """nav_msgs/msg/Odometry: the pose (x, y, yaw as a quaternion about z), the body twist
    (vx, wz); covariances 0."""
    w = _Writer()
    w.header(stamp_ns, frame_id)
    w.string(child_frame_id)
    _pose(w, x, y, yaw)
    w.f64(*[0.0] * COVARIANCE)
    w.f64(vx, 0.0, 0.0, 0.0, 0.0, wz)
    w.f64(*[0.0] * COVARIANCE)
    return w.payload()


def decode_odometry(b: bytes) -> Pose2D:
    r = _Reader(b)
    stamp_ns, frame_id = r.header()
    r.string()  # child_frame_id
    x, y, yaw = _read_pose(r)
    r.f64(COVARIANCE + 6 + COVARIANCE)  # the rest must be there too
    return Pose2D(stamp_ns, x, y, yaw, frame_id)


def encode_pose_stamped(stamp_ns: int, frame_id: str, x: float, y: float, yaw: float) -> bytes:
    w = _Writer()
    w.header(stamp_ns, frame_id)
    _pose(w, x, y, yaw)
    return w.payload()


def decode_pose_stamped(b: bytes) -> Pose2D:
    r = _Reader(b)
    stamp_ns, frame_id = r.header()
    x, y, yaw = _read_pose(r)
    return Pose2D(stamp_ns, x, y, yaw, frame_id)
