"""Readers and writers found by file extension.

Built-in handlers (USD, glTF, BVH) are listed here with their extensions and imported
only when a file of theirs is opened: reading a BVH file imports neither ``pxr`` nor
``pygltflib``, and ``import usdhands`` imports neither. Outside
packages add handlers through the entry-point group ``usdhands.formats``; each
entry point names an object (or a zero-argument factory returning one) with:

- ``name`` : str
- ``read_extensions`` / ``write_extensions`` : tuple of str, lower case with the dot
- ``read(path, *, fps=None) -> Asset``
- ``write(asset, path, **options) -> None``: a standalone file
- ``write_clip(source, clip, path, **options) -> None``: the source file with the
  clip's animation written into it, everything else kept
"""

from __future__ import annotations

import contextlib
import importlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Protocol

from usdhands.deferred_signals import DeferredSignals
from usdhands.errors import AssetReadError, OutputPathError

__all__ = [
    "FormatHandler", "BuiltinFormat", "BUILTIN_FORMATS", "handlers", "handler_for", "atomic_output", "atomic_write_bytes",
    "check_output_path", "register_handler", "same_file", "new_files_removed_on_failure",
]

ENTRY_POINT_GROUP = "usdhands.formats"



@dataclass(frozen=True)
class BuiltinFormat:
    """A built-in handler known by name and extensions before its module is imported.

    ``target`` is ``"module:attribute"`` of the handler object. The extensions must equal
    the handler's own (a test checks).
    """

    name: str
    target: str
    read_extensions: tuple[str, ...]
    write_extensions: tuple[str, ...]

    def load(self) -> "FormatHandler | None":
        """The handler, importing its module; None when the module's dependency is missing."""
        mod, attr = self.target.split(":")
        try:
            return getattr(importlib.import_module(mod), attr)
        except ImportError:
            return None


BUILTIN_FORMATS: tuple[BuiltinFormat, ...] = (
    BuiltinFormat("usd", "usdhands.formats.usd:HANDLER", (".usd", ".usda", ".usdc", ".usdz"), (".usd", ".usda", ".usdc")),
    BuiltinFormat("gltf", "usdhands.formats.gltf:HANDLER", (".gltf", ".glb"), (".gltf", ".glb")),
    BuiltinFormat("bvh", "usdhands.formats.bvh:HANDLER", (".bvh",), (".bvh",)),
)


class FormatHandler(Protocol):
    name: str
    read_extensions: tuple[str, ...]
    write_extensions: tuple[str, ...]

    def read(self, path: Path, *, fps: float | None = None) -> Any: ...

    def write(self, asset: Any, path: Path, **options: Any) -> None: ...

    def write_clip(self, source: Path, clip: Any, path: Path, **options: Any) -> None: ...


_outside: list[FormatHandler] | None = None  # entry points, then registered handlers
_builtin: dict[str, FormatHandler | None] = {}  # imported built-ins by name
_extra: list[FormatHandler] = []


def register_handler(handler: FormatHandler) -> None:
    """Add a handler at run time (takes precedence over built-ins for its extensions)."""
    global _outside
    _extra.append(handler)
    _outside = None


def _load_entry_points() -> list[FormatHandler]:
    from importlib.metadata import entry_points

    out = []
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        obj = ep.load()
        out.append(obj() if callable(obj) and not hasattr(obj, "read") else obj)
    return out


def _outside_handlers() -> list[FormatHandler]:
    """Handlers from entry points, then registered ones (later ones take precedence)."""
    global _outside
    if _outside is None:
        _outside = _load_entry_points() + list(_extra)
    return _outside


def _builtin_handler(fmt: BuiltinFormat) -> FormatHandler | None:
    if fmt.name not in _builtin:
        _builtin[fmt.name] = fmt.load()
    return _builtin[fmt.name]


def _builtins_in_use() -> list[BuiltinFormat]:
    """Built-ins not replaced by an outside handler of the same name."""
    taken = {h.name for h in _outside_handlers()}
    return [f for f in BUILTIN_FORMATS if f.name not in taken]


def handlers() -> dict[str, FormatHandler]:
    """All handlers by name: built-ins (each imported), then entry points, then registered ones."""
    found: dict[str, FormatHandler] = {}
    for fmt in BUILTIN_FORMATS:
        h = _builtin_handler(fmt)
        if h is not None:
            found[fmt.name] = h
    for h in _outside_handlers():
        found[h.name] = h
    return found


def _extension(path: Path) -> str:
    return path.suffix.lower()


def _extensions(h, mode: str) -> tuple[str, ...]:
    return h.read_extensions if mode == "read" else h.write_extensions


def handler_for(path: str | os.PathLike, mode: str = "read") -> FormatHandler:
    """The handler for ``path``'s extension; of the built-ins only that one is imported.

    Parameters
    ----------
    mode : {"read", "write"}

    Raises
    ------
    AssetReadError, OutputPathError
        For an extension no handler takes, listing the ones that are known.
    """
    path = Path(path)
    ext = _extension(path)
    for h in reversed(_outside_handlers()):
        if ext in _extensions(h, mode):
            return h
    for fmt in _builtins_in_use():
        if ext in _extensions(fmt, mode):
            h = _builtin_handler(fmt)
            if h is not None:
                return h
    known = sorted({e for h in _outside_handlers() for e in _extensions(h, mode)}
                   | {e for f in _builtins_in_use() if _builtin_handler(f) is not None for e in _extensions(f, mode)})
    msg = f"unknown file extension {ext or '(none)'!r}; {'readable' if mode == 'read' else 'writable'}: {', '.join(known)}"
    raise (AssetReadError if mode == "read" else OutputPathError)(msg, path=path)


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file: the same path in any spelling (``./x``,
    ``../dir/x``), through symlinks, or a hard link of it."""
    a, b = Path(a), Path(b)
    try:
        if a.resolve() == b.resolve():
            return True
    except (OSError, RuntimeError):  # a symlink loop: compare as spelled
        if os.path.abspath(a) == os.path.abspath(b):
            return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_output_path(out: str | os.PathLike, *inputs: str | os.PathLike) -> Path:
    """Refuse an output path that is one of the inputs (:func:`same_file`) or whose folder does not exist."""
    out = Path(out)
    for i in inputs:
        if i is not None and same_file(out, i):
            raise OutputPathError("output path equals the input; choose another file", path=out)
    if not out.parent.resolve().is_dir():
        raise OutputPathError(f"output folder {str(out.parent)!r} does not exist", path=out)
    if out.is_dir():
        raise OutputPathError("is a folder; give the output a file name", path=out)
    return out


def _current_umask() -> int:
    """The process umask, read without changing it where the system allows (Linux)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    mask = os.umask(0o022)  # elsewhere: the brief set-and-restore
    os.umask(mask)
    return mask


@contextlib.contextmanager
def _renamed_on_success(path: Path, make_temporary) -> Iterator[tuple[str, int | None]]:
    """The skeleton :func:`atomic_output` and :func:`atomic_write_bytes` share: yield ``(name, fd)`` of a
    temporary file beside ``path`` made by ``make_temporary(path)`` (``fd`` open, or None), rename it
    onto ``path`` when the block ends, remove it on any exception (``path`` left as it was).

    SIGTERM/SIGINT are deferred until the temporary file's name is known to the cleanup: a signal
    right after mkstemp left .out.XXXX files behind. ``make_temporary`` raises OutputPathError.
    """
    if path.is_dir():
        raise OutputPathError("is a folder; give the output a file name", path=path)
    deferred = DeferredSignals()
    tmp = None
    try:
        tmp, fd = make_temporary(path)
        try:
            deferred.replay()  # a signal that came meanwhile raises here, inside the cleanup
        except BaseException:
            if fd is not None:
                os.close(fd)
            raise
        yield tmp, fd
        try:
            os.replace(tmp, path)
        except OSError as e:
            raise OutputPathError(f"cannot replace the output: {e.strerror}", path=path) from None
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise
    finally:
        deferred.restore()


def _mkstemp_temporary(path: Path) -> tuple[str, None]:
    """A temporary file beside ``path`` by ``tempfile.mkstemp`` (mode 0600), closed."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    except OSError as e:  # read-only or missing folder
        raise OutputPathError(f"cannot write into folder {str(path.parent)!r}: {e.strerror}", path=path) from None
    os.close(fd)
    return tmp, None


def _exclusive_temporary(path: Path) -> tuple[str, int]:
    """A temporary file beside ``path`` made with ``O_EXCL`` and mode ``0o666`` less the umask, and its
    open descriptor."""
    for _ in range(tempfile.TMP_MAX):
        candidate = os.path.join(path.parent, f".{path.stem}.{os.urandom(6).hex()}{path.suffix}")
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:
            continue
        except OSError as e:  # read-only or missing folder
            raise OutputPathError(f"cannot write into folder {str(path.parent)!r}: {e.strerror}",
                                  path=path) from None
        return candidate, fd
    raise OutputPathError(f"cannot write into folder {str(path.parent)!r}: no free temporary name", path=path)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On any exception the temporary file is removed and ``path`` is left as it was.
    """
    with _renamed_on_success(Path(path), _mkstemp_temporary) as (tmp, _):
        tmp_path = Path(tmp)
        yield tmp_path
        # mkstemp creates the file 0600; give the output the mode a plain open() would
        with contextlib.suppress(OSError):
            os.chmod(tmp_path, 0o666 & ~_current_umask())


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` as :func:`atomic_output` does (a temporary file beside it renamed onto
    it; on any exception the temporary file is removed and ``path`` is left as it was), in one open.

    The temporary file is made with ``O_EXCL`` and mode ``0o666`` less the umask (what a plain
    ``open()`` gives, the mode :func:`atomic_output` sets after ``mkstemp``'s ``0o600``), written
    through the descriptor that made it and renamed: no second open, no ``chmod``, no reading of the
    umask (a USD output's texture: 0.28 -> 0.21 ms of CPU for CesiumMan's 210 KB image).
    """
    with _renamed_on_success(Path(path), _exclusive_temporary) as (_, fd):
        with open(fd, "wb") as f:
            f.write(data)


@contextlib.contextmanager
def new_files_removed_on_failure(folder: str | os.PathLike) -> Iterator[None]:
    """On any exception in the ``with`` block, remove the files it made in ``folder`` (and the folder
    when the block made it): the files an output writes beside itself (a USD output's textures) go
    with the output when it fails. Files that were there before are left."""
    folder = Path(folder)
    existed = folder.is_dir()
    before = set(os.listdir(folder)) if existed else set()
    try:
        yield
    except BaseException:
        with contextlib.suppress(OSError):
            for name in set(os.listdir(folder)) - before:
                with contextlib.suppress(FileNotFoundError):
                    (folder / name).unlink()
            if not existed:
                folder.rmdir()
        raise
