"""glTF 2.0 container: loading ``.gltf``/``.glb`` files, typed accessors, appending data.

The JSON document is a :class:`pygltflib.GLTF2`; buffer bytes are kept beside it in
:class:`GltfFile` (one ``bytes`` per buffer) and accessors are read into numpy arrays
here, with byte strides, sparse substitution and normalized integers applied.

The GLB chunk framing is read and written here rather than by pygltflib: a truncated
or corrupt file then gets one precise line (:class:`~usdhands.errors.AssetReadError`)
instead of a struct or Unicode error, and the binary chunk is used as it is, with no
re-packing of buffer views.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import pickle
import stat
import struct
import urllib.parse
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pygltflib

from usdhands.errors import AssetReadError
from usdhands.formats.gltf_decode import NotPlain, decode_gltf
from usdhands.input_files import check_json_depth, refuse_json_constant

__all__ = [
    "GltfFile", "load_gltf", "read_accessor", "BinaryAppender", "save_gltf", "contained_file", "read_external",
    "COMPONENT_DTYPES", "TYPE_SIZES",
]

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

#: componentType -> numpy dtype (little endian)
COMPONENT_DTYPES: dict[int, np.dtype] = {
    5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"),
    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4"),
}
#: accessor type -> number of components
TYPE_SIZES: dict[str, int] = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: bytes asked of the system per read of an external file
READ_CHUNK = 1 << 26
_DTYPE_COMPONENTS = {np.dtype("<u1"): 5121, np.dtype("<u2"): 5123, np.dtype("<u4"): 5125, np.dtype("<f4"): 5126,
                     np.dtype("<i1"): 5120, np.dtype("<i2"): 5122}


@dataclass
class GltfFile:
    """A loaded glTF document and its buffers.

    Attributes
    ----------
    path : Path
        The file read.
    gltf : pygltflib.GLTF2
        The JSON document.
    buffers : list of bytes-like
        Content of each ``gltf.buffers[i]`` (GLB chunk, data URI or external file); a GLB's
        binary chunk is a read-only ``memoryview`` of the file's bytes.
    is_glb : bool
    """

    path: Path
    gltf: pygltflib.GLTF2
    buffers: list[bytes | memoryview]
    is_glb: bool
    _cache: dict = field(default_factory=dict, repr=False)

    def error(self, message: str, location: str | None = None) -> AssetReadError:
        """An :class:`AssetReadError` about this file."""
        return AssetReadError(message, path=self.path, location=location)

    def accessor(self, index: int, *, as_float: bool = True) -> np.ndarray:
        """Accessor ``index`` as an array ``(count, components)``.

        Parameters
        ----------
        index : int
        as_float : bool
            Float64 with normalized integers mapped to [0, 1] / [-1, 1] (True), or
            the stored integer values (False, for indices and joint numbers).
        """
        key = (index, as_float)
        if key not in self._cache:
            self._cache[key] = read_accessor(self, index, as_float=as_float)
        return self._cache[key]


#: Most nodes, and most objects in all top-level arrays (accessors, animations, ...), of a glTF
#: document read. pygltflib decodes about a thousand objects a second: a 100,000-node chain
#: ran for more than 10 minutes. A character has a few hundred nodes.
MAX_NODES = 10_000
MAX_OBJECTS = 100_000


def _parse_json(path: Path, text: bytes | str) -> pygltflib.GLTF2:
    try:
        check_json_depth(text, path, what="glTF JSON")  # pygltflib recurses into what json parsed; its size
        data = json.loads(text, parse_constant=refuse_json_constant)
    except MemoryError:
        raise AssetReadError("glTF JSON too large to parse in the memory there is", path=path) from None
    except UnicodeDecodeError as e:
        raise AssetReadError(f"glTF JSON is not UTF-8 ({e.reason} at byte {e.start})", path=path) from None
    except json.JSONDecodeError as e:
        raise AssetReadError(f"invalid glTF JSON: {e.msg} at line {e.lineno} column {e.colno}", path=path) from None
    except ValueError as e:  # NaN/Infinity, an integer of more than 4300 digits
        raise AssetReadError(f"invalid glTF JSON: {str(e).split(';')[0]}", path=path) from None
    if not isinstance(data, dict):
        raise AssetReadError(f"invalid glTF JSON: top level is a {type(data).__name__}, not an object", path=path)
    version = str((data.get("asset") or {}).get("version", ""))
    if not version.startswith("2."):
        raise AssetReadError(f"not a glTF 2.0 file (asset.version {version or 'missing'!r})", path=path)
    nodes = data.get("nodes")
    if isinstance(nodes, list) and len(nodes) > MAX_NODES:
        raise AssetReadError(f"{len(nodes):,} nodes: more than {MAX_NODES:,} are refused", path=path)
    objects = sum(len(v) for v in data.values() if isinstance(v, list))
    if objects > MAX_OBJECTS:
        raise AssetReadError(f"{objects:,} objects in the top-level arrays: more than {MAX_OBJECTS:,} are refused",
                             path=path)
    global _last_decoded
    key = None
    if len(text) <= _DECODED_MAX_BYTES:
        key = bytes(text) if isinstance(text, (bytes, bytearray, memoryview)) else text.encode("utf-8", "surrogatepass")
        last = _last_decoded
        if last is not None and last[0] == key:
            return _copy(last[1])
    try:
        decoded = decode_gltf(data)  # pygltflib's objects without dataclasses_json's per-field inspection
    except NotPlain:  # a value of another shape than its field's: dataclasses_json converts or refuses it
        try:
            with warnings.catch_warnings():
                # dataclasses_json's note on a missing property pygltflib types as required (a channel
                # without target, an image without uri): the readers check what they use
                warnings.filterwarnings("ignore", "(Missing value|'NoneType' object value) of non-optional type",
                                        RuntimeWarning)
                decoded = pygltflib.GLTF2.from_dict(data, infer_missing=True)  # gltf_from_json without parsing again
        except Exception as e:  # dataclasses_json raises a variety of types on wrong shapes
            raise AssetReadError(f"invalid glTF JSON structure: {type(e).__name__}: {e}".splitlines()[0],
                                 path=path) from None
    if key is None:
        return decoded
    _last_decoded = (key, decoded)
    return _copy(decoded)


def _copy(decoded: pygltflib.GLTF2) -> pygltflib.GLTF2:
    """A copy of a document sharing no object with it: a pickle round trip, a third of
    ``copy.deepcopy``'s time (1.0 against 3.7 ms for 1,800 objects)."""
    return pickle.loads(pickle.dumps(decoded, protocol=pickle.HIGHEST_PROTOCOL))


#: pygltflib's decoding of the JSON into objects (dataclasses_json) takes about 1 ms per
#: object: 57 ms for the sample conversation, which a synthesis reads twice (the input,
#: then again as the source its output keeps); :mod:`usdhands.formats.gltf_decode` makes the
#: same objects in a thirtieth of that. The last document decoded is kept with
#: its JSON text, when that is at most 8 MB (a .glb's JSON, without the binary chunk;
#: a .gltf with its buffers in data URIs is larger and is not kept), and a load of the
#: same text gets a deep copy of it (a pickle round trip, about 1 ms): the same text always gives the same
#: document, and callers may change theirs. So a process holds at most one such
#: document (its text, and the objects, a few times the text's size) beyond what its
#: callers hold.
_last_decoded: tuple[bytes, pygltflib.GLTF2] | None = None
_DECODED_MAX_BYTES = 8 << 20


def clear_decoded_cache() -> None:
    """Forget the decoded document (benchmarks timing a first read call this)."""
    global _last_decoded
    _last_decoded = None


def _split_glb(path: Path, raw: bytes) -> tuple[bytes, memoryview | None]:
    """JSON and BIN chunks of a GLB file, with every length checked (the BIN chunk a view of ``raw``)."""
    if len(raw) < 12:
        raise AssetReadError(f"truncated .glb: {len(raw)} bytes, shorter than the 12-byte header", path=path)
    magic, version, length = struct.unpack_from("<4sII", raw, 0)
    if magic != GLB_MAGIC:
        raise AssetReadError(f"not a .glb file (magic {magic!r}, expected b'glTF')", path=path)
    if version != 2:
        raise AssetReadError(f"unsupported .glb version {version} (expected 2)", path=path)
    if length > len(raw):
        raise AssetReadError(f"truncated .glb: header says {length} bytes, file has {len(raw)}", path=path)
    offset = 12
    json_chunk = bin_chunk = None
    while offset < length:
        if offset + 8 > length:
            raise AssetReadError(f"truncated .glb: chunk header at byte {offset} cut off", path=path)
        clen, ctype = struct.unpack_from("<II", raw, offset)
        start, end = offset + 8, offset + 8 + clen
        if end > length:
            raise AssetReadError(f"truncated .glb: chunk at byte {offset} needs {clen} bytes, "
                                 f"{length - start} left", path=path)
        if ctype == CHUNK_JSON and json_chunk is None:
            json_chunk = raw[start:end]
        elif ctype == CHUNK_BIN and bin_chunk is None and json_chunk is not None:
            bin_chunk = memoryview(raw)[start:end]  # the file's bytes, not a copy of them (18 MB: 4 ms)
        offset = end
    if json_chunk is None:
        raise AssetReadError("corrupt .glb: no JSON chunk", path=path)
    return json_chunk, bin_chunk


def _buffer_bytes(path: Path, gltf: pygltflib.GLTF2, i: int, bin_chunk: bytes | None) -> bytes:
    buf = gltf.buffers[i]
    where = f"buffers[{i}]"
    if buf.uri is None:
        if i != 0 or bin_chunk is None:
            raise AssetReadError("buffer has no uri and there is no GLB binary chunk", path=path, location=where)
        data = bin_chunk
    elif isinstance(buf.uri, str) and buf.uri.startswith("data:"):
        head, _, payload = buf.uri.partition(",")
        if not head.endswith(";base64"):
            raise AssetReadError("data URI buffer is not base64", path=path, location=where)
        try:
            data = base64.b64decode(payload, validate=True)
        except ValueError as e:
            raise AssetReadError(f"bad base64 in data URI buffer ({e})", path=path, location=where) from None
    else:
        if not isinstance(buf.byteLength, int) or buf.byteLength < 0:
            raise AssetReadError(f"byteLength {buf.byteLength!r} is not a number of bytes", path=path, location=where)
        return read_external(path, buf.uri, "buffer", where, buf.byteLength)
    if buf.byteLength is None or len(data) < buf.byteLength:
        raise AssetReadError(f"buffer holds {len(data)} bytes, byteLength says {buf.byteLength}", path=path,
                             location=where)
    return data


def contained_file(path: Path, uri: str, what: str, location: str) -> Path:
    """The file a glTF's external ``uri`` names, resolved inside the glTF's folder.

    ``path`` is the glTF file; ``what`` says what the URI is for ("buffer", "image") in
    messages. The URI must be a relative path (percent-encoded or not) that stays in
    ``path``'s folder once both the folder and the URI's target are resolved through
    symlinks. Nothing is opened here, and a refusal tells nothing about the target
    (whether it exists, its size, its kind).

    Raises
    ------
    AssetReadError
        A URI with a scheme (``file:``, ``http:``), an absolute path, or one that
        leads out of the folder (``..``, a symlink to elsewhere).
    """
    try:
        scheme = urllib.parse.urlsplit(uri).scheme if isinstance(uri, str) else "?"
    except ValueError:  # "//[x": a malformed network location
        scheme = "?"
    if scheme:
        raise AssetReadError(f"{what} URI {uri!r} is not a relative file path", path=path, location=location)
    rel = urllib.parse.unquote(uri)
    if not rel or "\0" in rel or os.path.isabs(rel) or rel.startswith(("/", "\\")):
        raise AssetReadError(f"{what} URI {uri!r} points outside the glTF's folder", path=path, location=location)
    folder = path.parent.resolve()
    try:
        target = (folder / rel).resolve()
    except (OSError, RuntimeError):  # a symlink loop
        raise AssetReadError(f"{what} file {uri!r} cannot be read (symlink loop)", path=path,
                             location=location) from None
    if not target.is_relative_to(folder):
        raise AssetReadError(f"{what} URI {uri!r} points outside the glTF's folder", path=path, location=location)
    return target


def read_external(path: Path, uri: str, what: str, location: str, byte_length: int | None = None) -> bytes:
    """The bytes of the regular file ``uri`` names in ``path``'s folder (:func:`contained_file`).

    With ``byte_length`` (a buffer's), only its first ``byte_length`` bytes: a longer
    file is fine (the rest is not the buffer's) and is never read past that; a
    shorter one is refused. Never blocks on a FIFO, never reads a device.

    Raises
    ------
    AssetReadError
        As :func:`contained_file`; a file that is missing, unreadable, not a regular
        file, or shorter than ``byte_length``.
    """
    file = contained_file(path, uri, what, location)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(file, flags)
    except OSError as e:
        raise AssetReadError(f"{what} file {uri!r} cannot be read ({e.strerror or e})", path=path,
                             location=location) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise AssetReadError(f"{what} file {uri!r} is not a regular file", path=path, location=location)
        want = info.st_size if byte_length is None else byte_length
        if info.st_size < want:
            raise AssetReadError(f"{what} holds {info.st_size} bytes, byteLength says {want}", path=path,
                                 location=location)
        data = bytearray()
        while len(data) < want:  # one read(2) returns at most about 2 GiB
            chunk = os.read(fd, min(want - len(data), READ_CHUNK))
            if not chunk:
                raise AssetReadError(f"{what} file {uri!r} changed while being read", path=path,
                                     location=location)
            data += chunk
    except OSError as e:
        raise AssetReadError(f"{what} file {uri!r} cannot be read ({e.strerror or e})", path=path,
                             location=location) from None
    finally:
        os.close(fd)
    data = bytes(data)
    return data


def load_gltf(path: str | os.PathLike) -> GltfFile:
    """Load a ``.gltf`` or ``.glb`` file and all of its buffers.

    Raises
    ------
    AssetReadError
        Truncated or corrupt GLB, bad JSON, not glTF 2.0, a buffer file missing or
        shorter than its ``byteLength``.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise AssetReadError(f"cannot read file ({e.strerror or e})", path=path) from None
    is_glb = raw[:4] == GLB_MAGIC or path.suffix.lower() == ".glb"
    if is_glb:
        json_chunk, bin_chunk = _split_glb(path, raw)
    else:
        json_chunk, bin_chunk = raw, None
    gltf = _parse_json(path, json_chunk)
    buffers = [_buffer_bytes(path, gltf, i, bin_chunk) for i in range(len(gltf.buffers))]
    return GltfFile(path, gltf, buffers, is_glb)


def read_accessor(doc: GltfFile, index: int, *, as_float: bool = True) -> np.ndarray:
    """Accessor ``index`` of ``doc`` as ``(count, components)``; see :meth:`GltfFile.accessor`."""
    g = doc.gltf
    where = f"accessors[{index}]"
    if not 0 <= index < len(g.accessors):
        raise doc.error(f"accessor index {index} out of range (there are {len(g.accessors)})")
    acc = g.accessors[index]
    dtype = COMPONENT_DTYPES.get(acc.componentType)
    ncomp = TYPE_SIZES.get(acc.type)
    if dtype is None or ncomp is None or acc.count is None:
        raise doc.error(f"bad accessor (componentType {acc.componentType}, type {acc.type!r})", where)
    count = _size(doc, acc.count, "count", where)
    if acc.bufferView is not None:
        values = _read_view(doc, acc.bufferView, _size(doc, acc.byteOffset or 0, "byteOffset", where), count, dtype,
                            acc.type, where)
    else:
        values = np.zeros((count, ncomp), dtype=dtype)
    if acc.sparse is not None and acc.sparse.count:
        sp = acc.sparse
        idx_dtype = COMPONENT_DTYPES.get(sp.indices.componentType)
        if idx_dtype is None:
            raise doc.error(f"bad sparse indices componentType {sp.indices.componentType}", where)
        n = _size(doc, sp.count, "sparse.count", where)
        idx = _read_view(doc, sp.indices.bufferView, _size(doc, sp.indices.byteOffset or 0, "byteOffset", where), n,
                         idx_dtype, "SCALAR", where + ".sparse.indices")[:, 0].astype(np.int64)
        val = _read_view(doc, sp.values.bufferView, _size(doc, sp.values.byteOffset or 0, "byteOffset", where), n,
                         dtype, acc.type, where + ".sparse.values")
        if idx.size and (idx.min() < 0 or idx.max() >= count):
            raise doc.error(f"sparse index {int(idx.max())} out of range 0..{count - 1}", where)
        values = np.array(values)
        values[idx] = val
    if not as_float:
        return values
    with np.errstate(invalid="ignore"):  # a signalling NaN warned here; readers refuse NaN values themselves
        out = values.astype(np.float64)
    if acc.normalized and dtype.kind in "iu":
        info = np.iinfo(dtype)
        out = out / info.max
        if dtype.kind == "i":
            out = np.maximum(out, -1.0)
    return out


#: Largest byte offset, length or element count read from a glTF document (2**53: exact in a JSON number).
MAX_SIZE = 2 ** 53


def _size(doc: GltfFile, value, what: str, where: str) -> int:
    """A byte offset, length or count of the JSON as an int, refused in one line unless 0 <= value < 2**53.

    ``byteOffset: -1e308`` raised OverflowError from numpy; a float or a string passed through int().
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value or not 0 <= value < MAX_SIZE \
            or int(value) != value:
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        shown = f"{float(value):g}" if numeric and (isinstance(value, float) or abs(value) >= MAX_SIZE) \
            else repr(value)[:40]
        raise doc.error(f"{what} {shown} is not an integer from 0 to 2^53", where)
    return int(value)


def _read_view(doc: GltfFile, view_index: int, byte_offset: int, count: int, dtype: np.dtype, type_: str,
               where: str) -> np.ndarray:
    """``count`` elements of ``type_`` from a buffer view, honouring byteStride and column padding."""
    g = doc.gltf
    if not isinstance(view_index, int) or not 0 <= view_index < len(g.bufferViews):
        raise doc.error(f"bufferView {view_index} out of range (there are {len(g.bufferViews)})", where)
    view = g.bufferViews[view_index]
    vwhere = f"bufferViews[{view_index}]"
    if not isinstance(view.buffer, int) or not 0 <= view.buffer < len(doc.buffers):
        raise doc.error(f"buffer {view.buffer} out of range", vwhere)
    buf = doc.buffers[view.buffer]
    vstart = _size(doc, view.byteOffset or 0, "byteOffset", vwhere)
    vlen = _size(doc, view.byteLength, "byteLength", vwhere)
    if vstart + vlen > len(buf):
        raise doc.error(f"bufferView runs past the end of buffer {view.buffer} "
                        f"({vstart + vlen} > {len(buf)} bytes)", f"bufferViews[{view_index}]")
    ncomp = TYPE_SIZES[type_]
    isz = dtype.itemsize
    # matrix columns start on 4-byte boundaries (MAT2/MAT3 of 1- or 2-byte components)
    rows = {"MAT2": 2, "MAT3": 3}.get(type_)
    col_bytes = rows * isz if rows else ncomp * isz
    col_stride = (col_bytes + 3) // 4 * 4 if rows else col_bytes
    ncols = ncomp // rows if rows else 1
    elem = col_stride * ncols if rows else ncomp * isz
    stride = _size(doc, view.byteStride or 0, "byteStride", vwhere) or elem
    if stride < elem:  # overlapping elements: silently wrong values (VEC4 floats read with byteStride 4)
        raise doc.error(f"byteStride {stride} is smaller than one {type_} element ({elem} bytes)", vwhere)
    if count == 0:
        return np.zeros((0, ncomp), dtype=dtype)
    need = byte_offset + stride * (count - 1) + elem
    if need > vlen:
        raise doc.error(f"accessor needs {need} bytes of bufferView {view_index}, which has {vlen}", where)
    start = vstart + byte_offset
    if stride == elem and not (rows and col_stride != col_bytes):
        arr = np.frombuffer(buf, dtype=dtype, count=count * ncomp, offset=start)
        return arr.reshape(count, ncomp)
    raw = np.frombuffer(buf, dtype=np.uint8, count=stride * (count - 1) + elem, offset=start)
    out = np.empty((count, ncomp), dtype=dtype)
    for c in range(ncols):
        base = c * col_stride
        per = (rows if rows else ncomp)
        cols = np.lib.stride_tricks.as_strided(raw[base:], shape=(count, per * isz), strides=(stride, 1))
        out[:, c * per:(c + 1) * per] = np.ascontiguousarray(cols).view(dtype).reshape(count, per)
    return out


class BinaryAppender:
    """Appends arrays to one buffer of a document as new buffer views and accessors.

    Every buffer view starts on a 4-byte boundary. Call :meth:`finish` to store the
    bytes (``doc.buffers[i]``) and the buffer's ``byteLength``.

    Parameters
    ----------
    gltf : pygltflib.GLTF2
    buffer_index : int
        The buffer to append to (it must exist in ``gltf.buffers``).
    existing : bytes
        Its current content.
    """

    def __init__(self, gltf: pygltflib.GLTF2, buffer_index: int, existing: bytes = b""):
        self.gltf = gltf
        self.buffer_index = buffer_index
        self.parts: list[bytes] = [bytes(existing)]
        self.size = len(existing)

    def _align(self) -> None:
        pad = -self.size % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.size += pad

    def add_view(self, data: bytes | memoryview, target: int | None = None, byte_stride: int | None = None) -> int:
        """Append ``data`` (bytes, or a flat memoryview of bytes) as a new buffer view; returns its index."""
        self._align()
        view = pygltflib.BufferView(buffer=self.buffer_index, byteOffset=self.size, byteLength=len(data),
                                    target=target, byteStride=byte_stride)
        self.parts.append(data)
        self.size += len(data)
        self.gltf.bufferViews.append(view)
        return len(self.gltf.bufferViews) - 1

    def add_accessor(self, array: np.ndarray, type_: str, *, view: int | None = None, byte_offset: int = 0,
                     target: int | None = None, min_max: bool = False, normalized: bool = False) -> int:
        """Append an accessor for ``array`` ``(count, components)``.

        Parameters
        ----------
        array : (count, n) array of float32, uint8, uint16 or uint32
            The data (stored in a new view unless ``view`` is given, in which case it
            must already be in that view at ``byte_offset``).
        type_ : str
            ``"SCALAR"``, ``"VEC3"``, ``"VEC4"``, ``"MAT4"``...
        min_max : bool
            Write ``min``/``max`` (required for POSITION and animation inputs).
        """
        array = np.asarray(array)
        comp = _DTYPE_COMPONENTS[array.dtype.newbyteorder("<") if array.dtype.byteorder == ">" else array.dtype]
        count = array.shape[0]
        if view is None:
            view = self.add_view(np.ascontiguousarray(array).tobytes(), target=target)
            byte_offset = 0
        acc = pygltflib.Accessor(bufferView=view, byteOffset=byte_offset, componentType=comp,
                                 count=count, type=type_, normalized=normalized or None)
        if min_max and count:
            flat = array.reshape(count, -1)
            acc.min = [_json_number(v) for v in flat.min(axis=0)]
            acc.max = [_json_number(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def finish(self, buffers: list) -> int:
        """Store the buffer's content in ``buffers`` and its byteLength in the document; returns the length.

        The content is stored as the tuple of its parts (bytes and memoryviews, in order), which
        :func:`save_gltf` writes one after the other: a clip's 18 MB are not joined into one
        more copy first.
        """
        self._align()
        while len(buffers) <= self.buffer_index:
            buffers.append(b"")
        buffers[self.buffer_index] = tuple(p for p in self.parts if len(p))
        self.gltf.buffers[self.buffer_index].byteLength = self.size
        return self.size


def _json_number(v) -> float | int:
    return int(v) if np.issubdtype(type(v), np.integer) else float(v)


#: dataclass type -> its field names in order (what ``dataclasses.fields`` gives), for :func:`_as_plain`
_FIELD_NAMES: dict[type, tuple[str, ...]] = {}
_IMMUTABLE_LEAVES = (str, int, float, bool, type(None))


def _as_plain(obj):
    """pygltflib's ``gltf_asdict`` (dataclasses as dicts of their fields in order, ``Attributes``
    as a copy of its ``__dict__``, containers copied), without its per-value ``deepcopy`` of
    numbers and strings (immutable: the same objects) and its ``fields()`` call per object.

    A document of one 10,000-frame, 65-joint clip (~2,000 objects): ~2.3 ms instead of ~5.2.
    Anything else (tuples, subclasses, other objects) goes to pygltflib's own conversion.
    """
    kind = type(obj)
    if kind in _IMMUTABLE_LEAVES:
        return obj
    if kind is list:
        return [_as_plain(v) for v in obj]
    names = _FIELD_NAMES.get(kind)
    if names is not None:
        return {n: _as_plain(getattr(obj, n)) for n in names}
    if kind is dict:
        return {_as_plain(k): _as_plain(v) for k, v in obj.items()}
    if kind is not pygltflib.Attributes and dataclasses.is_dataclass(kind) and kind.__module__ == "pygltflib":
        _FIELD_NAMES[kind] = tuple(f.name for f in dataclasses.fields(kind))
        return _as_plain(obj)
    return pygltflib._asdict_inner(obj, dict)


def _to_json(gltf: pygltflib.GLTF2) -> str:
    """The document's JSON text, the same text as ``gltf.gltf_to_json(separators=(",", ":"), indent=None)``
    (tests/test_gltf_write_fast.py compares them), made from :func:`_as_plain`."""
    data = pygltflib.delete_empty_keys(_as_plain(gltf))
    return json.dumps(data, cls=pygltflib.JsonEncoder, skipkeys=True, ensure_ascii=True, check_circular=True,
                      allow_nan=False, indent=None, separators=(",", ":"), default=pygltflib.json_serial,
                      sort_keys=False)


def _parts(buffer) -> tuple:
    """A buffer given to :func:`save_gltf` as its parts: bytes-like alone, or the tuple :meth:`BinaryAppender.finish` stores."""
    return buffer if isinstance(buffer, tuple) else (buffer,)


def save_gltf(gltf: pygltflib.GLTF2, buffers: list, path: str | os.PathLike, *, glb: bool) -> None:
    """Write a document and its buffers.

    Parameters
    ----------
    glb : bool
        A binary ``.glb``: buffer 0 (which must have no ``uri``) becomes the BIN chunk.
        Otherwise a ``.gltf``: every buffer without ``uri`` is embedded as a data URI.
        Buffers with a ``uri`` are written as they are (their files are not copied).
    """
    path = Path(path)
    if glb:
        for i, b in enumerate(gltf.buffers):
            if b.uri is None and i != 0:
                raise ValueError(f"only buffer 0 can be the GLB binary chunk, buffer {i} has no uri")
        bin_parts = _parts(buffers[0]) if gltf.buffers and gltf.buffers[0].uri is None else None
        json_bytes = _to_json(gltf).encode("utf-8")
        json_bytes += b" " * (-len(json_bytes) % 4)
        chunks = [struct.pack("<II", len(json_bytes), CHUNK_JSON), json_bytes]
        if bin_parts is not None:
            size = sum(len(p) for p in bin_parts)
            chunks += [struct.pack("<II", size + -size % 4, CHUNK_BIN), *bin_parts, b"\0" * (-size % 4)]
        total = 12 + sum(len(c) for c in chunks)
        with open(path, "wb") as f:
            f.write(struct.pack("<4sII", GLB_MAGIC, 2, total))
            for c in chunks:
                f.write(c)
        return
    saved = [b.uri for b in gltf.buffers]
    try:
        for i, b in enumerate(gltf.buffers):
            if b.uri is None:
                data = b"".join(_parts(buffers[i]))
                b.uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
        text = _to_json(gltf)
    finally:
        for b, uri in zip(gltf.buffers, saved):
            b.uri = uri
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
