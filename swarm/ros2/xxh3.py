"""XXH3-128 (xxHash 0.8, default secret, seed 0) in pure Python: rmw_zenoh (Jazzy and later)
makes each entity's GID from it, the hash of the entity's whole liveliness key
(rmw_zenoh_cpp/src/detail/liveliness_utils.cpp, `Entity::Entity`: `simplified_XXH3_128bits`
of the key, low 64 bits then high 64 bits, each little-endian). Written from the xxHash
specification; tests/test_ros2_wire.py checks it against the `xxhash` package for every
length from 0 to 1,100 bytes. Slow (tens of microseconds for a 200-byte key), which is fine:
a GID is computed once per publisher."""

from __future__ import annotations

M64 = (1 << 64) - 1
M32 = (1 << 32) - 1

P32_1, P32_2, P32_3 = 0x9E3779B1, 0x85EBCA77, 0xC2B2AE3D
P64_1, P64_2, P64_3 = 0x9E3779B185EBCA87, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9
P64_4, P64_5 = 0x85EBCA77C2B2AE63, 0x27D4EB2F165667C5
PRIME_MX1, PRIME_MX2 = 0x165667919E3779F9, 0x9FB21C651E98DF25

SECRET = bytes.fromhex(
    "b8fe6c3923a44bbe7c01812cf721ad1cded46de9839097db7240a4a4b7b3671f"
    "cb79e64eccc0e578825ad07dccff7221b8084674f743248ee03590e6813a264c"
    "3c2852bb91c300cb88d0658b1b532ea371644897a20df94e3819ef46a9deacd8"
    "a8fa763fe39c343ff9dcbbc7c70b4f1d8a51e04bcdb45931c89f7ec9d9787364"
    "eac5ac8334d3ebc3c581a0fffa1363eb170ddd51b7f0da49d316552629d4689e"
    "2b16be587d47a1fc8ff8b8d17ad031ce45cb3a8f95160428afd7fbcabb4b407e"
)
STRIPE = 64
ACCS = 8
CONSUME_RATE = 8
MIDSIZE_MAX = 240
SECRET_SIZE_MIN = 136


def _u64(b: bytes, i: int) -> int:
    return int.from_bytes(b[i : i + 8], "little")


def _u32(b: bytes, i: int) -> int:
    return int.from_bytes(b[i : i + 4], "little")


def _mul128(a: int, b: int) -> tuple[int, int]:
    """(low, high) 64-bit halves of the 128-bit product."""
    p = a * b
    return p & M64, p >> 64


def _fold64(a: int, b: int) -> int:
    lo, hi = _mul128(a, b)
    return lo ^ hi


def _avalanche(h: int) -> int:
    h ^= h >> 37
    h = (h * PRIME_MX1) & M64
    return h ^ (h >> 32)


def _xxh64_avalanche(h: int) -> int:
    h ^= h >> 33
    h = (h * P64_2) & M64
    h ^= h >> 29
    h = (h * P64_3) & M64
    return h ^ (h >> 32)


def _swap64(x: int) -> int:
    return int.from_bytes(x.to_bytes(8, "little"), "big")


def _swap32(x: int) -> int:
    return int.from_bytes(x.to_bytes(4, "little"), "big")


def _len_1to3(data: bytes) -> tuple[int, int]:
    n = len(data)
    c1, c2, c3 = data[0], data[n >> 1], data[n - 1]
    combined_lo = (c1 << 16) | (c2 << 24) | c3 | (n << 8)
    sw = _swap32(combined_lo)
    combined_hi = ((sw << 13) | (sw >> 19)) & M32
    flip_lo = _u32(SECRET, 0) ^ _u32(SECRET, 4)
    flip_hi = _u32(SECRET, 8) ^ _u32(SECRET, 12)
    return _xxh64_avalanche(combined_lo ^ flip_lo), _xxh64_avalanche(combined_hi ^ flip_hi)


def _len_4to8(data: bytes) -> tuple[int, int]:
    n = len(data)
    value = _u32(data, 0) + (_u32(data, n - 4) << 32)
    keyed = value ^ (_u64(SECRET, 16) ^ _u64(SECRET, 24))
    lo, hi = _mul128(keyed, (P64_1 + (n << 2)) & M64)
    hi = (hi + (lo << 1)) & M64
    lo ^= hi >> 3
    lo ^= lo >> 35
    lo = (lo * PRIME_MX2) & M64
    lo ^= lo >> 28
    return lo, _avalanche(hi)


def _len_9to16(data: bytes) -> tuple[int, int]:
    n = len(data)
    flip_lo = _u64(SECRET, 32) ^ _u64(SECRET, 40)
    flip_hi = _u64(SECRET, 48) ^ _u64(SECRET, 56)
    in_lo, in_hi = _u64(data, 0), _u64(data, n - 8)
    lo, hi = _mul128(in_lo ^ in_hi ^ flip_lo, P64_1)
    lo = (lo + ((n - 1) << 54)) & M64
    in_hi ^= flip_hi
    hi = (hi + in_hi + (in_hi & M32) * (P32_2 - 1)) & M64
    lo ^= _swap64(hi)
    h_lo, h_hi = _mul128(lo, P64_2)
    h_hi = (h_hi + hi * P64_2) & M64
    return _avalanche(h_lo), _avalanche(h_hi)


def _mix16(data: bytes, i: int, s: int) -> int:
    return _fold64(_u64(data, i) ^ _u64(SECRET, s), _u64(data, i + 8) ^ _u64(SECRET, s + 8))


def _mix32(acc: tuple[int, int], data: bytes, i1: int, i2: int, s: int) -> tuple[int, int]:
    lo, hi = acc
    lo = (lo + _mix16(data, i1, s)) & M64
    lo ^= (_u64(data, i2) + _u64(data, i2 + 8)) & M64
    hi = (hi + _mix16(data, i2, s + 16)) & M64
    hi ^= (_u64(data, i1) + _u64(data, i1 + 8)) & M64
    return lo, hi


def _finish_mid(acc: tuple[int, int], n: int) -> tuple[int, int]:
    lo, hi = acc
    h_lo = (lo + hi) & M64
    h_hi = (lo * P64_1 + hi * P64_4 + n * P64_2) & M64
    return _avalanche(h_lo), (-_avalanche(h_hi)) & M64


def _len_17to128(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * P64_1) & M64, 0)
    if n > 32:
        if n > 64:
            if n > 96:
                acc = _mix32(acc, data, 48, n - 64, 96)
            acc = _mix32(acc, data, 32, n - 48, 64)
        acc = _mix32(acc, data, 16, n - 32, 32)
    acc = _mix32(acc, data, 0, n - 16, 0)
    return _finish_mid(acc, n)


def _len_129to240(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * P64_1) & M64, 0)
    for i in range(32, 160, 32):
        acc = _mix32(acc, data, i - 32, i - 16, i - 32)
    acc = (_avalanche(acc[0]), _avalanche(acc[1]))
    for i in range(160, n + 1, 32):
        acc = _mix32(acc, data, i - 32, i - 16, 3 + i - 160)
    acc = _mix32(acc, data, n - 16, n - 32, SECRET_SIZE_MIN - 17 - 16)
    return _finish_mid(acc, n)


def _accumulate(acc: list[int], data: bytes, at: int, s: int) -> None:
    for lane in range(ACCS):
        value = _u64(data, at + 8 * lane)
        key = value ^ _u64(SECRET, s + 8 * lane)
        acc[lane ^ 1] = (acc[lane ^ 1] + value) & M64
        acc[lane] = (acc[lane] + (key & M32) * (key >> 32)) & M64


def _scramble(acc: list[int]) -> None:
    s = len(SECRET) - STRIPE
    for lane in range(ACCS):
        a = acc[lane]
        a ^= a >> 47
        a ^= _u64(SECRET, s + 8 * lane)
        acc[lane] = (a * P32_1) & M64


def _merge(acc: list[int], s: int, start: int) -> int:
    result = start
    for i in range(4):
        result += _fold64(acc[2 * i] ^ _u64(SECRET, s + 16 * i), acc[2 * i + 1] ^ _u64(SECRET, s + 16 * i + 8))
    return _avalanche(result & M64)


def _long(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = [P32_3, P64_1, P64_2, P64_3, P64_4, P32_2, P64_5, P32_1]
    per_block = (len(SECRET) - STRIPE) // CONSUME_RATE
    block = STRIPE * per_block
    blocks = (n - 1) // block
    for b in range(blocks):
        for k in range(per_block):
            _accumulate(acc, data, b * block + k * STRIPE, k * CONSUME_RATE)
        _scramble(acc)
    stripes = ((n - 1) - block * blocks) // STRIPE
    for k in range(stripes):
        _accumulate(acc, data, blocks * block + k * STRIPE, k * CONSUME_RATE)
    _accumulate(acc, data, n - STRIPE, len(SECRET) - STRIPE - 7)
    lo = _merge(acc, 11, (n * P64_1) & M64)
    hi = _merge(acc, len(SECRET) - 64 - 11, ~(n * P64_2) & M64)
    return lo, hi


def xxh3_128(data: bytes) -> tuple[int, int]:
    """(low64, high64) of XXH3_128bits(data)."""
    n = len(data)
    if n == 0:
        flip_lo = _u64(SECRET, 64) ^ _u64(SECRET, 72)
        flip_hi = _u64(SECRET, 80) ^ _u64(SECRET, 88)
        return _xxh64_avalanche(flip_lo), _xxh64_avalanche(flip_hi)
    if n <= 3:
        return _len_1to3(data)
    if n <= 8:
        return _len_4to8(data)
    if n <= 16:
        return _len_9to16(data)
    if n <= 128:
        return _len_17to128(data)
    if n <= MIDSIZE_MAX:
        return _len_129to240(data)
    return _long(data)


def xxh3_128_le(data: bytes) -> bytes:
    """The 16 bytes rmw_zenoh copies into a GID: the low 64 bits, then the high 64 bits, each
    little-endian (the reverse of xxHash's canonical, big-endian form)."""
    lo, hi = xxh3_128(data)
    return lo.to_bytes(8, "little") + hi.to_bytes(8, "little")
