"""``usdhands samples OUTDIR [--formats usd,gltf,bvh] [--layout committed|full]``: write the sample assets."""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, check_seed, parse_list, print_json, print_table
from usdhands.errors import OutputPathError


def register(sub) -> None:
    p = sub.add_parser("samples", help="generate the sample assets (humanoid, gesture database, conversation, cup)",
                       description="Write the generated sample assets: a humanoid with full hands and a skinned "
                                   "mesh, a labelled database of 8 gesture types x 8 takes with ground-truth "
                                   "finger motion, a conversational clip, body-only copies as synthesis inputs, "
                                   "and a cup prop. Deterministic: the same command writes the same bytes.")
    p.add_argument("outdir", type=Path, help="folder to write into (created if missing)")
    p.add_argument("--formats", default="usd,gltf,bvh",
                   help="comma-separated formats among usd, gltf, bvh (default: all three)")
    p.add_argument("--layout", choices=("committed", "full"), default="committed",
                   help="'committed' (default): the compact set of sample_assets/, ground truth in .glb only; "
                        "'full': every clip in every format (about 40 MB)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the variations (default 0: the committed set)")
    p.add_argument("--json", action="store_true", help="list the files written, with their sizes, as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from usdhands.samples.generate import FORMATS, generate_samples

    check_seed(args.seed)
    formats = parse_list(args.formats, FORMATS)
    if not formats:
        raise OutputPathError("no format given; use --formats usd,gltf,bvh", path=args.outdir)
    out: Path = args.outdir
    if out.exists() and not out.is_dir():
        raise OutputPathError("exists and is not a folder", path=out)
    if not out.parent.resolve().is_dir():
        raise OutputPathError(f"parent folder {str(out.parent)!r} does not exist", path=out)
    try:
        out.mkdir(exist_ok=True)
    except OSError as e:
        raise OutputPathError(f"cannot create the folder: {e.strerror}", path=out) from None
    files = generate_samples(out, formats, args.layout, args.seed, progress=Progress("samples"))
    if args.json:
        sizes = [(f.relative_to(out).as_posix(), f.stat().st_size) for f in files]
        print_json({"outdir": str(out), "files": [{"path": p, "bytes": n} for p, n in sizes],
                    "total_bytes": sum(n for _, n in sizes)})
        return 0
    groups: dict[str, list[Path]] = {}
    for f in files:
        rel = f.relative_to(out)
        key = rel.parts[0] + "/" if len(rel.parts) > 1 else rel.name
        groups.setdefault(key, []).append(f)
    rows = [(k, len(v), f"{sum(p.stat().st_size for p in v) / 1e6:.2f}") for k, v in groups.items()]
    total = sum(p.stat().st_size for p in files) / 1e6
    rows.append(("total", len(files), f"{total:.2f}"))
    print_table(rows, ("path", "files", "MB"))
    return 0
