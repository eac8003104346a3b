"""What a ``.usdc`` (USD crate) file claims, checked against its size before USD opens it.

USD's crate reader trusts the counts a file states: it allocates the table of contents,
the token, field, path and spec tables and every array at the size written in the file
before it reads a byte of them, so a 20 KB file claiming 117 million sections asked
for 3.7 GB, and a section or an offset past the end of the file made USD print
``failed call to posix_madvise`` on stderr. :func:`check_crate` reads the same layout
(bootstrap, table of contents, the six structural sections, then every value the
fields point to: arrays, time samples, dictionaries, list ops, vectors) and refuses,
in one line, any count that the bytes after it cannot hold. It allocates at most what
the file's own sections decompress to, so a normal file costs a few milliseconds
(the bundled ``conversation_bodyonly.usdc``: see benchmarks/bench_usdc_check.py).

The layout is the one of USD's ``crateFile.cpp`` (versions 0.4.0 to 0.14.0 checked in
full; older files, which USD no longer writes, get the table-of-contents and section
checks). Claims are bounded by the LZ4 ratio (:data:`LZ4_MAX_RATIO`): a count of
compressed integers can be at most about 4 x 255 per compressed byte.
"""

from __future__ import annotations

import mmap
import os
import struct
from pathlib import Path
from typing import NamedTuple

import numpy as np

from usdhands.compiled import kernel_module
from usdhands.errors import AssetReadError

__all__ = ["CRATE_MAGIC", "CrateCheck", "check_crate", "check_crate_bytes", "check_crate_file", "lz4_block_decompress"]

#: The first 8 bytes of every crate file.
CRATE_MAGIC = b"PXR-USDC"
#: Size of the bootstrap header (ident, version, tocOffset, 8 reserved int64).
_BOOTSTRAP = 88
#: Size of one table-of-contents entry (name[16], start, size).
_SECTION = 32
#: At most this many output bytes per input byte of an LZ4 block (each 255 length byte adds 255).
LZ4_MAX_RATIO = 256
#: Fewest elements a compressed int/float array is stored compressed with (USD's MinCompressedArraySize).
_MIN_COMPRESSED_ARRAY = 16
#: Deepest nesting of dictionaries / values inside values that is walked.
_MAX_VALUE_DEPTH = 64

# Type enumerants of crateDataTypes.h -> bytes per array element as stored (indices for strings/tokens/paths).
_ELEMENT_BYTES = {1: 1, 2: 1, 3: 4, 4: 4, 5: 8, 6: 8, 7: 2, 8: 4, 9: 8, 10: 4, 11: 4, 12: 4,
                  13: 32, 14: 72, 15: 128, 16: 32, 17: 16, 18: 8, 19: 16, 20: 8, 21: 4, 22: 8,
                  23: 24, 24: 12, 25: 6, 26: 12, 27: 32, 28: 16, 29: 8, 30: 16, 56: 8, 57: 4}
_COMPRESSED_INTS = {3, 4, 5, 6}  # Int, UInt, Int64, UInt64: stored as compressed integers
_COMPRESSED_FLOATS = {7, 8, 9}  # Half, Float, Double: 'i' (integers) or 't' (lookup table)
_ELEMENT_TABLE = np.zeros(256, dtype=np.int64)
_ELEMENT_TABLE[list(_ELEMENT_BYTES)] = list(_ELEMENT_BYTES.values())
_COMPRESSIBLE = np.zeros(256, dtype=bool)
_COMPRESSIBLE[list(_COMPRESSED_INTS | _COMPRESSED_FLOATS)] = True
# ValueRep bits (crateFile.h)
_ARRAY, _INLINED, _COMPRESSED, _PAYLOAD = 1 << 63, 1 << 62, 1 << 61, (1 << 48) - 1
_ARRAY_OR_INLINED, _ARRAY_BIT = np.uint64(_ARRAY | _INLINED), np.uint64(_ARRAY)
_DICTIONARY, _VALUE, _UNREGISTERED_VALUE, _TIME_SAMPLES = 31, 52, 53, 46
_STRING_KINDS, _TOKEN_KINDS, _PATH_EXPRESSION = {10}, {11, 12}, 57  # string, token/asset path: an index
_NAMED_KINDS = _STRING_KINDS | _TOKEN_KINDS
#: Longest run of indices checked by struct (longer ones by NumPy), and its readers by length
_FEW_INDICES = 8
_READ_U32S = [struct.Struct(f"<{k}I").unpack_from for k in range(_FEW_INDICES + 1)]
#: type enumerant -> whether it is a string / a token (asset path) / stored as an index into those tables
_IS_STRING, _IS_TOKEN, _IS_INDEXED = (np.zeros(256, dtype=bool) for _ in range(3))
_IS_STRING[list(_STRING_KINDS)] = True
_IS_TOKEN[list(_TOKEN_KINDS)] = True
_IS_INDEXED[list(_STRING_KINDS | _TOKEN_KINDS | {_PATH_EXPRESSION})] = True
_PAYLOAD_KIND = 47
# vectors of indices: type -> (indices per entry, table); of numbers: type -> bytes per entry
_INDEX_VECTORS = {40: (1, "path"), 41: (1, "token"), 50: (1, "string"), 45: (2, "string"), 58: (2, "path")}
_VECTORS = {48: 8, 49: 16}
_DOUBLE_VECTOR = 48  # a time samples' times
# list ops: of indices -> table; of numbers -> bytes per item; references, payloads, values walked
_INDEX_LIST_OPS = {32: "token", 33: "string", 34: "path"}
_NUMBER_LIST_OPS = {36: 4, 37: 8, 38: 4, 39: 8}
_REFERENCE_LIST_OP, _PAYLOAD_LIST_OP = 35, 55
_LIST_OPS = {32, 33, 34, 35, 36, 37, 38, 39, 54, 55}


#: SdfSpecType values each kind of path may carry (pseudo-root 7; prim 6, variant 10, variant set 11;
#: attribute 1, relationship 8; below a property: connection 2, expression 3, mapper 4, mapper arg 5,
#: relationship target 9). Out-of-range types are USD's own check.
_SPEC_TYPES = {"root": {7}, "prim": {6, 10, 11}, "property": {1, 8}, "target": {2, 3, 4, 5, 9}}


class _Corrupt(Exception):
    """What is wrong, raised inside the walk and turned into one AssetReadError."""


def _lz4_length(src: bytes, i: int, length: int, what: str) -> tuple[int, int]:
    """A sequence's length: the token's 4 bits, extended by bytes while they are 255; and the next position."""
    if length != 15:
        return length, i
    while True:
        if i >= len(src):
            raise ValueError(f"LZ4 {what} length runs past the block")
        b = src[i]
        i += 1
        length += b
        if b != 255:
            return length, i


def lz4_block_decompress(src: bytes, limit: int) -> bytes:
    """Decode one LZ4 block (the format USD's TfFastCompression writes); at most ``limit`` bytes out.

    Raises ValueError for a malformed block or one that decodes to more than ``limit``.
    """
    out = bytearray()
    i, n = 0, len(src)
    while i < n:
        token = src[i]
        i += 1
        literal = token >> 4
        if literal == 15:  # (the length's extension bytes read only where there are some)
            literal, i = _lz4_length(src, i, literal, "literal")
        if i + literal > n:
            raise ValueError("LZ4 literals run past the block")
        out += src[i:i + literal]
        i += literal
        if i == n:
            break  # the last sequence holds literals only
        if i + 2 > n:
            raise ValueError("LZ4 match offset runs past the block")
        offset = src[i] | (src[i + 1] << 8)
        i += 2
        if offset == 0 or offset > len(out):
            raise ValueError("LZ4 match offset outside the output")
        length = token & 15
        if length == 15:
            length, i = _lz4_length(src, i, length, "match")
        length += 4
        if len(out) + length > limit:
            raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
        start = len(out) - offset
        if offset >= length:
            out += out[start:start + length]
        else:  # an overlapping copy repeats the last `offset` bytes
            pattern = bytes(out[start:])
            out += (pattern * (length // offset + 1))[:length]
        if len(out) > limit:
            raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
    if len(out) > limit:
        raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
    return bytes(out)


#: bit offsets of the four 2-bit codes in a byte, and bytes per code (0: the common delta) for 32- and 64-bit integers
_CODE_SHIFTS = np.array([0, 2, 4, 6], dtype=np.uint8)
_CODE_BYTES = {4: np.array([0, 1, 2, 4], dtype=np.int64), 8: np.array([0, 2, 4, 8], dtype=np.int64)}


#: Most 32-bit integers decoded one by one in Python (a structural section of a small file holds
#: 12-189): 2.3 us for 12 and 7.8 for 53 against NumPy's 11.6 and 12.4, which wins from ~100 on
_FEW_INTS = 96
_DELTA_BYTES = (0, 1, 2, 4)
_DELTA_READ = (None, struct.Struct("<b").unpack_from, struct.Struct("<h").unpack_from, struct.Struct("<i").unpack_from)


def _decode_few_ints(encoded: bytes, n: int, common: int, codes_size: int) -> np.ndarray:
    """:func:`decode_ints` of ``n`` 32-bit integers one by one (the sums cannot leave int64: each
    delta is below 2**31 in size)."""
    codes = encoded[4:4 + codes_size]
    pos, size = 4 + codes_size, len(encoded)
    out = []
    total = 0
    for k in range(n):
        code = (codes[k >> 2] >> ((k & 3) << 1)) & 3
        if code:
            end = pos + _DELTA_BYTES[code]
            if end > size:
                raise ValueError(f"{size} bytes hold no {n} coded integers")
            total += _DELTA_READ[code](encoded, pos)[0]
            pos = end
        else:
            total += common
        out.append(total)
    return np.array(out, dtype=np.int64)


def decode_ints(encoded: bytes, n: int, width: int = 4) -> np.ndarray:
    """Sdf's integer coding (a common delta, 2-bit codes, 8/16/32-bit deltas), decoded: ``n`` int64.

    Every delta is read as ``width`` bytes from where it starts (the buffer padded with zeros)
    and cut to its own size by two shifts (a sign-extending one back).

    Raises ValueError when the bytes are too few for ``n`` integers.
    """
    common_size = width
    codes_size = (2 * n + 7) // 8
    if len(encoded) < common_size + codes_size:
        raise ValueError(f"{len(encoded)} bytes hold no {n} coded integers")
    common = int.from_bytes(encoded[:common_size], "little", signed=True)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if width == 4 and n <= _FEW_INTS:
        return _decode_few_ints(encoded, n, common, codes_size)
    packed = np.frombuffer(encoded, dtype=np.uint8, count=codes_size, offset=common_size)
    sizes = _CODE_BYTES[width][((packed[:, None] >> _CODE_SHIFTS) & 3).reshape(-1)[:n]]
    ends = np.cumsum(sizes)
    head = common_size + codes_size
    if head + int(ends[-1]) > len(encoded):
        raise ValueError(f"{len(encoded)} bytes hold no {n} coded integers")
    raw = np.zeros(len(encoded) + width, dtype=np.uint8)
    raw[:len(encoded)] = np.frombuffer(encoded, dtype=np.uint8)
    words = raw[(head + ends - sizes)[:, None] + np.arange(width)]
    deltas = words.view("<u4")[:, 0].astype(np.int64) if width == 4 else words.view("<i8")[:, 0]
    shift = np.where(sizes > 0, 64 - 8 * sizes, 0)
    deltas = (deltas << shift) >> shift
    deltas[sizes == 0] = common
    return np.cumsum(deltas)


#: The check's two byte loops compiled ahead of time (:mod:`usdhands.formats._crate_compiled`: the same
#: bytes, integers and errors), or these Python functions where it was not built: CesiumMan.usdz's
#: check 0.27 -> 0.17 ms, the loops 0.11 -> ~0.01 ms.
_COMPILED = kernel_module("formats._crate_compiled")
_lz4_block = _COMPILED.lz4_block_decompress if _COMPILED is not None else lz4_block_decompress
_decode_ints = _COMPILED.decode_ints if _COMPILED is not None else decode_ints
#: The walks of the values and of the path tree compiled (``_Crate.values``, ``_Crate.spec_types``: the
#: same checks in the same order, the same messages), or None: the Python methods run
_walk_values = getattr(_COMPILED, "walk_values", None)
_spec_types = getattr(_COMPILED, "spec_types", None)
#: The table of contents and the structural sections checked compiled (``_Crate.table_of_contents`` and
#: ``structural``' twin), or None
_check_structure = getattr(_COMPILED, "check_structure", None)
#: Whether every child a crate's specs list has a spec, decided from its bytes (True), or not shown
#: simply (False: ``usd_common.check_children`` walks the layer through Sdf); None where not built
_listed_children = getattr(_COMPILED, "listed_children_have_specs", None)


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    """``np.unique(a)`` of a 1-d array by a sort: NumPy 2's hashing unique took 64 us for 1,800 uint64
    value reps (a clip's time samples) and 840 us for 20,000, a sort 5.6 and 48."""
    a = np.sort(a)
    return a[np.concatenate(([True], a[1:] != a[:-1]))] if len(a) > 1 else a


class _Crate:
    """Reads a crate's claims from its bytes; every method raises :class:`_Corrupt` on a lie."""

    def __init__(self, data: bytes):
        self.data = data
        self.size = len(data)
        self.version = (0, 0, 0)
        self.sections: dict[str, tuple[int, int]] = {}
        #: entries of the token, string and path tables (values index into them)
        self.tables = {"token": 0, "string": 0, "path": 0}

    # -- primitive reads -------------------------------------------------------------------
    def u64(self, at: int, what: str) -> int:
        if at < 0 or at + 8 > self.size:
            raise _Corrupt(f"{what} at byte {at} is past the end of the file ({self.size} bytes)")
        return struct.unpack_from("<Q", self.data, at)[0]

    def i64(self, at: int, what: str) -> int:
        if at < 0 or at + 8 > self.size:
            raise _Corrupt(f"{what} at byte {at} is past the end of the file ({self.size} bytes)")
        return struct.unpack_from("<q", self.data, at)[0]

    def u32(self, at: int, what: str) -> int:
        if at < 0 or at + 4 > self.size:
            raise _Corrupt(f"{what} at byte {at} is past the end of the file ({self.size} bytes)")
        return struct.unpack_from("<I", self.data, at)[0]

    def fits(self, at: int, nbytes: int, what: str, end: int | None = None) -> None:
        """``nbytes`` from ``at`` lie inside the file (or before ``end``)."""
        end = self.size if end is None else end
        if at < 0 or nbytes < 0 or at + nbytes > end:
            raise _Corrupt(f"{what} claims {nbytes} bytes at byte {at}, past the end of its "
                           f"{'section' if end != self.size else 'file'} ({end} bytes)")

    def indices(self, values: np.ndarray, table: str, what: str) -> None:
        """Every index in ``values`` names an entry of the ``table`` (USD looks them up unchecked)."""
        if len(values) and int(values.max()) >= self.tables[table]:
            raise _Corrupt(f"{what} names {table} {int(values.max())} of {self.tables[table]}")

    def index(self, value: int, table: str, what: str) -> None:
        """``value`` names an entry of the ``table``."""
        if value >= self.tables[table]:
            raise _Corrupt(f"{what} names {table} {value} of {self.tables[table]}")

    def index_run(self, at: int, n: int, table: str, what: str) -> None:
        """``n`` uint32 indices into ``table`` stored from ``at`` (a few read by struct: most runs
        are one index, which NumPy took ~3 us to look at, struct ~0.3)."""
        self.count(n, at, 4, what)
        if n <= _FEW_INDICES:
            if n:
                self.index(max(_READ_U32S[n](self.data, at)), table, what)
            return
        self.indices(np.frombuffer(self.data, dtype="<u4", count=n, offset=at), table, what)

    def count(self, n: int, at: int, element: int, what: str, end: int | None = None) -> int:
        """``n`` elements of ``element`` bytes each fit from ``at``; returns ``n``."""
        end = self.size if end is None else end
        room = max(end - at, 0)
        if n > room // max(element, 1):
            raise _Corrupt(f"{what} claims {n} entries; the {room} bytes after it hold at most "
                           f"{room // max(element, 1)}")
        return n

    # -- compressed blocks -----------------------------------------------------------------
    def compressed_span(self, at: int, size: int, what: str, end: int) -> None:
        """A TfFastCompression buffer: its chunk table (first byte) must stay inside ``size`` bytes."""
        self.fits(at, size, what, end)
        if size == 0:
            raise _Corrupt(f"{what} is empty")
        chunks = self.data[at]
        pos, stop = at + 1, at + size
        for _ in range(chunks):  # 0 chunks: one block filling the rest
            if pos + 4 > stop:
                raise _Corrupt(f"{what}: its chunk table runs past its {size} bytes")
            n = struct.unpack_from("<i", self.data, pos)[0]
            pos += 4
            if n < 0 or pos + n > stop:
                raise _Corrupt(f"{what}: a chunk of {n} bytes runs past its {size} bytes")
            pos += n

    def decompress(self, at: int, size: int, limit: int, what: str, end: int) -> bytes:
        """The bytes of a TfFastCompression buffer (at most ``limit``)."""
        self.compressed_span(at, size, what, end)
        chunks = self.data[at]
        try:
            if chunks == 0:
                return _lz4_block(self.data[at + 1:at + size], limit)
            out, pos = bytearray(), at + 1
            for _ in range(chunks):
                n = struct.unpack_from("<i", self.data, pos)[0]
                out += _lz4_block(self.data[pos + 4:pos + 4 + n], limit - len(out))
                pos += 4 + n
            return bytes(out)
        except ValueError as e:
            raise _Corrupt(f"{what}: {e}") from None

    def compressed_ints(self, at: int, n: int, what: str, end: int | None = None) -> int:
        """``n`` integers stored compressed from ``at`` (uint64 size, then the buffer); returns the end."""
        end = self.size if end is None else end
        size = self.u64(at, f"{what} size")
        self.compressed_span(at + 8, size, what, end)
        # 2 bits of code per integer after LZ4: at most 4 integers per decoded byte
        most = 4 * LZ4_MAX_RATIO * size + 64
        if n > most:
            raise _Corrupt(f"{what} claims {n} integers; its {size} compressed bytes hold at most {most}")
        return at + 8 + size

    def ints(self, at: int, n: int, what: str, end: int) -> tuple[np.ndarray, int]:
        """``n`` compressed 32-bit integers from ``at``, decoded; and the position after them."""
        after = self.compressed_ints(at, n, what, end)
        limit = 4 + (2 * n + 7) // 8 + 4 * n
        raw = self.decompress(at + 8, after - at - 8, limit, what, end)
        try:
            values = _decode_ints(raw, n)
        except ValueError as e:
            raise _Corrupt(f"{what}: {e}") from None
        return values, after

    def spec_types(self, specs: list[np.ndarray], paths: list[np.ndarray]) -> None:
        """Each spec's type fits its path: the root, a prim (or variant), a property, or below a property.

        USD checks the type's range, not this: a Mapper spec on a prim path aborted the
        interpreter ('Dereferenced an invalid SdfPrimSpec'). The path tree is walked as
        USD builds it (each entry once: a jump back would make USD loop).
        """
        if _spec_types is not None and _spec_types(specs[0], specs[2], paths[0], paths[1], paths[2], _Corrupt):
            return  # (False: path indexes outside the table or jumps near 2**63, which this function walks)
        self.python_spec_types(specs, paths)

    def python_spec_types(self, specs: list[np.ndarray], paths: list[np.ndarray]) -> None:
        """:meth:`spec_types` in Python: the reference of the compiled walk."""
        indexes, elements, jumps = (a.tolist() for a in paths)
        n = len(indexes)
        kind = [""] * n  # "root", "prim", "property", "target"
        todo = [(0, None)] if n else []
        while todo:
            here, parent = todo.pop()
            while True:
                if not 0 <= here < n or kind[here]:
                    raise _Corrupt(f"PATHS: its jumps table reaches entry {here} twice or outside 0..{n - 1}")
                if parent is None:
                    kind[here] = "root"
                elif elements[here] < 0:
                    kind[here] = "property"
                else:
                    kind[here] = "target" if kind[parent] in ("property", "target") else "prim"
                jump = jumps[here]
                has_child, has_sibling = jump > 0 or jump == -1, jump >= 0
                if has_child and has_sibling:
                    todo.append((here + jump, parent))
                if has_child:
                    parent = here
                if not (has_child or has_sibling):
                    break
                here += 1
        of_path = {i: k for i, k in zip(indexes, kind) if k}  # an entry the walk never reaches: no path
        for path_index, spec_type in zip(specs[0].tolist(), specs[2].tolist()):
            where = of_path.get(path_index)
            if where is not None and spec_type not in _SPEC_TYPES[where]:
                raise _Corrupt(f"SPECS: a spec of type {spec_type} on a {where} path")

    # -- layout ----------------------------------------------------------------------------
    def structure(self) -> bytes | None:
        """:meth:`table_of_contents` then :meth:`structural` (compiled where built: the same checks in the
        same order and the same messages); returns the decompressed value reps of FIELDS (or None)."""
        if _check_structure is None:
            self.table_of_contents()
            return self.structural()
        kept = []  # FIELDSETS' integers, for listed_children
        self.version, tokens, strings, paths_n, reps, specs, paths = _check_structure(self.data, _Corrupt, kept)
        self.tables = {"token": tokens, "string": strings, "path": paths_n}
        if specs is not None and paths is not None:
            self.spec_types(specs, paths)
            self.decoded = (reps, specs, paths, kept[0] if kept else None)
        return reps

    #: FIELDS' value reps, SPECS, PATHS and FIELDSETS as :meth:`structure` decoded them (compiled), or None
    decoded = None

    def listed_children(self) -> bool:
        """Whether the bytes show that every child the specs list has a spec (the compiled decision, after
        the check passed; False where it is not built or not shown: the Sdf walk decides)."""
        if _listed_children is None or self.decoded is None or self.decoded[0] is None:
            return False
        reps, specs, paths, field_sets = self.decoded
        return bool(_listed_children(self.data, reps, specs[0], specs[1], specs[2], paths[0], paths[1], paths[2],
                                     self.tables["path"], field_sets))

    def table_of_contents(self) -> None:
        if self.size < _BOOTSTRAP:
            raise _Corrupt(f"a .usdc file of {self.size} bytes is shorter than its {_BOOTSTRAP}-byte header")
        self.version = tuple(self.data[8:11])
        toc = self.i64(16, "table of contents offset")
        if toc + 8 > self.size:  # USD's words for it
            raise _Corrupt(f"Sdf crate file corrupt, possibly truncated: table of contents at offset {toc} but "
                           f"file size is {self.size}")
        if toc < _BOOTSTRAP:
            raise _Corrupt(f"table of contents at offset {toc} is inside the header")
        n = self.count(self.u64(toc, "section count"), toc + 8, _SECTION, "table of contents")
        for k in range(n):
            at = toc + 8 + k * _SECTION
            name = bytes(self.data[at:at + 16]).split(b"\0", 1)[0].decode("latin-1")
            start, size = struct.unpack_from("<qq", self.data, at + 16)
            if start < 0 or size < 0 or start + size > self.size:
                raise _Corrupt(f"section {name!r} claims bytes {start} to {start + size}, outside the "
                               f"file ({self.size} bytes)")
            self.sections.setdefault(name, (start, start + size))

    def structural(self) -> bytes | None:
        """Check the six structural sections; returns the decompressed value reps of FIELDS (or None)."""
        compressed = self.version >= (0, 4, 0)
        reps = None
        if "TOKENS" in self.sections:
            start, end = self.sections["TOKENS"]
            n = self.u64(start, "token count")
            if compressed:
                raw, packed = self.u64(start + 8, "token bytes"), self.u64(start + 16, "token compressed bytes")
                self.compressed_span(start + 24, packed, "TOKENS", end)
                if raw > LZ4_MAX_RATIO * packed + 64:
                    raise _Corrupt(f"TOKENS claims {raw} bytes from {packed} compressed bytes")
            else:
                raw = self.u64(start + 8, "token bytes")
                self.fits(start + 16, raw, "TOKENS", end)
            if n > max(raw, 1):
                raise _Corrupt(f"TOKENS claims {n} tokens in {raw} bytes")
            self.tables["token"] = n
        if "STRINGS" in self.sections:
            start, end = self.sections["STRINGS"]
            n = self.count(self.u64(start, "string count"), start + 8, 4, "STRINGS", end)
            self.tables["string"] = n
            self.indices(np.frombuffer(self.data, dtype="<u4", count=n, offset=start + 8), "token", "STRINGS")
        if "FIELDS" in self.sections:
            start, end = self.sections["FIELDS"]
            n = self.u64(start, "field count")
            if compressed:
                at = self.compressed_ints(start + 8, n, "FIELDS tokens", end)
                size = self.u64(at, "FIELDS value reps size")
                if n * 8 > LZ4_MAX_RATIO * size + 64:
                    raise _Corrupt(f"FIELDS claims {n} fields from {size} compressed bytes")
                reps = self.decompress(at + 8, size, n * 8, "FIELDS value reps", end)
                if len(reps) != n * 8:
                    raise _Corrupt(f"FIELDS value reps decode to {len(reps)} bytes for {n} fields")
            else:
                self.count(n, start + 8, 16, "FIELDS", end)
        specs = paths = None
        for name, arrays in (("FIELDSETS", 1), ("SPECS", 3)):
            if name in self.sections:
                start, end = self.sections[name]
                n = self.u64(start, f"{name} count")
                if compressed:
                    at, decoded = start + 8, []
                    for _ in range(arrays):
                        values, at = self.ints(at, n, name, end)
                        decoded.append(values)
                    if name == "SPECS":
                        specs = decoded
                else:
                    self.count(n, start + 8, 4 * arrays, name, end)
        if "PATHS" in self.sections:
            start, end = self.sections["PATHS"]
            n = self.u64(start, "path count")
            self.tables["path"] = n
            if compressed:
                self.count(n, start, 1, "PATHS")  # a path table entry per byte of the file at most
                encoded = self.u64(start + 8, "encoded path count")
                at, paths = start + 16, []
                for _ in range(3):
                    values, at = self.ints(at, encoded, "PATHS", end)
                    paths.append(values)
            else:
                self.count(n, start + 8, 9, "PATHS", end)
        if specs is not None and paths is not None:
            self.spec_types(specs, paths)
        return reps

    # -- values ----------------------------------------------------------------------------
    def values(self, reps: bytes) -> None:
        if self.version < (0, 5, 0):
            return  # arrays still carried a rank then; USD has not written these since 2017
        if _walk_values is not None:
            _walk_values(self.data, reps, self.tables["token"], self.tables["string"], self.tables["path"],
                         self.version >= (0, 7, 0), self.version >= (0, 8, 0), _Corrupt)
            return
        self.python_values(reps)

    def python_values(self, reps: bytes) -> None:
        """:meth:`values` in Python: the reference of the compiled walk."""
        self.array_reps: list[np.ndarray] = []
        seen: set[int] = set()
        self.many(np.frombuffer(reps, dtype="<u8"), 0, seen)
        if self.array_reps:
            self.arrays(_sorted_unique(np.concatenate(self.array_reps)))

    def many(self, reps: np.ndarray, depth: int, seen: set[int]) -> None:
        """Check a run of value reps: arrays are collected for :meth:`arrays`, the rest walked here."""
        if ((reps & _ARRAY_OR_INLINED) == _ARRAY_BIT).all():
            # arrays stored out of line, every one (an array attribute's time samples): nothing inlined to
            # look up, nothing else to walk; what the steps below do for them, in 2 NumPy calls instead of ~15
            self.array_reps.append(reps)
            return
        inlined = (reps & np.uint64(_INLINED)) != 0
        kind = ((reps >> np.uint64(48)) & np.uint64(0xFF)).astype(np.intp)
        for kinds, table in ((_IS_STRING, "string"), (_IS_TOKEN, "token")):  # payload: an index
            named = inlined & kinds[kind] & ((reps & np.uint64(_ARRAY)) == 0)
            self.indices((reps[named] & np.uint64(0xFFFFFFFF)), table, "a value")
        reps = reps[~inlined]
        arrays = (reps & np.uint64(_ARRAY)) != 0
        if arrays.all():  # a time-sampled array attribute: one array per sample, nothing else to walk
            self.array_reps.append(reps)
            return
        self.array_reps.append(reps[arrays])
        for rep in _sorted_unique(reps[~arrays]).tolist():
            self.value(rep, depth, seen)

    def value(self, rep: int, depth: int, seen: set[int]) -> None:
        if rep in seen:
            return
        seen.add(rep)
        if depth > _MAX_VALUE_DEPTH:
            raise _Corrupt(f"values nested more than {_MAX_VALUE_DEPTH} deep")
        kind = (rep >> 48) & 0xFF
        at = rep & _PAYLOAD
        if rep & _INLINED:
            if not rep & _ARRAY and kind in _NAMED_KINDS:
                self.index(at & 0xFFFFFFFF, "string" if kind in _STRING_KINDS else "token", "a value")
        elif rep & _ARRAY:
            self.array_reps.append(np.array([rep], dtype=np.uint64))
        elif rep & (1 << 60):  # an array edit (0.14): not walked
            return
        elif kind in _NAMED_KINDS or kind == _PATH_EXPRESSION:  # stored out of line: an index
            self.index_run(at, 1, "token" if kind in _TOKEN_KINDS else "string", "a value")
        elif kind == _DICTIONARY:
            self.dictionary(at, depth, seen)
        elif kind in (_VALUE, _UNREGISTERED_VALUE):
            self.vt_value(at, depth, seen)
        elif kind == _TIME_SAMPLES:
            jump = self.i64(at, "time samples offset")
            if jump < 8:
                raise _Corrupt(f"time samples offset {jump} points backwards")
            times = at + jump
            times_rep = self.u64(times, "time samples times")
            self.value(times_rep, depth + 1, seen)
            jump = self.i64(times + 8, "time samples values offset")
            if jump < 8:
                raise _Corrupt(f"time samples values offset {jump} points backwards")
            where = times + 8 + jump
            n = self.count(self.u64(where, "time sample count"), where + 8, 8, "time samples")
            if (times_rep >> 48) & 0xFF == _DOUBLE_VECTOR and not times_rep & (_INLINED | _ARRAY):
                # USD reads the value of each time by its index (usdc fuzz: a times vector moved onto the
                # header claimed thousands, a SdfReadOutOfBoundsError traceback past the 4 values)
                held = self.u64(times_rep & _PAYLOAD, "time samples times")
                if held > n:
                    raise _Corrupt(f"time samples claim {held} times for {n} values")
            self.many(np.frombuffer(self.data, dtype="<u8", count=n, offset=where + 8), depth + 1, seen)
        elif kind in _INDEX_VECTORS:
            n = self.u64(at, "vector size")
            width, table = _INDEX_VECTORS[kind]
            self.index_run(at + 8, n * width, table, "a vector value")
        elif kind in _VECTORS:
            self.count(self.u64(at, "vector size"), at + 8, _VECTORS[kind], "a vector value")
        elif kind == _PAYLOAD_KIND:
            self.payload(at)
        elif kind in _LIST_OPS:
            self.fits(at, 1, "a list op")
            header, pos = self.data[at], at + 1
            for bit in range(1, 7):
                if header & (1 << bit):
                    pos = self.list_items(kind, pos, depth, seen)

    def list_items(self, kind: int, at: int, depth: int, seen: set[int]) -> int:
        """One vector of a list op at ``at``; returns the position after it."""
        n = self.u64(at, "list op size")
        pos = at + 8
        if kind in _INDEX_LIST_OPS:
            self.index_run(pos, n, _INDEX_LIST_OPS[kind], "a list op")
            return pos + 4 * n
        if kind in _NUMBER_LIST_OPS:
            self.count(n, pos, _NUMBER_LIST_OPS[kind], "a list op")
            return pos + n * _NUMBER_LIST_OPS[kind]
        self.count(n, pos, 16, "a list op")  # references, payloads, values: 16 bytes at the least
        for _ in range(n):
            if kind == _REFERENCE_LIST_OP:  # asset path, prim path, layer offset, customData
                self.index_run(pos, 1, "string", "a reference")
                self.index_run(pos + 4, 1, "path", "a reference")
                pos = self.dictionary(pos + 24, depth, seen)
            elif kind == _PAYLOAD_LIST_OP:
                pos = self.payload(pos)
            else:  # unregistered values
                pos = self.vt_value(pos, depth, seen)
        return pos

    def payload(self, at: int) -> int:
        """An SdfPayload (asset path, prim path, layer offset from 0.8.0); returns the position after it."""
        self.index_run(at, 1, "string", "a payload")
        self.index_run(at + 4, 1, "path", "a payload")
        return at + (24 if self.version >= (0, 8, 0) else 8)

    def dictionary(self, at: int, depth: int, seen: set[int]) -> int:
        """A VtDictionary (count, then string-index keys and values); returns the position after it."""
        n = self.count(self.u64(at, "dictionary size"), at + 8, 12, "a dictionary")
        pos = at + 8
        for _ in range(n):
            self.index_run(pos, 1, "string", "a dictionary key")
            pos = self.vt_value(pos + 4, depth, seen)
        return pos

    def vt_value(self, at: int, depth: int, seen: set[int]) -> int:
        """A VtValue stored as an int64 jump then a rep; returns the position after it."""
        jump = self.i64(at, "value offset")
        if jump < 8:  # USD prefetches `jump` bytes from here (posix_madvise), then seeks
            raise _Corrupt(f"value offset {jump} points backwards")
        where = at + jump
        self.value(self.u64(where, "value"), depth + 1, seen)
        return where + 8

    def arrays(self, reps: np.ndarray) -> None:
        """Every array's element count against the bytes after it (vectorised: a clip holds thousands)."""
        kind = ((reps >> np.uint64(48)) & np.uint64(0xFF)).astype(np.intp)
        at = (reps & np.uint64(_PAYLOAD)).astype(np.int64)
        element = _ELEMENT_TABLE[kind]
        keep = (at != 0) & (element > 0)  # 0: an empty array; no element size: not an array type (USD refuses)
        reps, kind, at, element = reps[keep], kind[keep], at[keep], element[keep]
        wide = self.version >= (0, 7, 0)
        head = 8 if wide else 4
        outside = at + head > self.size
        if outside.any():
            k = int(np.argmax(outside))
            raise _Corrupt(f"an array at byte {at[k]} is past the end of the file ({self.size} bytes)")
        raw = np.frombuffer(self.data, dtype=np.uint8)
        gathered = raw[at[:, None] + np.arange(head)]
        n = np.ascontiguousarray(gathered).view("<u8" if wide else "<u4")[:, 0].astype(np.uint64)
        room = (self.size - at - head).astype(np.uint64) // element.astype(np.uint64)
        compressed = ((reps & np.uint64(_COMPRESSED)) != 0) & _COMPRESSIBLE[kind] & (n >= _MIN_COMPRESSED_ARRAY)
        plain_over = ~compressed & (n > room)
        if plain_over.any():
            k = int(np.argmax(plain_over))
            raise _Corrupt(f"an array claims {n[k]} entries; the {self.size - at[k] - head} bytes after it "
                           f"hold at most {room[k]}")
        for k in np.flatnonzero(compressed).tolist():
            self.compressed_array(int(kind[k]), int(at[k]) + head, int(n[k]), int(element[k]))
        for k in np.flatnonzero(_IS_INDEXED[kind]).tolist():
            table = "token" if int(kind[k]) in _TOKEN_KINDS else "string"
            self.index_run(int(at[k]) + head, int(n[k]), table, "an array")

    def compressed_array(self, kind: int, pos: int, n: int, element: int) -> None:
        if kind in _COMPRESSED_FLOATS:
            self.fits(pos, 1, "a compressed array")
            code = self.data[pos]
            pos += 1
            if code == ord("t"):
                lut = self.count(self.u32(pos, "lookup table size"), pos + 4, element, "a lookup table")
                pos += 4 + lut * element
            elif code != ord("i"):
                raise _Corrupt(f"compressed array code {code} is neither 'i' nor 't'")
        self.compressed_ints(pos, n, "a compressed array")


def check_crate_bytes(data: bytes, path: str | os.PathLike | None = None, children: bool = False) -> bool:
    """Refuse crate bytes whose claims the bytes cannot hold (see the module docstring).

    With ``children``, returns whether the bytes also show that every child the crate's specs list
    has a spec (``usd_common.check_children``'s question, decided in compiled code where that is
    simple: :func:`usdhands.formats._crate_compiled.listed_children_have_specs`); False otherwise.

    Raises
    ------
    AssetReadError
        One line naming ``path`` and the first claim that does not fit.
    """
    crate = _Crate(data)
    try:
        reps = crate.structure()
        if reps is not None:
            crate.values(reps)
    except _Corrupt as e:
        raise AssetReadError(f"cannot read as USD: {e}", path=path) from None
    return children and crate.listed_children()


class CrateCheck(NamedTuple):
    """What :func:`check_crate_file` found: whether the file is a crate (a ``.usdz`` package: True), and
    whether its bytes show that every child its root layer's specs list has a spec (the layer USD
    opens from the file: a ``.usdc``'s own, a package's first member)."""

    crate: bool
    children_listed: bool


def check_crate_file(path: str | os.PathLike) -> CrateCheck:
    """Check ``path`` with :func:`check_crate_bytes` if it is a crate file (a ``.usdz`` package: member by
    member, each crate file it stores). Raises as :func:`check_crate_bytes`."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(8)
        if head == CRATE_MAGIC:
            # mapped, not read: the check touches the structure and each value's header, not the
            # values (a copy of a 20 MB clip cost more than the check); USD maps the file as well.
            # Not closed here: arrays the check made may still view it (an error's traceback); it
            # closes when the last of them goes
            listed = check_crate_bytes(mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ), path, children=True)
            return CrateCheck(True, listed)
        if head[:4] == b"PK\x03\x04":
            return CrateCheck(True, _check_package(path, f))  # the file open already (not opened again)
    return CrateCheck(False, False)


def check_crate(path: str | os.PathLike) -> bool:
    """Check ``path`` with :func:`check_crate_bytes` if it is a crate file; whether it was one.

    A ``.usdz`` package is checked member by member (each crate file it stores; True).
    """
    return check_crate_file(path).crate


#: A zip local file header: its signature, and where the lengths of the name and the extra field are.
_LOCAL_HEADER, _LOCAL_HEADER_SIZE = b"PK\x03\x04", 30
#: Most local headers a package's walk visits.
_MAX_LOCAL_HEADERS = 100_000


def _walk_local_headers(data, members: dict) -> None:
    """Add to ``members`` (``(start, size) -> name``) the stored members a walk of the local headers of
    ``data`` finds from offset 0: each header's data (its compressed and its uncompressed size, where
    they differ) followed by the next header."""
    todo, seen = [0], set()
    while todo and len(seen) < _MAX_LOCAL_HEADERS:
        at = todo.pop()
        if at in seen or data[at:at + 4] != _LOCAL_HEADER or at + _LOCAL_HEADER_SIZE > len(data):
            continue
        seen.add(at)
        method, = struct.unpack_from("<H", data, at + 8)
        packed, size, name_size, extra_size = struct.unpack_from("<IIHH", data, at + 18)
        start = at + _LOCAL_HEADER_SIZE + name_size + extra_size
        name = bytes(data[at + _LOCAL_HEADER_SIZE:at + _LOCAL_HEADER_SIZE + name_size]).decode("utf-8", "replace")
        for n in {packed, size}:
            if method == 0:
                members.setdefault((start, n), name)
            todo.append(start + n)


def _root_member(data) -> tuple[int, int] | None:
    """``(start, size)`` of the member USD opens as a package's root layer, the first (the local header
    at offset 0), where it is simply a stored crate file: stored, its two sizes equal, a plain name
    ending in .usdc or .usd; else None."""
    if data[:4] != _LOCAL_HEADER or len(data) < _LOCAL_HEADER_SIZE:
        return None
    method, = struct.unpack_from("<H", data, 8)
    packed, size, name_size, extra_size = struct.unpack_from("<IIHH", data, 18)
    name = bytes(data[_LOCAL_HEADER_SIZE:_LOCAL_HEADER_SIZE + name_size])
    if method != 0 or packed != size or not name.isascii() or not name.decode().isprintable() or b"[" in name \
            or b"]" in name or not name.lower().endswith((b".usdc", b".usd")):
        return None
    return _LOCAL_HEADER_SIZE + name_size + extra_size, size


def _check_package(path: Path, f) -> bool:
    """Check each crate file a ``.usdz`` stores, as the bytes USD reads: after the member's local
    header, whatever its checksum says, sliced from the mapped package (no checksum of every member).

    The members are those a walk of the local headers from the start of the package finds (each
    header's data followed by the next header): USD finds members that way (``UsdZipFile``'s
    iterator, from offset 0, the sizes of each local header) and never reads the central
    directory. A package whose central directory points elsewhere (usdz fuzz: an entry's offset
    changed) handed USD a crate a check of the directory's members had not read, which made it
    map 9.6 GB. ``f``: the package, open for reading in binary (:func:`check_crate`'s, not opened again).

    Returns whether the bytes show that every child the root layer's specs list has a spec (the root
    layer: the first member, :func:`_root_member`, a crate file; :func:`check_crate_bytes`' ``children``).
    """
    listed = False
    try:
        # not closed here, as check_crate's map: each member is checked through a view of the map (a
        # copy of CesiumMan.usdz's 220 KB crate and its page faults cost more than the check's reads),
        # which arrays the check made (an error's traceback) may still hold; it closes with the last
        data = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        members = {}  # (start, size) -> name
        _walk_local_headers(data, members)
        root = _root_member(data)
        for (start, size), name in sorted(members.items()):
            if size < 8 or data[start:start + 8] != CRATE_MAGIC:
                continue  # USD reads only stored members (it refuses the others itself)
            try:
                ok = check_crate_bytes(memoryview(data)[start:start + size], children=(start, size) == root)
            except AssetReadError as e:
                shown = name if name.isprintable() else repr(name)[1:-1]  # a name holding a line break (usdz fuzz)
                raise AssetReadError(f"{shown}: {e.message}", path=path) from None
            listed = listed or ok
    except (OSError, ValueError):
        return False  # not a readable package (an empty file cannot be mapped): USD says so itself
    return listed
