"""``usdhands samples OUTDIR [--formats usd,gltf,bvh] [--layout committed|full]``: write the sample assets."""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, print_json, print_table


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
    from usdhands.jobs.option_checks import parse_list
    from usdhands.jobs.sample_assets import SamplesOptions, write_samples

    options = SamplesOptions(formats=tuple(parse_list(args.formats)), layout=args.layout, seed=args.seed)
    result = write_samples(args.outdir, options, progress=Progress("samples"))
    if args.json:
        print_json(result.to_json())
        return 0
    groups: dict[str, list[int]] = {}
    for rel, size in result.files:
        parts = rel.split("/")
        key = parts[0] + "/" if len(parts) > 1 else rel
        groups.setdefault(key, []).append(size)
    rows = [(k, len(v), f"{sum(v) / 1e6:.2f}") for k, v in groups.items()]
    rows.append(("total", len(result.files), f"{result.total_bytes / 1e6:.2f}"))
    print_table(rows, ("path", "files", "MB"))
    return 0
