"""Shared by ``db``, ``synthesize`` and ``evaluate``: inputs, labels, the bundled database."""

from __future__ import annotations

import csv
import io
import re
from importlib import resources
from pathlib import Path

from usdhands.errors import ConfigError, UsdHandsError
from usdhands.input_files import read_text
from usdhands.optional import require_matplotlib

EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz", ".gltf", ".glb", ".bvh")
BUNDLED_NAME = "gesture_db"


def bundled_database_path() -> Path:
    """Folder of the database shipped in the package (built from the generated gesture set)."""
    return Path(str(resources.files("usdhands").joinpath("data", BUNDLED_NAME)))


def check_plot_folder(folder: Path | None, pngs: tuple[str, ...] = (), inputs: dict | None = None) -> None:
    """Refuse a ``--plot DIR`` that cannot be a folder, before any work.

    ``pngs`` are the file names the command may write into it and ``inputs`` the mapping
    given to :func:`~usdhands.jobs.outputs.check_paths` (label -> path or paths): a PNG
    that would land on an input (same path, symlink, hard link) is refused, naming it.
    """
    if folder is None:
        return
    require_matplotlib(folder)
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise UsdHandsError("--plot needs a folder; this is a file", path=folder)
    parent = folder.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise UsdHandsError(f"--plot folder cannot be made: {str(parent)!r} is a file", path=folder)
    from usdhands.errors import OutputPathError
    from usdhands.formats.registry import same_file
    from usdhands.jobs.outputs import MAIN_INPUT, each_path

    for label, value in (inputs or {}).items():
        for p in each_path(value):
            for name in pngs:
                if same_file(folder / name, p):
                    what = "the input" if label == MAIN_INPUT else f"the {label} file"
                    raise OutputPathError(f"--plot would write {name} over {what}; choose another folder",
                                          path=folder / name)


def expand_inputs(inputs: list[Path]) -> list[Path]:
    """Files as given; folders replaced by their animation files (sorted)."""
    out = []
    for p in inputs:
        p = Path(p)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix.lower() in EXTENSIONS)
            if not found:
                raise UsdHandsError(f"no animation files ({', '.join(EXTENSIONS)}) in folder", path=p)
            out.extend(found)
        else:
            out.append(p)
    if not out:
        raise UsdHandsError("no input files given")
    return out


def labeller(regex: str | None, labels_file: Path | None):
    """A function ``label(path) -> str | None`` from ``--labels REGEX`` or ``--labels-file CSV``.

    The regex's first group (or the whole match when it has no group), searched in the
    file name, is the label. The CSV has rows ``file,label`` (file name or path).
    """
    if regex and labels_file:
        raise UsdHandsError("give --labels or --labels-file, not both")
    if regex:
        try:
            rx = re.compile(regex)
        except re.error as e:
            raise UsdHandsError(f"bad --labels regular expression {regex!r}: {e}") from None

        def by_regex(path: Path) -> str:
            m = rx.search(path.name)
            if not m:
                raise UsdHandsError(f"--labels '{regex}' does not match the file name '{path.name}'", path=path)
            return m.group(1) if rx.groups else m.group(0)

        return by_regex
    if labels_file:
        table = {}
        text = read_text(labels_file, what="labels file", error=ConfigError)  # not UTF-8: one line
        for n, row in enumerate(csv.reader(io.StringIO(text, newline="")), 1):
            if not row or row[0].startswith("#"):
                continue
            if len(row) < 2:
                raise ConfigError(f"expected 'file,label', got {row!r}", path=labels_file, location=f"line {n}")
            table[row[0].strip()] = row[1].strip()

        def by_table(path: Path) -> str:
            for key in (str(path), path.name, path.stem):
                if key in table:
                    return table[key]
            raise UsdHandsError(f"no label for {path.name!r} in {labels_file}", path=path)

        return by_table
    return lambda path: None


def read_labelled(paths: list[Path], label_of, fps, handmap_path, animation=None, progress=None,
                  fingerless: bool = False):
    """Read clips with their hand maps and labels: list of ``(path, label, clip, handmap)``.

    With ``fingerless``, a skeleton without finger joints gets a hand map of its arms
    (wrists found by name, see :func:`usdhands.algorithms.synthesis.hand_graft.find_wrists`).
    """
    from usdhands.formats.io import read_clip

    out = []
    for i, p in enumerate(paths):
        label = label_of(p)
        clip = read_clip(p, animation=animation, fps=fps)
        handmap = arms_only(clip, p) if fingerless and handmap_path is None else None
        if handmap is not None:
            check_frames(handmap, clip.skeleton, p)
        handmap = handmap or handmap_for(clip, p, handmap_path)
        out.append((p, label, clip, handmap))
        if progress:
            progress(i + 1, len(paths), p.name)
    return out


def handmap_for(clip, path, handmap_path):
    """The clip's hand map: the JSON override, the map the file records, or detection.

    Detection errors name the file they came from.
    """
    from usdhands.formats.hands import hands_for

    try:
        handmap = hands_for(path, clip.skeleton, handmap_path)[0]
    except UsdHandsError as e:
        if e.path is None:
            raise type(e)(e.message, path=path, location=e.location) from None
        raise
    check_frames(handmap, clip.skeleton, path)
    return handmap


def check_frames(handmap, skeleton, path) -> None:
    """Refuse, naming the file, hands with mirrored joint frames (finger transfer cannot use them)."""
    from usdhands.algorithms.synthesis.finger_transfer import check_hand_frames

    for hand in handmap.sides:
        if hand.finger_joints:
            check_hand_frames(skeleton, hand, path=path)


def arms_only(clip, path):
    """The hand map of a skeleton, or of its arms when it has no finger joints (None if neither)."""
    from usdhands.algorithms.synthesis.hand_graft import find_wrists
    from usdhands.errors import NoHandsError
    from usdhands.model.hand_detection import detect_hands
    from usdhands.model.handmap import HandMap, HandSide

    sk = clip.skeleton
    try:
        return detect_hands(sk)
    except NoHandsError:
        sides = {}
        for side, w in find_wrists(sk).items():
            chain = sk.chain_to_root(w)
            name = lambda i: sk.joint_names[chain[i]] if i < len(chain) else None  # noqa: E731
            sides[side] = HandSide(side, name(0), name(1), name(2), sk.joint_names[chain[-1]])
        return HandMap(**sides) if sides else None


def load_config(path):
    from usdhands.algorithms.synthesis.config import SynthesisConfig, load_synthesis_config

    return SynthesisConfig() if path is None else load_synthesis_config(path)


def sample_database_items(seed: int = 0):
    """The generated gesture database as ``DatabaseClip`` items (source ``samples:gestures/<name>``)."""
    from usdhands.algorithms.synthesis.database import DatabaseClip
    from usdhands.model.hand_detection import detect_hands
    from usdhands.samples.gestures import gesture_database

    items = []
    handmap = None
    for label, clip in gesture_database(seed=seed):
        handmap = handmap or detect_hands(clip.skeleton)
        items.append(DatabaseClip(clip, handmap, label, f"samples:gestures/{clip.name}"))
    return items


_DATABASES: dict = {}


def cached_database(path: Path | None = None):
    """The finger database at ``path`` (default: the bundled one), loaded once per process.

    Kept while the folder's index file is unchanged (same modification time and size), so
    a batch worker or a pipeline that runs many jobs pays the load once.
    """
    from usdhands.algorithms.synthesis.database import load_database

    bundled = path is None
    folder = Path(path) if path is not None else bundled_database_path()
    try:
        stamp = tuple((f.name, f.stat().st_mtime_ns, f.stat().st_size) for f in sorted(folder.iterdir()))
    except OSError:
        return load_database(folder)  # missing or unreadable: load_database says what is wrong
    key = str(folder.resolve())
    hit = _DATABASES.get(key)
    if hit is not None and hit[0] == stamp:
        return hit[1]
    # the bundled database's manifest is validated by the tests, not on every run
    db = load_database(folder, check_schema=False) if bundled else load_database(folder)
    _DATABASES[key] = (stamp, db)
    return db


def still_hands(clip, handmap, tolerance_deg: float = 0.5) -> list[str]:
    """Sides whose finger joints turn by less than ``tolerance_deg`` over the whole clip."""
    from usdhands.model.rotations import quat_angle_deg

    still = []
    for hand in handmap.sides:
        joints = [clip.skeleton.index(j) for j in hand.finger_joints]
        if joints and quat_angle_deg(clip.rotations[:, joints], clip.rotations[:1, joints]).max() < tolerance_deg:
            still.append(hand.side)
    return still


def stage_progress(progress, stage: str):
    """``progress(done, total, what)`` with ``what`` prefixed by ``stage`` (reading, building, ...)."""
    return lambda done, total, what="": progress(done, total, f"{stage}: {what}" if what else stage)
