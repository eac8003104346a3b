# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The byte loops and walks of :mod:`usdhands.formats.usdc_crate`'s check, compiled ahead of time.

:func:`lz4_block_decompress` and :func:`decode_ints` take the same arguments and give the
same results as the Python functions of that module (the same bytes, the same int64
integers, the same ``ValueError`` messages, raised at the same point of the input), which
stay the reference and run where this module was not built. A crate check of CesiumMan.usdz
spent about 0.11 ms of its 0.27 in them (8 LZ4 blocks, 7 runs of integers).

:func:`check_structure`, :func:`walk_values` and :func:`spec_types` are ``_Crate.table_of_contents``
with ``structural`` (the header, the table of contents, the six structural sections), the walk of
``_Crate.values`` (every value the fields point to) and ``_Crate.spec_types`` (the path tree and each
spec's type): the same checks in the same order, raising the caller's exception with the same message
for the same first claim that does not fit (the Python methods, ``python_values`` and
``python_spec_types`` stay the reference). Their Python
walks took 0.12 of the 0.23 ms of CesiumMan.usdz's check in a loop (~40 values, 4 runs of value
reps, each step a few small NumPy calls or struct reads), the structure 0.03 more. Tests hold each to
its twin on files USD writes, on their headers, sections, value reps, bytes and tables changed and cut
short, and on random path trees.
"""

from cpython.bytes cimport PyBytes_FromStringAndSize
from libc.stdint cimport int64_t, uint64_t, int8_t, int16_t, int32_t, uint32_t, INT64_MAX
from libc.stdlib cimport malloc, realloc, free
from libc.string cimport memcpy

import numpy as np


cdef Py_ssize_t _length(const unsigned char[::1] src, Py_ssize_t *i, Py_ssize_t length, str what) except -1:
    """A sequence's length, its 4 bits extended by bytes while they are 255 (as ``_lz4_length``)."""
    cdef Py_ssize_t n = src.shape[0]
    cdef unsigned char b
    if length != 15:
        return length
    while True:
        if i[0] >= n:
            raise ValueError(f"LZ4 {what} length runs past the block")
        b = src[i[0]]
        i[0] += 1
        length += b
        if b != 255:
            return length


cdef unsigned char *_grown(unsigned char *out, Py_ssize_t *cap, Py_ssize_t need) except NULL:
    """``out`` reallocated to the first doubling of ``cap[0]`` that holds ``need`` bytes (``cap`` updated);
    MemoryError where there is no such memory (``out`` is then still the caller's to free)."""
    cdef Py_ssize_t new_cap = cap[0]
    cdef unsigned char *grown
    while need > new_cap:
        new_cap *= 2
    grown = <unsigned char *>realloc(out, new_cap)
    if grown == NULL:
        raise MemoryError()
    cap[0] = new_cap
    return grown


def lz4_block_decompress(const unsigned char[::1] src, Py_ssize_t limit):
    """Decode one LZ4 block; at most ``limit`` bytes out (``usdc_crate.lz4_block_decompress``'s twin)."""
    cdef Py_ssize_t i = 0, n = src.shape[0], literal, length, offset, start, k, size = 0
    cdef Py_ssize_t cap = 256
    cdef unsigned char token
    cdef unsigned char *out = <unsigned char *>malloc(cap)
    if out == NULL:
        raise MemoryError()
    try:
        while i < n:
            token = src[i]
            i += 1
            literal = token >> 4
            if literal == 15:
                literal = _length(src, &i, literal, "literal")
            if i + literal > n:
                raise ValueError("LZ4 literals run past the block")
            if size + literal > cap:
                out = _grown(out, &cap, size + literal)
            if literal:
                memcpy(out + size, &src[i], literal)
            size += literal
            i += literal
            if i == n:
                break  # the last sequence holds literals only
            if i + 2 > n:
                raise ValueError("LZ4 match offset runs past the block")
            offset = src[i] | (src[i + 1] << 8)
            i += 2
            if offset == 0 or offset > size:
                raise ValueError("LZ4 match offset outside the output")
            length = token & 15
            if length == 15:
                length = _length(src, &i, length, "match")
            length += 4
            if size + length > limit:
                raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
            if size + length > cap:
                out = _grown(out, &cap, size + length)
            start = size - offset
            for k in range(length):  # forward, byte by byte: an overlapping match repeats the last `offset` bytes
                out[size + k] = out[start + k]
            size += length
            if size > limit:
                raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
        if size > limit:
            raise ValueError(f"LZ4 block decodes to more than {limit} bytes")
        return PyBytes_FromStringAndSize(<char *>out, size)
    finally:
        free(out)


def decode_ints(const unsigned char[::1] encoded, Py_ssize_t n, int width=4):
    """Sdf's integer coding decoded: ``n`` int64 (``usdc_crate.decode_ints``'s twin: the sums wrap
    as int64, as NumPy's cumulative sum does; ValueError when the bytes are too few)."""
    cdef Py_ssize_t size = encoded.shape[0]
    cdef Py_ssize_t codes_size = (2 * n + 7) // 8
    cdef Py_ssize_t pos, k, need
    cdef int code
    cdef int64_t common
    cdef uint64_t total = 0
    cdef int64_t[::1] view
    if size < width + codes_size:
        raise ValueError(f"{size} bytes hold no {n} coded integers")
    if width == 4:
        common = <int32_t>(<uint64_t>encoded[0] | (<uint64_t>encoded[1] << 8) | (<uint64_t>encoded[2] << 16)
                           | (<uint64_t>encoded[3] << 24))
    else:
        common = 0
        for k in range(8):
            common |= <int64_t>(<uint64_t>encoded[k] << (8 * k))
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    # every delta inside the bytes (the NumPy path's test, made before it decodes)
    pos = width + codes_size
    need = 0
    for k in range(n):
        code = (encoded[width + (k >> 2)] >> ((k & 3) << 1)) & 3
        if code:
            need += (1 << (code - 1)) if width == 4 else (2 << (code - 1))
    if pos + need > size:
        raise ValueError(f"{size} bytes hold no {n} coded integers")
    out = np.empty(n, dtype=np.int64)
    view = out
    for k in range(n):
        code = (encoded[width + (k >> 2)] >> ((k & 3) << 1)) & 3
        if code == 0:
            total += <uint64_t>common
        elif width == 4:
            if code == 1:
                total += <uint64_t>(<int64_t>(<int8_t>encoded[pos]))
                pos += 1
            elif code == 2:
                total += <uint64_t>(<int64_t>(<int16_t>(<uint64_t>encoded[pos] | (<uint64_t>encoded[pos + 1] << 8))))
                pos += 2
            else:
                total += <uint64_t>(<int64_t>(<int32_t>(<uint64_t>encoded[pos] | (<uint64_t>encoded[pos + 1] << 8)
                                                         | (<uint64_t>encoded[pos + 2] << 16)
                                                         | (<uint64_t>encoded[pos + 3] << 24))))
                pos += 4
        else:
            if code == 1:
                total += <uint64_t>(<int64_t>(<int16_t>(<uint64_t>encoded[pos] | (<uint64_t>encoded[pos + 1] << 8))))
                pos += 2
            elif code == 2:
                total += <uint64_t>(<int64_t>(<int32_t>(<uint64_t>encoded[pos] | (<uint64_t>encoded[pos + 1] << 8)
                                                         | (<uint64_t>encoded[pos + 2] << 16)
                                                         | (<uint64_t>encoded[pos + 3] << 24))))
                pos += 4
            else:
                total += (<uint64_t>encoded[pos] | (<uint64_t>encoded[pos + 1] << 8) | (<uint64_t>encoded[pos + 2] << 16)
                          | (<uint64_t>encoded[pos + 3] << 24) | (<uint64_t>encoded[pos + 4] << 32)
                          | (<uint64_t>encoded[pos + 5] << 40) | (<uint64_t>encoded[pos + 6] << 48)
                          | (<uint64_t>encoded[pos + 7] << 56))
                pos += 8
        view[k] = <int64_t>total
    return out


# ------------------------------------------------------------------------------------------------
# The walk of the values (``usdc_crate._Crate.values``) and of the path tree (``_Crate.spec_types``):
# the same checks in the same order, the same messages, raised as the caller's exception class.

from libc.stdlib cimport qsort

cdef uint64_t _ARRAY = (<uint64_t>1) << 63
cdef uint64_t _INLINED = (<uint64_t>1) << 62
cdef uint64_t _COMPRESSED = (<uint64_t>1) << 61
cdef uint64_t _EDIT = (<uint64_t>1) << 60
cdef uint64_t _PAYLOAD = ((<uint64_t>1) << 48) - 1
cdef int _MAX_VALUE_DEPTH = 64
cdef int _MIN_COMPRESSED_ARRAY = 16
cdef uint64_t _LZ4_MAX_RATIO = 256

# type enumerant -> bytes per array element as stored (usdc_crate._ELEMENT_BYTES), 0 for none
cdef int _ELEMENT[256]
cdef int _k
for _k in range(256):
    _ELEMENT[_k] = 0
for _k, _v in {1: 1, 2: 1, 3: 4, 4: 4, 5: 8, 6: 8, 7: 2, 8: 4, 9: 8, 10: 4, 11: 4, 12: 4, 13: 32, 14: 72,
               15: 128, 16: 32, 17: 16, 18: 8, 19: 16, 20: 8, 21: 4, 22: 8, 23: 24, 24: 12, 25: 6, 26: 12,
               27: 32, 28: 16, 29: 8, 30: 16, 56: 8, 57: 4}.items():
    _ELEMENT[_k] = _v

# tables: 0 token, 1 string, 2 path
cdef tuple _TABLE_NAMES = ("token", "string", "path")


cdef int _compare_u64(const void *a, const void *b) noexcept nogil:
    cdef uint64_t x = (<const uint64_t *>a)[0], y = (<const uint64_t *>b)[0]
    return (x > y) - (x < y)


cdef inline uint64_t _le64(const unsigned char *p) noexcept nogil:
    return (<uint64_t>p[0] | (<uint64_t>p[1] << 8) | (<uint64_t>p[2] << 16) | (<uint64_t>p[3] << 24)
            | (<uint64_t>p[4] << 32) | (<uint64_t>p[5] << 40) | (<uint64_t>p[6] << 48) | (<uint64_t>p[7] << 56))


cdef inline uint32_t _le32(const unsigned char *p) noexcept nogil:
    return <uint32_t>p[0] | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef inline bint _is_string(int kind) noexcept nogil:
    return kind == 10


cdef inline bint _is_token(int kind) noexcept nogil:
    return kind == 11 or kind == 12


cdef class _ValueWalk:
    """``_Crate.values`` and the methods it calls, over the file's bytes (positions as int64: every one
    is checked against the file's size before a sum that could leave it is made)."""
    cdef const unsigned char *data
    cdef int64_t size
    cdef uint64_t tables[3]
    cdef bint wide, payload24
    cdef object error
    cdef set seen
    cdef uint64_t *arrays
    cdef Py_ssize_t n_arrays, cap_arrays

    def __dealloc__(self):
        free(self.arrays)

    cdef int fail(self, str message) except -1:
        raise self.error(message)

    # -- primitive reads (usdc_crate._Crate.u64, i64, u32, fits, count, index, index_run) --------
    cdef int past(self, object at, str what) except -1:
        raise self.error(f"{what} at byte {at} is past the end of the file ({self.size} bytes)")

    cdef uint64_t u64(self, int64_t at, str what) except? 0xFFFFFFFFFFFFFFFF:
        if at < 0 or at > self.size - 8:
            self.past(at, what)
        return _le64(self.data + at)

    cdef int64_t i64(self, int64_t at, str what) except? -1:
        if at < 0 or at > self.size - 8:
            self.past(at, what)
        return <int64_t>_le64(self.data + at)

    cdef uint32_t u32(self, int64_t at, str what) except? 0xFFFFFFFF:
        if at < 0 or at > self.size - 4:
            self.past(at, what)
        return _le32(self.data + at)

    cdef int fits(self, int64_t at, uint64_t nbytes, str what, int64_t end=-1) except -1:
        """``nbytes`` from ``at`` inside the file, or before ``end`` (``at`` is never negative here)."""
        if end < 0:
            end = self.size
        if at > end or nbytes > <uint64_t>(end - at):
            raise self.error(f"{what} claims {nbytes} bytes at byte {at}, past the end of its "
                             f"{'section' if end != self.size else 'file'} ({end} bytes)")
        return 0

    cdef int count(self, uint64_t n, int64_t at, int64_t element, str what, int64_t end=-1) except -1:
        cdef int64_t room
        if end < 0:
            end = self.size
        room = end - at
        if room < 0:
            room = 0
        if n > <uint64_t>(room // element):
            raise self.error(f"{what} claims {n} entries; the {room} bytes after it hold at most {room // element}")
        return 0

    cdef int index(self, uint64_t value, int table, str what) except -1:
        if value >= self.tables[table]:
            raise self.error(f"{what} names {_TABLE_NAMES[table]} {value} of {self.tables[table]}")
        return 0

    cdef int index_run(self, int64_t at, uint64_t n, int table, str what) except -1:
        cdef uint64_t k, most = 0, v
        self.count(n, at, 4, what)
        if n == 0:
            return 0
        for k in range(n):
            v = _le32(self.data + at + 4 * k)
            if v > most:
                most = v
        return self.index(most, table, what)

    # -- compressed blocks (_Crate.compressed_span, compressed_ints) ------------------------------
    cdef int compressed_span(self, int64_t at, uint64_t size, str what, int64_t end=-1) except -1:
        cdef int64_t pos, stop
        cdef int32_t n
        cdef int chunks, c
        self.fits(at, size, what, end)
        if size == 0:
            raise self.error(f"{what} is empty")
        chunks = self.data[at]
        pos, stop = at + 1, at + <int64_t>size
        for c in range(chunks):
            if pos + 4 > stop:
                raise self.error(f"{what}: its chunk table runs past its {size} bytes")
            n = <int32_t>_le32(self.data + pos)
            pos += 4
            if n < 0 or pos + n > stop:
                raise self.error(f"{what}: a chunk of {n} bytes runs past its {size} bytes")
            pos += n
        return 0

    cdef int64_t compressed_ints(self, int64_t at, uint64_t n, str what, int64_t end=-1) except -1:
        """``n`` integers stored compressed from ``at``; returns the position after them."""
        cdef uint64_t size = self.u64(at, f"{what} size")
        cdef uint64_t most
        self.compressed_span(at + 8, size, what, end)
        most = 4 * _LZ4_MAX_RATIO * size + 64
        if n > most:
            raise self.error(f"{what} claims {n} integers; its {size} compressed bytes hold at most {most}")
        return at + 8 + <int64_t>size

    # -- structure (usdc_crate._Crate.decompress, ints) ------------------------------------------
    cdef object decompress(self, const unsigned char[::1] data, int64_t at, uint64_t size, int64_t limit, str what,
                           int64_t end):
        cdef int chunks, c
        cdef int64_t pos
        cdef int32_t n
        self.compressed_span(at, size, what, end)
        chunks = self.data[at]
        try:
            if chunks == 0:
                return lz4_block_decompress(data[at + 1:at + <int64_t>size], limit)
            out, pos = bytearray(), at + 1
            for c in range(chunks):
                n = <int32_t>_le32(self.data + pos)
                out += lz4_block_decompress(data[pos + 4:pos + 4 + n], limit - len(out))
                pos += 4 + n
            return bytes(out)
        except ValueError as e:
            raise self.error(f"{what}: {e}") from None

    cdef tuple ints(self, const unsigned char[::1] data, int64_t at, uint64_t n, str what, int64_t end):
        cdef int64_t after = self.compressed_ints(at, n, what, end)
        cdef int64_t limit = 4 + (2 * <int64_t>n + 7) // 8 + 4 * <int64_t>n
        raw = self.decompress(data, at + 8, <uint64_t>(after - at - 8), limit, what, end)
        try:
            values = decode_ints(raw, n)
        except ValueError as e:
            raise self.error(f"{what}: {e}") from None
        return values, after

    # -- values (_Crate.many, value, list_items, payload, dictionary, vt_value) -------------------
    cdef int keep_array(self, uint64_t rep) except -1:
        cdef uint64_t *grown
        if self.n_arrays == self.cap_arrays:
            grown = <uint64_t *>realloc(self.arrays, sizeof(uint64_t) * (2 * self.cap_arrays + 16))
            if grown == NULL:
                raise MemoryError()
            self.arrays = grown
            self.cap_arrays = 2 * self.cap_arrays + 16
        self.arrays[self.n_arrays] = rep
        self.n_arrays += 1
        return 0

    cdef int many(self, const unsigned char *reps, Py_ssize_t n, int depth) except -1:
        cdef Py_ssize_t k, m = 0
        cdef uint64_t rep, most
        cdef int kind, table
        cdef bint any_named
        cdef uint64_t *others
        # inlined strings, then inlined tokens: the largest index of each against its table
        for table in (1, 0):
            most, any_named = 0, False
            for k in range(n):
                rep = _le64(reps + 8 * k)
                kind = (rep >> 48) & 0xFF
                if rep & _INLINED and not rep & _ARRAY and (_is_string(kind) if table == 1 else _is_token(kind)):
                    any_named = True
                    if rep & 0xFFFFFFFF > most:
                        most = rep & 0xFFFFFFFF
            if any_named:
                self.index(most, table, "a value")
        for k in range(n):
            rep = _le64(reps + 8 * k)
            if rep & _INLINED:
                continue
            if rep & _ARRAY:
                self.keep_array(rep)
            else:
                m += 1
        if m == 0:
            return 0
        others = <uint64_t *>malloc(sizeof(uint64_t) * m)
        if others == NULL:
            raise MemoryError()
        try:
            m = 0
            for k in range(n):
                rep = _le64(reps + 8 * k)
                if not rep & (_INLINED | _ARRAY):
                    others[m] = rep
                    m += 1
            qsort(others, m, sizeof(uint64_t), _compare_u64)
            for k in range(m):
                if k and others[k] == others[k - 1]:
                    continue
                self.value(others[k], depth)
        finally:
            free(others)
        return 0

    cdef int value(self, uint64_t rep, int depth) except -1:
        cdef int kind
        cdef int64_t at, jump, times, where
        cdef uint64_t times_rep, n, held
        cdef int header, bit
        key = rep
        if key in self.seen:
            return 0
        self.seen.add(key)
        if depth > _MAX_VALUE_DEPTH:
            raise self.error(f"values nested more than {_MAX_VALUE_DEPTH} deep")
        kind = (rep >> 48) & 0xFF
        at = <int64_t>(rep & _PAYLOAD)
        if rep & _INLINED:
            if not rep & _ARRAY and (kind == 10 or kind == 11 or kind == 12):
                self.index(<uint64_t>at & 0xFFFFFFFF, 1 if kind == 10 else 0, "a value")
        elif rep & _ARRAY:
            self.keep_array(rep)
        elif rep & _EDIT:
            return 0
        elif kind == 10 or kind == 11 or kind == 12 or kind == 57:
            self.index_run(at, 1, 0 if (kind == 11 or kind == 12) else 1, "a value")
        elif kind == 31:
            self.dictionary(at, depth)
        elif kind == 52 or kind == 53:
            self.vt_value(at, depth)
        elif kind == 46:
            jump = self.i64(at, "time samples offset")
            if jump < 8:
                raise self.error(f"time samples offset {jump} points backwards")
            if jump > self.size:
                self.past(<object>at + jump, "time samples times")
            times = at + jump
            times_rep = self.u64(times, "time samples times")
            self.value(times_rep, depth + 1)
            jump = self.i64(times + 8, "time samples values offset")
            if jump < 8:
                raise self.error(f"time samples values offset {jump} points backwards")
            if jump > self.size:
                self.past(<object>times + 8 + jump, "time sample count")
            where = times + 8 + jump
            n = self.u64(where, "time sample count")
            self.count(n, where + 8, 8, "time samples")
            if (times_rep >> 48) & 0xFF == 48 and not times_rep & (_INLINED | _ARRAY):
                held = self.u64(<int64_t>(times_rep & _PAYLOAD), "time samples times")
                if held > n:
                    raise self.error(f"time samples claim {held} times for {n} values")
            self.many(self.data + where + 8, <Py_ssize_t>n, depth + 1)
        elif kind == 40 or kind == 41 or kind == 50 or kind == 45 or kind == 58:
            n = self.u64(at, "vector size")
            if kind == 45 or kind == 58:  # two indices an entry: the count may pass 64 bits
                if n > <uint64_t>(max(self.size - (at + 8), 0) // 4) // 2:
                    room = max(self.size - (at + 8), 0)
                    raise self.error(f"a vector value claims {(<object>n) * 2} entries; the {room} bytes after it "
                                     f"hold at most {room // 4}")
                n *= 2
            self.index_run(at + 8, n, 2 if (kind == 40 or kind == 58) else (0 if kind == 41 else 1), "a vector value")
        elif kind == 48 or kind == 49:
            self.count(self.u64(at, "vector size"), at + 8, 8 if kind == 48 else 16, "a vector value")
        elif kind == 47:
            self.payload(at)
        elif 32 <= kind <= 39 or kind == 54 or kind == 55:
            self.fits(at, 1, "a list op")
            header = self.data[at]
            at += 1
            for bit in range(1, 7):
                if header & (1 << bit):
                    at = self.list_items(kind, at, depth)
        return 0

    cdef int64_t list_items(self, int kind, int64_t at, int depth) except -1:
        cdef uint64_t n = self.u64(at, "list op size"), k
        cdef int64_t pos = at + 8, element
        if 32 <= kind <= 34:
            self.index_run(pos, n, 0 if kind == 32 else (1 if kind == 33 else 2), "a list op")
            return pos + 4 * <int64_t>n
        if 36 <= kind <= 39:
            element = 4 if (kind == 36 or kind == 38) else 8
            self.count(n, pos, element, "a list op")
            return pos + <int64_t>n * element
        self.count(n, pos, 16, "a list op")
        for k in range(n):
            if kind == 35:
                self.index_run(pos, 1, 1, "a reference")
                self.index_run(pos + 4, 1, 2, "a reference")
                pos = self.dictionary(pos + 24, depth)
            elif kind == 55:
                pos = self.payload(pos)
            else:
                pos = self.vt_value(pos, depth)
        return pos

    cdef int64_t payload(self, int64_t at) except -1:
        self.index_run(at, 1, 1, "a payload")
        self.index_run(at + 4, 1, 2, "a payload")
        return at + (24 if self.payload24 else 8)

    cdef int64_t dictionary(self, int64_t at, int depth) except -1:
        cdef uint64_t n = self.u64(at, "dictionary size"), k
        cdef int64_t pos = at + 8
        self.count(n, at + 8, 12, "a dictionary")
        for k in range(n):
            self.index_run(pos, 1, 1, "a dictionary key")
            pos = self.vt_value(pos + 4, depth)
        return pos

    cdef int64_t vt_value(self, int64_t at, int depth) except -1:
        cdef int64_t jump = self.i64(at, "value offset"), where
        if jump < 8:
            raise self.error(f"value offset {jump} points backwards")
        if jump > self.size:
            self.past(<object>at + jump, "value")
        where = at + jump
        self.value(self.u64(where, "value"), depth + 1)
        return where + 8

    # -- arrays (_Crate.arrays, compressed_array) -------------------------------------------------
    cdef int check_arrays(self) except -1:
        cdef Py_ssize_t k, m = 0
        cdef uint64_t rep, n, room
        cdef int64_t at, head = 8 if self.wide else 4, element
        cdef int kind
        cdef uint64_t *reps = self.arrays
        if self.n_arrays == 0:
            return 0
        qsort(reps, self.n_arrays, sizeof(uint64_t), _compare_u64)
        for k in range(self.n_arrays):  # unique, and only those with an offset and an element size
            rep = reps[k]
            if k and rep == reps[k - 1]:
                continue
            if (rep & _PAYLOAD) != 0 and _ELEMENT[(rep >> 48) & 0xFF] > 0:
                reps[m] = rep
                m += 1
        for k in range(m):
            at = <int64_t>(reps[k] & _PAYLOAD)
            if at + head > self.size:
                raise self.error(f"an array at byte {at} is past the end of the file ({self.size} bytes)")
        for k in range(m):
            if self.plain(reps[k], head) and self.claimed(reps[k], head) > <uint64_t>(
                    (self.size - <int64_t>(reps[k] & _PAYLOAD) - head) // _ELEMENT[(reps[k] >> 48) & 0xFF]):
                at = <int64_t>(reps[k] & _PAYLOAD)
                element = _ELEMENT[(reps[k] >> 48) & 0xFF]
                raise self.error(f"an array claims {self.claimed(reps[k], head)} entries; the {self.size - at - head} "
                                 f"bytes after it hold at most {<uint64_t>((self.size - at - head) // element)}")
        for k in range(m):
            if not self.plain(reps[k], head):
                self.compressed_array((reps[k] >> 48) & 0xFF, <int64_t>(reps[k] & _PAYLOAD) + head,
                                      self.claimed(reps[k], head), _ELEMENT[(reps[k] >> 48) & 0xFF])
        for k in range(m):
            kind = (reps[k] >> 48) & 0xFF
            if kind == 10 or kind == 11 or kind == 12 or kind == 57:
                self.index_run(<int64_t>(reps[k] & _PAYLOAD) + head, self.claimed(reps[k], head),
                               0 if (kind == 11 or kind == 12) else 1, "an array")
        return 0

    cdef inline uint64_t claimed(self, uint64_t rep, int64_t head) noexcept:
        cdef const unsigned char *p = self.data + <int64_t>(rep & _PAYLOAD)
        return _le64(p) if head == 8 else <uint64_t>_le32(p)

    cdef inline bint plain(self, uint64_t rep, int64_t head) noexcept:
        """Not stored compressed: no compressed bit, a type stored uncompressed, or fewer than 16 elements."""
        cdef int kind = (rep >> 48) & 0xFF
        return not (rep & _COMPRESSED and 3 <= kind <= 9 and self.claimed(rep, head) >= _MIN_COMPRESSED_ARRAY)

    cdef int compressed_array(self, int kind, int64_t pos, uint64_t n, int64_t element) except -1:
        cdef unsigned char code
        cdef uint64_t lut
        if 7 <= kind <= 9:
            self.fits(pos, 1, "a compressed array")
            code = self.data[pos]
            pos += 1
            if code == ord("t"):
                lut = self.u32(pos, "lookup table size")
                self.count(lut, pos + 4, element, "a lookup table")
                pos += 4 + <int64_t>lut * element
            elif code != ord("i"):
                raise self.error(f"compressed array code {code} is neither 'i' nor 't'")
        return self.compressed_ints(pos, n, "a compressed array")


def walk_values(const unsigned char[::1] data, const unsigned char[::1] reps, tokens, strings, paths,
                bint wide, bint payload24, error):
    """``usdc_crate._Crate.values`` (the file's ``data``, FIELDS' value ``reps``, the sizes of the token,
    string and path tables, crate version >= 0.7.0 and >= 0.8.0): None, or ``error(message)`` raised
    with the Python walk's message for the first claim that does not fit, found in the same order."""
    cdef _ValueWalk walk = _ValueWalk()
    walk.data = &data[0] if data.shape[0] else NULL
    walk.size = data.shape[0]
    walk.tables[0], walk.tables[1], walk.tables[2] = tokens, strings, paths
    walk.wide, walk.payload24 = wide, payload24
    walk.error = error
    walk.seen = set()
    walk.many(&reps[0] if reps.shape[0] else NULL, reps.shape[0] // 8, 0)
    walk.check_arrays()


cdef tuple _KINDS = ("", "root", "prim", "property", "target")


cdef Py_ssize_t _walk_tree(const int64_t[::1] jumps, Py_ssize_t n, int64_t *order, int64_t *parents,
                           int64_t *stack, int64_t *bad) noexcept:
    """A crate's path tree walked from entry 0 as USD builds its paths from ``jumps`` (-1: a child only, at
    the next entry; 0: a sibling only, at the next entry; > 0: both, the sibling at entry + jump; -2:
    neither). Each entry reached goes into ``order`` (a parent before its children) with its parent in
    ``parents`` (-1: the root), which must hold -2 ("not reached") for every entry on the call. Returns
    how many entries were reached, or -1 with ``bad[0]`` the first entry reached twice or outside 0..n-1.
    ``stack``: room for n + 1 (entry, parent) pairs (each entry reached pushes at most one). The caller
    has refused jumps that could take an entry past 64 bits."""
    cdef Py_ssize_t top = 1, count = 0
    cdef int64_t here, parent, jump
    cdef bint has_child, has_sibling
    if n == 0:
        return 0
    stack[0], stack[1] = 0, -1
    while top:
        top -= 1
        here, parent = stack[2 * top], stack[2 * top + 1]
        while True:
            if here < 0 or here >= n or parents[here] != -2:
                bad[0] = here
                return -1
            parents[here] = parent
            order[count] = here
            count += 1
            jump = jumps[here]
            has_child, has_sibling = jump > 0 or jump == -1, jump >= 0
            if has_child and has_sibling:
                stack[2 * top], stack[2 * top + 1] = here + jump, parent
                top += 1
            if has_child:
                parent = here
            if not (has_child or has_sibling):
                break
            here += 1
    return count


def spec_types(const int64_t[::1] spec_paths, const int64_t[::1] spec_types_, const int64_t[::1] indexes,
               const int64_t[::1] elements, const int64_t[::1] jumps, error):
    """``usdc_crate._Crate.spec_types`` on the decoded SPECS (path indexes, types) and PATHS (indexes,
    element tokens, jumps): True when checked (``error(message)`` raised for a type that does not fit or a
    walk that loops or leaves the table), False where the path indexes leave ``0..n-1`` or a jump
    could leave 64 bits: the Python function decides those."""
    cdef Py_ssize_t n = min(indexes.shape[0], elements.shape[0], jumps.shape[0]), k, reached
    cdef Py_ssize_t m = min(spec_paths.shape[0], spec_types_.shape[0])
    cdef int64_t here, parent, t, bad = 0
    cdef int where
    cdef bint fits_type
    for k in range(n):
        if indexes[k] < 0 or indexes[k] >= n or jumps[k] > INT64_MAX - n:
            return False
    kind = np.zeros(n + 1, dtype=np.int8)  # by entry
    cdef signed char[::1] kinds = kind
    of = np.zeros(n + 1, dtype=np.int8)  # by path index
    cdef signed char[::1] of_path = of
    walk = np.full(2 * n + 2 * (n + 1) + 1, -2, dtype=np.int64)  # parents, order, stack
    cdef int64_t[::1] w = walk
    reached = _walk_tree(jumps, n, &w[n], &w[0], &w[2 * n], &bad)
    if reached < 0:
        raise error(f"PATHS: its jumps table reaches entry {bad} twice or outside 0..{n - 1}")
    for k in range(reached):  # root, property, target or prim, each after its parent
        here = w[n + k]
        parent = w[here]
        if parent < 0:
            kinds[here] = 1
        elif elements[here] < 0:
            kinds[here] = 3
        else:
            kinds[here] = 4 if kinds[parent] >= 3 else 2
    for k in range(n):
        if kinds[k]:
            of_path[indexes[k]] = kinds[k]
    for k in range(m):
        if spec_paths[k] < 0 or spec_paths[k] >= n:
            continue
        where = of_path[spec_paths[k]]
        if not where:
            continue
        t = spec_types_[k]
        if where == 1:
            fits_type = t == 7
        elif where == 2:
            fits_type = t == 6 or t == 10 or t == 11
        elif where == 3:
            fits_type = t == 1 or t == 8
        else:
            fits_type = 2 <= t <= 5 or t == 9
        if not fits_type:
            raise error(f"SPECS: a spec of type {t} on a {_KINDS[where]} path")
    return True


def check_structure(const unsigned char[::1] data, error, list kept=None):
    """``usdc_crate._Crate.table_of_contents`` then ``structural`` (the bootstrap, the table of contents and
    the six structural sections, the same checks in the same order and the same messages, raised as
    ``error(message)``): ``(version, token count, string count, path count, FIELDS' value reps or None,
    SPECS' three arrays or None, PATHS' three arrays or None)``; the caller checks the specs' types.
    ``kept``: a list FIELDSETS' decoded integers are appended to, where they were decoded (for
    :func:`listed_children_have_specs`, which would decode them again)."""
    cdef _ValueWalk c = _ValueWalk()
    cdef int64_t size = data.shape[0], toc, start, length, end, at
    cdef uint64_t n, k, raw, packed, most, reps_size, encoded, tokens = 0, strings = 0, paths_n = 0
    cdef int arrays, a
    cdef bint compressed
    c.size = size
    c.error = error
    if size < 88:
        raise error(f"a .usdc file of {size} bytes is shorter than its 88-byte header")
    c.data = &data[0]
    version = (data[8], data[9], data[10])
    toc = c.i64(16, "table of contents offset")
    if toc > size - 8:
        raise error(f"Sdf crate file corrupt, possibly truncated: table of contents at offset {toc} but "
                    f"file size is {size}")
    if toc < 88:
        raise error(f"table of contents at offset {toc} is inside the header")
    n = c.u64(toc, "section count")
    c.count(n, toc + 8, 32, "table of contents")
    sections = {}
    for k in range(n):
        at = toc + 8 + <int64_t>k * 32
        name = bytes(data[at:at + 16]).split(b"\0", 1)[0].decode("latin-1")
        start, length = <int64_t>_le64(c.data + at + 16), <int64_t>_le64(c.data + at + 24)
        if start < 0 or length < 0 or start > size or length > size - start:
            raise error(f"section {name!r} claims bytes {start} to {<object>start + length}, outside the "
                        f"file ({size} bytes)")
        sections.setdefault(name, (start, start + length))
    compressed = version >= (0, 4, 0)
    reps = specs = paths = None
    if "TOKENS" in sections:
        start, end = sections["TOKENS"]
        n = c.u64(start, "token count")
        if compressed:
            raw = c.u64(start + 8, "token bytes")
            packed = c.u64(start + 16, "token compressed bytes")
            c.compressed_span(start + 24, packed, "TOKENS", end)
            if raw > _LZ4_MAX_RATIO * packed + 64:
                raise error(f"TOKENS claims {raw} bytes from {packed} compressed bytes")
        else:
            raw = c.u64(start + 8, "token bytes")
            c.fits(start + 16, raw, "TOKENS", end)
        if n > (raw if raw > 1 else 1):
            raise error(f"TOKENS claims {n} tokens in {raw} bytes")
        tokens = n
    c.tables[0] = tokens
    if "STRINGS" in sections:
        start, end = sections["STRINGS"]
        n = c.u64(start, "string count")
        c.count(n, start + 8, 4, "STRINGS", end)
        strings = n
        c.tables[1] = strings
        most = 0
        for k in range(n):
            if _le32(c.data + start + 8 + 4 * <int64_t>k) > most:
                most = _le32(c.data + start + 8 + 4 * <int64_t>k)
        if n:
            c.index(most, 0, "STRINGS")
    if "FIELDS" in sections:
        start, end = sections["FIELDS"]
        n = c.u64(start, "field count")
        if compressed:
            at = c.compressed_ints(start + 8, n, "FIELDS tokens", end)
            reps_size = c.u64(at, "FIELDS value reps size")
            if reps_size <= (0xFFFFFFFFFFFFFFFF - 64) // _LZ4_MAX_RATIO and n > (_LZ4_MAX_RATIO * reps_size + 64) // 8:
                raise error(f"FIELDS claims {n} fields from {reps_size} compressed bytes")
            # (a count past what the bytes can hold wraps here; the span's check refuses it before the limit counts)
            reps = c.decompress(data, at + 8, reps_size, <int64_t>(n * <uint64_t>8), "FIELDS value reps", end)
            if <uint64_t>len(reps) != n * 8:
                raise error(f"FIELDS value reps decode to {len(reps)} bytes for {n} fields")
        else:
            c.count(n, start + 8, 16, "FIELDS", end)
    for name, arrays in (("FIELDSETS", 1), ("SPECS", 3)):
        if name in sections:
            start, end = sections[name]
            n = c.u64(start, f"{name} count")
            if compressed:
                at, decoded = start + 8, []
                for a in range(arrays):
                    values, at = c.ints(data, at, n, name, end)
                    decoded.append(values)
                if name == "SPECS":
                    specs = decoded
                elif kept is not None:
                    kept.append(decoded[0])
            else:
                c.count(n, start + 8, 4 * arrays, name, end)
    if "PATHS" in sections:
        start, end = sections["PATHS"]
        n = c.u64(start, "path count")
        paths_n = n
        if compressed:
            c.count(n, start, 1, "PATHS")
            encoded = c.u64(start + 8, "encoded path count")
            at, paths = start + 16, []
            for a in range(3):
                values, at = c.ints(data, at, encoded, "PATHS", end)
                paths.append(values)
        else:
            c.count(n, start + 8, 9, "PATHS", end)
    return version, tokens, strings, paths_n, reps, specs, paths


# ------------------------------------------------------------------------------------------------
# Whether every child a crate's specs list has a spec (``usd_common.check_children``'s question),
# decided from the bytes where that is simple; False where it is not (the Sdf walk then decides).

from libc.string cimport memchr, memcmp

cdef uint32_t _TERMINATOR = 0xFFFFFFFF
cdef int _TOKEN_VECTOR = 41
# spec types (SdfSpecType)
cdef int _ATTRIBUTE = 1, _PRIM = 6, _PSEUDO_ROOT = 7, _RELATIONSHIP = 8
# a token's kind, found when first asked: 0 not yet, then 1 + these bits
cdef int _IDENTIFIER = 1, _NAMESPACED = 2, _PRIM_CHILDREN = 4, _PROPERTIES = 8, _VARIANT_FIELD = 16


cdef object _unpacked(const unsigned char[::1] data, int64_t at, uint64_t size, int64_t end, int64_t limit):
    """The bytes of a TfFastCompression buffer of ``size`` bytes at ``at`` (before ``end``), at most
    ``limit``; None where it is malformed (``_Crate.decompress`` without its messages)."""
    cdef int chunks, c
    cdef int64_t pos, stop
    cdef int32_t n
    if at < 0 or size == 0 or at > end or size > <uint64_t>(end - at) or limit < 0:
        return None
    chunks = data[at]
    stop = at + <int64_t>size
    try:
        if chunks == 0:
            return lz4_block_decompress(data[at + 1:stop], limit)
        out, pos = bytearray(), at + 1
        for c in range(chunks):
            if pos + 4 > stop:
                return None
            n = <int32_t>_le32(&data[pos])
            pos += 4
            if n < 0 or pos + n > stop:
                return None
            out += lz4_block_decompress(data[pos:pos + n], limit - len(out))
            pos += n
        return bytes(out)
    except ValueError:
        return None


cdef object _unpacked_ints(const unsigned char[::1] data, int64_t at, uint64_t n, int64_t end):
    """``n`` compressed 32-bit integers stored from ``at`` (uint64 size, then the buffer), decoded
    (int64), or None where they are not there."""
    cdef uint64_t size
    if at < 0 or at > end - 8 or n > <uint64_t>(end - at):
        return None
    size = _le64(&data[at])
    raw = _unpacked(data, at + 8, size, end, 4 + (2 * <int64_t>n + 7) // 8 + 4 * <int64_t>n)
    if raw is None:
        return None
    try:
        return decode_ints(raw, n)
    except ValueError:
        return None


cdef inline bint _ident_start(unsigned char c) noexcept nogil:
    return (c >= 65 and c <= 90) or (c >= 97 and c <= 122) or c == 95


cdef inline bint _ident_char(unsigned char c) noexcept nogil:
    return _ident_start(c) or (c >= 48 and c <= 57)


cdef int _token_kind(const unsigned char *s, int64_t n) noexcept nogil:
    """A token's bits: a plain ASCII identifier, identifiers joined by ':', one of the children fields."""
    cdef int64_t k
    cdef bint start = True, plain = True
    cdef int kind = 0
    if n == 12 and memcmp(s, b"primChildren", 12) == 0:
        kind |= _PRIM_CHILDREN
    elif n == 10 and memcmp(s, b"properties", 10) == 0:
        kind |= _PROPERTIES
    elif (n == 18 and memcmp(s, b"variantSetChildren", 18) == 0) or (n == 15 and memcmp(s, b"variantChildren", 15) == 0):
        kind |= _VARIANT_FIELD
    if n == 0:
        return kind
    for k in range(n):
        if start:
            if not _ident_start(s[k]):
                return kind
            start = False
        elif s[k] == 58:  # ':'
            plain = False
            start = True
        elif not _ident_char(s[k]):
            return kind
    if start:  # ends with ':'
        return kind
    kind |= _NAMESPACED
    if plain:
        kind |= _IDENTIFIER
    return kind


cdef int _compare_pairs(const void *a, const void *b) noexcept nogil:
    """(parent, element, entry) triples of int64 by parent, then element."""
    cdef const int64_t *x = <const int64_t *>a
    cdef const int64_t *y = <const int64_t *>b
    if x[0] != y[0]:
        return (x[0] > y[0]) - (x[0] < y[0])
    return (x[1] > y[1]) - (x[1] < y[1])


cdef class _Listing:
    """The scratch of :func:`listed_children_have_specs`: one block of memory, freed with the object."""
    cdef int64_t *block

    def __dealloc__(self):
        free(self.block)


def listed_children_have_specs(const unsigned char[::1] data, const unsigned char[::1] reps,
                               const int64_t[::1] spec_paths, const int64_t[::1] spec_fieldsets,
                               const int64_t[::1] spec_types_, const int64_t[::1] indexes,
                               const int64_t[::1] elements, const int64_t[::1] jumps, uint64_t paths_n,
                               field_sets=None):
    """True when the bytes of a crate file (``data``, which the check passed; FIELDS' value ``reps``, the
    decoded SPECS and PATHS, PATHS' count; FIELDSETS' integers where ``check_structure`` kept them) show
    that every child its specs list has a spec, as ``usd_common.check_children`` walks them through Sdf;
    False where that is not shown simply (the walk decides then, and gives the error). Read as USD reads
    them (``crateFile.cpp``: the field sets as runs ended by ~0, the path tree built from the jumps, the
    tokens split on NUL, 32-bit integers) and conservatively: True only when

    - the version is 0.4.0 or later (compressed sections), every index is in its table, the path
      indexes of PATHS and those of SPECS are each unique, the tree is entry 0 (the root, no sibling)
      and each entry is reached once, each spec's field set starts a run;
    - every spec is the root's (pseudo-root, 7), a prim's whose path is the root then plain ASCII
      identifiers (6), or a property's (attribute 1 or relationship 8) of such a prim, named by
      identifiers joined by ':' (so each spec's path is the one its entries spell, and no two specs
      of different kinds share one); no field is ``variantSetChildren`` or ``variantChildren``;
    - each ``primChildren`` and ``properties`` field (the root's: ``primChildren`` only) is a token vector
      stored out of line, not compressed, inside the file, whose names are such identifiers, each the
      element of an entry below the spec's own entry (a property's: negative) that has a spec.

    Then every spec's path is the one its entries spell (USD appends each element to its parent's path;
    an entry whose element it cannot append, and those below it, carry no spec), whichever spec USD keeps
    where two share a path it was checked here, and each name the walk appends to a path it visits is
    the path of an entry found here, which has a spec of the kind the walk looks up.
    """
    cdef Py_ssize_t size = data.shape[0]
    cdef int64_t toc, start, length, at, end, tok_start = -1, tok_end = 0, fld_start = -1, fld_end = 0
    cdef int64_t set_start = -1, set_end = 0
    cdef uint64_t n_sections, n_tokens, raw, packed, n_fields, n_sets, k, j
    cdef Py_ssize_t n = indexes.shape[0], m = spec_paths.shape[0], i, c, reached, lo, hi, mid, p, kk
    cdef int64_t here, parent, e, t, node, rep, count, name, f, s
    cdef const unsigned char *chars
    cdef const unsigned char *zero
    cdef int kind
    cdef bint found

    if size < 88 or (data[8], data[9], data[10]) < (0, 4, 0):
        return False
    if elements.shape[0] != n or jumps.shape[0] != n or spec_fieldsets.shape[0] != m or spec_types_.shape[0] != m:
        return False
    if n == 0 or paths_n == 0 or paths_n > <uint64_t>size:
        return False
    # the table of contents (the first section of each name, as USD's GetSection)
    toc = <int64_t>_le64(&data[16])
    if toc < 88 or toc > size - 8:
        return False
    n_sections = _le64(&data[toc])
    if n_sections > <uint64_t>((size - toc - 8) // 32):
        return False
    for k in range(n_sections):
        at = toc + 8 + <int64_t>k * 32
        start, length = <int64_t>_le64(&data[at + 16]), <int64_t>_le64(&data[at + 24])
        if start < 0 or length < 0 or start > size or length > size - start:
            return False
        zero = <const unsigned char *>memchr(&data[at], 0, 16)
        name = 16 if zero == NULL else zero - &data[at]
        if name == 6 and memcmp(&data[at], b"TOKENS", 6) == 0 and tok_start < 0:
            tok_start, tok_end = start, start + length
        elif name == 6 and memcmp(&data[at], b"FIELDS", 6) == 0 and fld_start < 0:
            fld_start, fld_end = start, start + length
        elif name == 9 and memcmp(&data[at], b"FIELDSETS", 9) == 0 and set_start < 0:
            set_start, set_end = start, start + length
    if tok_start < 0 or fld_start < 0 or set_start < 0:
        return False
    # TOKENS: the decompressed bytes, exactly as many as stated, NUL-ended, split into the stated count
    if tok_end - tok_start < 24:
        return False
    n_tokens, raw, packed = _le64(&data[tok_start]), _le64(&data[tok_start + 8]), _le64(&data[tok_start + 16])
    if raw == 0 or raw > <uint64_t>(_LZ4_MAX_RATIO * <uint64_t>size + 64) or n_tokens > raw:
        return False
    text = _unpacked(data, tok_start + 24, packed, tok_end, <int64_t>raw)
    if text is None or <uint64_t>len(text) != raw:
        return False
    cdef const unsigned char[::1] chars_view = text
    chars = &chars_view[0]
    if chars[raw - 1] != 0:
        return False
    # FIELDS: the token of each field (its value reps are ``reps``)
    if fld_end - fld_start < 8:
        return False
    n_fields = _le64(&data[fld_start])
    if <uint64_t>reps.shape[0] != n_fields * 8 or n_fields > <uint64_t>size:
        return False
    field_tokens = _unpacked_ints(data, fld_start + 8, n_fields, fld_end)
    if field_tokens is None:
        return False
    cdef const int64_t[::1] ftok = field_tokens
    # FIELDSETS: runs of field indices, each ended by ~0
    if set_end - set_start < 8:
        return False
    n_sets = _le64(&data[set_start])
    if n_sets == 0 or n_sets > <uint64_t>size:
        return False
    sets = _unpacked_ints(data, set_start + 8, n_sets, set_end) if field_sets is None else field_sets
    if sets is None or <uint64_t>len(sets) != n_sets:
        return False
    cdef const int64_t[::1] fsets = sets
    if <uint32_t>fsets[n_sets - 1] != _TERMINATOR:
        return False

    # scratch: token offsets (n_tokens + 1) and kinds (n_tokens); by entry: parent, state; by path index:
    # entry, spec; (parent, element, entry) triples of the entries below another
    cdef _Listing scratch = _Listing()
    scratch.block = <int64_t *>malloc(sizeof(int64_t) * (2 * n_tokens + 1 + 2 * n + 2 * paths_n + 3 * n + 1 + n))
    if scratch.block == NULL:
        raise MemoryError()
    cdef int64_t *offsets = scratch.block
    cdef int64_t *kinds = offsets + n_tokens + 1
    cdef int64_t *parents = kinds + n_tokens
    cdef int64_t *state = parents + n  # 0 unreached; 1 root; 2 plain prim; 3 property of a plain prim; 4 other
    cdef int64_t *entry_of = state + n
    cdef int64_t *spec_of = entry_of + paths_n
    cdef int64_t *pairs = spec_of + paths_n  # the walk's stack, then the (parent, element, entry) triples
    cdef int64_t *order = pairs + 3 * n + 1
    # the tokens
    p = 0
    for k in range(n_tokens):
        zero = <const unsigned char *>memchr(chars + p, 0, raw - p)
        if zero == NULL:
            return False
        offsets[k] = p
        kinds[k] = 0
        p = zero - chars + 1
    offsets[n_tokens] = p
    if <uint64_t>p != raw:  # more NULs than tokens: USD would read the same, but say no
        return False
    # PATHS: unique path indexes, elements naming tokens, the tree walked from entry 0 as USD builds it
    for k in range(paths_n):
        entry_of[k] = -1
        spec_of[k] = -1
    for i in range(n):
        if indexes[i] < 0 or <uint64_t>indexes[i] >= paths_n or entry_of[indexes[i]] >= 0:
            return False
        entry_of[indexes[i]] = i
        e = elements[i]
        if e <= -2147483648 or e > 2147483647 or <uint64_t>(e if e >= 0 else -e) >= n_tokens:
            return False
        if jumps[i] < -2 or jumps[i] > 2147483647:
            return False
        state[i] = 0
        parents[i] = -2
    if jumps[0] >= 0:  # the root has a sibling (USD makes it a child of the root)
        return False
    reached = _walk_tree(jumps, n, order, parents, pairs, &here)
    if reached < 0:
        return False
    for i in range(reached):  # each entry after its parent
        here = order[i]
        parent = parents[here]
        if parent < 0:
            state[here] = 1
        else:
            e = elements[here]
            if e > 0 and (state[parent] == 1 or state[parent] == 2):
                kind = kinds[e]
                if kind == 0:
                    kind = 1 + _token_kind(chars + offsets[e], offsets[e + 1] - offsets[e] - 1)
                    kinds[e] = kind
                state[here] = 2 if (kind - 1) & _IDENTIFIER else 4
            elif e < 0 and state[parent] == 2:
                kind = kinds[-e]
                if kind == 0:
                    kind = 1 + _token_kind(chars + offsets[-e], offsets[-e + 1] - offsets[-e] - 1)
                    kinds[-e] = kind
                state[here] = 3 if (kind - 1) & _NAMESPACED else 4
            else:
                state[here] = 4
    # SPECS: unique path indexes of reached entries, each spec's type the one its path allows, field sets
    for i in range(m):
        s = spec_paths[i]
        if s < 0 or <uint64_t>s >= paths_n or spec_of[s] >= 0 or entry_of[s] < 0:
            return False
        spec_of[s] = i
        node, t = entry_of[s], spec_types_[i]
        if state[node] == 1:
            if t != _PSEUDO_ROOT:
                return False
        elif state[node] == 2:
            if t != _PRIM:
                return False
        elif state[node] == 3:
            if t != _ATTRIBUTE and t != _RELATIONSHIP:
                return False
        else:
            return False
        f = spec_fieldsets[i]
        if f < 0 or <uint64_t>f >= n_sets or (f and <uint32_t>fsets[f - 1] != _TERMINATOR):
            return False
    if spec_of[indexes[0]] < 0:  # no pseudo-root spec
        return False
    # the entries below another, by (parent, element), for the look-ups
    c = 0
    for i in range(1, n):
        if state[i]:
            pairs[3 * c], pairs[3 * c + 1], pairs[3 * c + 2] = parents[i], elements[i], i
            c += 1
    qsort(pairs, c, 3 * sizeof(int64_t), _compare_pairs)
    # each spec's children fields
    for i in range(m):
        node = entry_of[spec_paths[i]]
        f = spec_fieldsets[i]
        while <uint32_t>fsets[f] != _TERMINATOR:
            j = <uint32_t>fsets[f]
            f += 1
            if j >= n_fields:
                return False
            t = <uint32_t>ftok[j]
            if <uint64_t>t >= n_tokens:
                return False
            kind = kinds[t]
            if kind == 0:
                kind = 1 + _token_kind(chars + offsets[t], offsets[t + 1] - offsets[t] - 1)
                kinds[t] = kind
            kind -= 1
            if kind & _VARIANT_FIELD:
                return False
            if not kind & (_PRIM_CHILDREN | _PROPERTIES):
                continue
            if kind & _PROPERTIES and state[node] != 2:
                return False  # (the root's properties, a property's: the walk decides)
            if kind & _PRIM_CHILDREN and state[node] != 1 and state[node] != 2:
                return False
            rep = <int64_t>_le64(&reps[8 * j])
            if (<uint64_t>rep >> 60) != 0 or ((<uint64_t>rep >> 48) & 0xFF) != _TOKEN_VECTOR:
                return False
            at = rep & <int64_t>_PAYLOAD
            if at > size - 8:
                return False
            count = <int64_t>_le64(&data[at])
            if count < 0 or count > (size - at - 8) // 4:
                return False
            for kk in range(count):
                name = _le32(&data[at + 8 + 4 * kk])
                if <uint64_t>name >= n_tokens or name == 0:
                    return False
                t = kinds[name]
                if t == 0:
                    t = 1 + _token_kind(chars + offsets[name], offsets[name + 1] - offsets[name] - 1)
                    kinds[name] = t
                t -= 1
                if kind & _PRIM_CHILDREN:
                    if not t & _IDENTIFIER:
                        return False
                    e = name
                else:
                    if not t & _NAMESPACED:
                        return False
                    e = -name
                # the entries (node, e): one of them with a spec
                lo, hi = 0, c
                while lo < hi:
                    mid = (lo + hi) // 2
                    if pairs[3 * mid] < node or (pairs[3 * mid] == node and pairs[3 * mid + 1] < e):
                        lo = mid + 1
                    else:
                        hi = mid
                found = False
                while lo < c and pairs[3 * lo] == node and pairs[3 * lo + 1] == e:
                    if spec_of[indexes[pairs[3 * lo + 2]]] >= 0:
                        found = True
                        break
                    lo += 1
                if not found:
                    return False
    return True
