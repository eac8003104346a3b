"""What the fuzzers run: seeds made from the samples, a byte mutator, and the check of one input.

Kept apart from run.py so the short CI run (tests/test_fuzz_readers.py) and the long
runs use the same seeds, mutations and verdicts.
"""

from __future__ import annotations

import hashlib
import json
import re
import signal
import tempfile
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_assets" / "gestures" / "ok_00.glb"

#: reader -> file extension fed to it: the asset readers, then the side files (hand map, synthesis and
#: interaction configurations, reduction model, finger database manifest, marker and label CSVs)
READERS = {"bvh": ".bvh", "gltf": ".gltf", "glb": ".glb", "usda": ".usda", "usdc": ".usdc", "usdz": ".usdz",
           "handmap": ".json",
           "config": ".json", "interaction": ".json", "model": ".json", "manifest": ".json", "markers": ".csv",
           "labels": ".csv"}
#: frames of the clip a markers CSV is read for (its seed has as many rows)
MARKER_FRAMES = 4
#: Most CPU seconds one read may take before it counts as a hang (CPU, not wall-clock: the
#: machine may be busy).
READ_SECONDS = 20


@lru_cache(maxsize=None)
def _seed_files() -> dict[str, list[bytes]]:
    """Seed bytes per reader: the sample gesture take, 4 frames of it, in every format."""
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands

    asset = read_asset(SAMPLE)
    clip = asset.clips[0]
    short = clip.__class__(clip.skeleton, clip.fps, clip.rotations[:4], clip.translations[:4], clip.scales[:4],
                           name=clip.name)
    small = Asset(str(SAMPLE), asset.skeletons, (short,), asset.meshes)
    rest = Asset(str(SAMPLE), asset.skeletons, (), ())
    folder = Path(tempfile.mkdtemp(prefix="usdhands_fuzz_seeds_"))
    out: dict[str, list[bytes]] = {}
    side = _side_file_seeds(folder)
    for reader, ext in READERS.items():
        if reader == "handmap":
            out[reader] = [json.dumps({"skeleton": asset.skeletons[0].name,
                                       **detect_hands(asset.skeletons[0]).to_dict()}, indent=2).encode()]
            continue
        if reader in side:
            out[reader] = side[reader]
            continue
        if reader == "usdz":
            out[reader] = _usdz_seeds(folder, small)
            continue
        out[reader] = []
        for k, a in enumerate((small, rest)):
            path = folder / f"seed{k}{ext}"
            write_asset(a, path)
            out[reader].append(path.read_bytes())
    return out


def _usdz_seeds(folder: Path, asset) -> list[bytes]:
    """Two packages of ``asset`` as usdhands writes it: a ``.usdc`` as the root layer, and a ``.usda``
    root that sublayers a ``.usdc`` member (the crate check slices each member out of the package)."""
    from pxr import Sdf

    from usdhands.formats.io import write_asset

    crate = folder / "member.usdc"
    write_asset(asset, crate)
    text = folder / "root.usda"
    text.write_text('#usda 1.0\n(\n    subLayers = [@./member.usdc@]\n)\n')
    out = []
    for k, members in enumerate(((crate,), (text, crate))):
        package = folder / f"seed{k}.usdz"
        writer = Sdf.ZipFileWriter.CreateNew(str(package))
        for member in members:
            writer.AddFile(str(member), member.name)
        writer.Save()
        out.append(package.read_bytes())
    return out


def _side_file_seeds(folder: Path) -> dict[str, list[bytes]]:
    """Seeds of the side-file readers: each file as usdhands writes it or the docs show it."""
    from usdhands.algorithms.interaction.finger_geometry import DEFAULT_LIMITS_DEG, DEFAULT_RADII_MM
    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.jobs.reduction import reduce
    from usdhands.jobs.splicing import MARKER_NAMES

    model = folder / "model.json"
    reduce(SAMPLE, None, model_output=model)
    columns = [f"{side}.{m}.{a}" for side in ("left", "right") for m in MARKER_NAMES for a in "xyz"]
    rows = [",".join(["frame", *columns])] + [",".join([str(f), *(f"{0.5 * k + f:.3f}" for k in range(len(columns)))])
                                              for f in range(MARKER_FRAMES)]
    interaction = {"radii_mm": {k: list(v) for k, v in DEFAULT_RADII_MM.items()}, "limits_deg": DEFAULT_LIMITS_DEG,
                   "tip_fraction": 0.8, "tolerance_mm": 0.5, "smoothing_s": 0.15, "ik": "ccd"}
    return {
        "config": [json.dumps(SynthesisConfig().to_dict(), indent=2).encode()],
        "interaction": [json.dumps(interaction, indent=2).encode()],
        "model": [model.read_bytes()],
        "manifest": [(bundled_database_path() / "manifest.json").read_bytes()],
        "markers": [("\n".join(rows) + "\n").encode()],
        "labels": [b"# file,label\nok_00.glb,ok\nbeat_01.glb, beat\n\"takes/x,y.glb\",\"quoted, label\"\n"],
    }


def seeds(reader: str) -> list[bytes]:
    return _seed_files()[reader]


_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
_INTERESTING_NUMBERS = [b"0", b"-1", b"1e308", b"-1e308", b"nan", b"inf", b"99999999999", b"4294967295",
                        b"2147483648", b"1e-320", b"0.5", b"100000"]
_INTERESTING_BYTES = [0x00, 0xFF, 0x7F, 0x80, 0x01, 0x20, ord("{"), ord("}"), ord("["), ord('"'), ord("\n")]


def mutate(data: bytes, rng) -> bytes:
    """``data`` with 1 to 4 random edits: byte flips, interesting bytes and numbers, cuts, copies, truncation."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        n = len(out)
        op = rng.randrange(8)
        if n == 0:
            out += bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
            continue
        i = rng.randrange(n)
        if op == 0:
            out[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            out[i] = rng.choice(_INTERESTING_BYTES)
        elif op == 2:  # a number token replaced by an extreme one (text formats, JSON)
            numbers = list(_NUMBER.finditer(bytes(out)))
            if numbers:
                m = rng.choice(numbers)
                out[m.start():m.end()] = rng.choice(_INTERESTING_NUMBERS)
        elif op == 3:
            del out[i:i + rng.randint(1, 64)]
        elif op == 4:
            j = rng.randrange(n)
            out[j:j] = out[i:i + rng.randint(1, 64)]
        elif op == 5:
            out[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 6:
            del out[i:]
        else:  # a 4-byte little-endian field set to an extreme value (binary formats)
            out[i:i + 4] = rng.choice([b"\xff\xff\xff\xff", b"\x00\x00\x00\x80", b"\xff\xff\xff\x7f", b"\0\0\0\0"])
    return bytes(out)


class _TooSlow(Exception):
    pass


def _alarm(signum, frame):
    raise _TooSlow()


class Target:
    """Feeds bytes to one reader; :meth:`check` returns None when the promise holds, else what broke."""

    def __init__(self, reader: str, *, timer: bool = True):
        if reader not in READERS:
            raise ValueError(f"unknown reader {reader!r}; expected one of {sorted(READERS)}")
        self.reader = reader
        self.ext = READERS[reader]
        self.folder = Path(tempfile.mkdtemp(prefix=f"usdhands_fuzz_{reader}_"))
        self.count = 0
        self._skeleton = None
        self.timer = timer  # off under libFuzzer, which has its own -timeout

    def _read(self, path: Path) -> None:
        side = _SIDE_READERS.get(self.reader)
        if side is not None:
            side(self, path)
            return
        if self.reader == "handmap":
            from usdhands.model.hand_detection import load_handmap

            if self._skeleton is None:
                from usdhands.formats.io import read_asset

                self._skeleton = read_asset(SAMPLE).skeletons[0]
            load_handmap(path, self._skeleton)
        else:
            from usdhands.formats.io import read_asset

            read_asset(path)

    def check(self, data: bytes) -> str | None:
        """Read ``data`` as a file of this reader's format; None or a description of the broken promise."""
        import warnings

        from usdhands.errors import UsdHandsError

        self.count += 1
        path = self.folder / f"in{self.count}{self.ext}"  # a new name each time: USD caches layers by path
        path.write_bytes(data)
        if self.timer:
            previous = signal.signal(signal.SIGPROF, _alarm)
            signal.setitimer(signal.ITIMER_PROF, READ_SECONDS)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RuntimeWarning)
                self._read(path)
            flagged = [w for w in caught if issubclass(w.category, RuntimeWarning)]
            if flagged:  # a read that succeeded past a numpy warning: a value nobody checked
                return f"RuntimeWarning: {flagged[0].message}"
            return None
        except UsdHandsError as e:
            if "\n" in str(e):
                return f"error message of more than one line: {str(e)[:200]!r}"
            return None
        except _TooSlow:
            return f"read took more than {READ_SECONDS} CPU seconds"
        except RecursionError:
            return "RecursionError"
        except Exception as e:  # noqa: BLE001  (any other exception breaks the promise)
            return f"{type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''}"
        finally:
            if self.timer:
                signal.setitimer(signal.ITIMER_PROF, 0)
                signal.signal(signal.SIGPROF, previous)
            path.unlink(missing_ok=True)

    def save(self, data: bytes, problem: str, crashes: Path) -> dict:
        """Write a finding's bytes to ``crashes``; returns its record."""
        crashes.mkdir(parents=True, exist_ok=True)
        name = f"{self.reader}-{hashlib.sha256(data).hexdigest()[:16]}{self.ext}"
        (crashes / name).write_bytes(data)
        return {"file": str(crashes / name), "problem": problem}


def _read_manifest(target: Target, path: Path) -> None:
    """The bytes as the manifest of a copy of the bundled database (its arrays as they are)."""
    import shutil

    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.jobs.inputs import bundled_database_path

    db = target.folder / "db"
    if not db.is_dir():
        shutil.copytree(bundled_database_path(), db)
    shutil.copyfile(path, db / "manifest.json")
    load_database(db)


def _read_labels(target: Target, path: Path) -> None:
    from usdhands.errors import UsdHandsError
    from usdhands.jobs.inputs import labeller

    label = labeller(None, path)
    for name in ("ok_00.glb", "takes/x,y.glb", "beat_01"):
        try:
            label(Path(name))
        except UsdHandsError:
            pass  # no label for that file: a one-line error of its own


def _side_reader(load):
    def read(target: Target, path: Path) -> None:
        load(path)
    return read


def _load_model(path):
    from usdhands.algorithms.reduction.model import ReductionModel

    return ReductionModel.load(path)


def _load_config(path):
    from usdhands.algorithms.synthesis.config import load_synthesis_config

    return load_synthesis_config(path)


def _load_interaction(path):
    from usdhands.algorithms.interaction.finger_geometry import load_interaction_config

    return load_interaction_config(path)


def _load_markers(path):
    from usdhands.jobs.splicing import read_markers_csv

    return read_markers_csv(path, MARKER_FRAMES)


#: side-file reader -> ``read(target, path)``
_SIDE_READERS = {"config": _side_reader(_load_config), "interaction": _side_reader(_load_interaction),
                 "model": _side_reader(_load_model), "manifest": _read_manifest,
                 "markers": _side_reader(_load_markers), "labels": _read_labels}
