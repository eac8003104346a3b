# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The two byte loops of :mod:`usdhands.formats.usdc_crate`'s check, compiled ahead of time.

:func:`lz4_block_decompress` and :func:`decode_ints` take the same arguments and give the
same results as the Python functions of that module (the same bytes, the same int64
integers, the same ``ValueError`` messages, raised at the same point of the input), which
stay the reference and run where this module was not built. Tests hold each to its twin on
valid, truncated and random inputs. A crate check of CesiumMan.usdz spent about 0.11 ms of
its 0.27 in them (8 LZ4 blocks, 7 runs of integers).
"""

from cpython.bytes cimport PyBytes_FromStringAndSize
from libc.stdint cimport int64_t, uint64_t, int8_t, int16_t, int32_t
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
