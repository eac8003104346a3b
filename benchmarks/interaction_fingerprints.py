"""Fingerprints of every answer the interaction code gives on its benchmark cases, to check that a
change meant to keep the answers keeps them to the bit.

For each case: a SHA-1 of the corrected rotations, of the per-frame penetration depths before and
after, the report's summary (penetration, jitter, change), the chains corrected and the exact
distance queries it took:

- the benchmark's 60 s sweep over the mug (``bench_interaction.py``), with both IKs;
- the Utah teapot (open edges: the winding number's sign) under the same sweep, 8 s, both IKs;
- the closing hand on the test cylinder;
- ``usdhands correct`` of the ``cup_grasp``, ``table_rest`` and ``scratch_head`` samples (``--self``);
- ``synthesize --props`` of the 60 s sweep (library calls, as the benchmark times them: the synthesized
  rotations, then the correction of the result) and the synthesize job on ``cup_grasp_bodyonly``.

Run it on the code before and after a change and compare (the cases need ``../shared/assets``)::

    python benchmarks/interaction_fingerprints.py > before.json   # on the code before
    python benchmarks/interaction_fingerprints.py > after.json
    diff before.json after.json && echo "the same answers, the same queries"
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from interaction_data import (  # noqa: E402
    closing_hand_clip,
    colliders_for,
    cylinder_under_palm,
    grasping_clip,
    grasping_mug_position,
)

from usdhands.algorithms.interaction.colliders import Colliders, mesh_collider  # noqa: E402
from usdhands.algorithms.interaction.correction import correct_clip  # noqa: E402
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig  # noqa: E402
from usdhands.formats.props import read_props  # noqa: E402
from usdhands.model.prop import PropMesh  # noqa: E402
from usdhands.samples.humanoid import humanoid_handmap  # noqa: E402

ASSETS = ROOT.parent / "shared" / "assets"
SAMPLES = ROOT / "sample_assets"


def sha1(*arrays) -> str:
    """The first 16 hex digits of the SHA-1 of the arrays' bytes (C order)."""
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def queries(colliders) -> int:
    """Exact distance queries the mesh colliders of ``colliders`` took."""
    return sum(getattr(c, "exact_queries", 0) for c in colliders.items)


def report_print(out, report, colliders) -> dict:
    """A correction's fingerprint."""
    return {"rotations": sha1(out.rotations), "before": sha1(report.penetration_before_mm),
            "after": sha1(report.penetration_after_mm), "summary": report.to_dict(),
            "chains": list(report.chains_corrected), "unresolved": len(report.unresolved),
            "queries": queries(colliders)}


def mug_for(clip) -> PropMesh:
    (mug,) = read_props(ASSETS / "mujoco_mug" / "mug.obj", meters_per_unit=clip.skeleton.meters_per_unit,
                        up_axis="Y", prop_meters_per_unit=0.01)
    return PropMesh("mug", np.asarray(mug.vertices) + grasping_mug_position(), mug.faces)


def teapot_for(clip) -> PropMesh:
    """The teapot (metres, open edges) under the sweeping left hand, its top 1 cm below the mug's rim."""
    (pot,) = read_props(ASSETS / "usd_teapot" / "UtahTeapot.usd", meters_per_unit=clip.skeleton.meters_per_unit,
                        up_axis="Y")
    v = np.asarray(pot.vertices)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    top = grasping_mug_position() + [0.0, 6.2, 0.0]
    return PropMesh("teapot", v - [centre[0], v[:, 1].max(), centre[2]] + top, pot.faces)


def main() -> None:
    out: dict = {}
    clip = grasping_clip(60.0)
    hm = humanoid_handmap(clip.skeleton)
    mug = mug_for(clip)
    for ik in ("opening", "ccd"):
        cols = Colliders([mesh_collider(mug, clip.times)])
        fixed, report = correct_clip(clip, hm, cols, config=InteractionConfig(ik=ik))
        out[f"bench {ik}"] = report_print(fixed, report, cols)
    short = grasping_clip(8.0)
    for ik in ("opening", "ccd"):
        cols = colliders_for(short, teapot_for(short))
        fixed, report = correct_clip(short, humanoid_handmap(short.skeleton), cols, config=InteractionConfig(ik=ik))
        out[f"teapot {ik}"] = report_print(fixed, report, cols)
    closing = closing_hand_clip(frames=30, noise_deg=1.5)
    cols = colliders_for(closing, cylinder_under_palm())
    fixed, report = correct_clip(closing, humanoid_handmap(closing.skeleton), cols)
    out["cylinder"] = report_print(fixed, report, cols)

    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.formats.io import read_asset
    from usdhands.jobs.correction import CorrectOptions, correct
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.jobs.props import synthesis_interaction
    from usdhands.jobs.synthesis import SynthesizeOptions, synthesize

    props = SAMPLES / "props"
    samples = {"cup_grasp": (("cup_on_table.obj", "table.obj"), ("cup_on_table=RightHand:48-102",), False),
               "table_rest": (("table.obj",), (), False), "scratch_head": (("table.obj",), (), True)}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (files, attach, self_collision) in samples.items():
            result = correct(SAMPLES / "interaction" / f"{name}.glb", Path(tmp) / f"{name}.glb",
                             CorrectOptions(props=tuple(props / f for f in files), attach=attach,
                                            self_collision=self_collision))
            report = result.to_json()
            report.pop("seconds")
            report.pop("output")
            report.pop("file")
            report["props"] = [Path(p).name for p in report["props"]]
            out[f"correct {name}"] = {"rotations": sha1(read_asset(Path(tmp) / f"{name}.glb").clips[0].rotations),
                                      "report": report}
        db = load_database(bundled_database_path())
        cfg = SynthesisConfig()
        options = SimpleNamespace(attach=[], self_collision=False, margin=0.0, collision_weight=1.0, file="bench")
        world = clip.world_xforms()
        factory, cols = synthesis_interaction(options, clip, hm, db, cfg, [(Path("mug.obj"), mug)],
                                              InteractionConfig(), world=world)
        result = synthesize_clip(clip, hm, db, cfg, interaction=factory)
        term_queries = queries(cols)
        fixed, report = correct_clip(result.clip, hm, cols, world=world)
        out["synthesize --props bench"] = {"synthesized": sha1(result.clip.rotations), "term queries": term_queries,
                                           **report_print(fixed, report, cols)}
        synthesize(SAMPLES / "interaction" / "cup_grasp_bodyonly.glb", Path(tmp) / "cup_synth.glb",
                   SynthesizeOptions(props=(props / "cup_on_table.obj", props / "table.obj"),
                                     attach=("cup_on_table=RightHand:48-102",)))
        out["synthesize --props cup_grasp"] = {"rotations": sha1(read_asset(Path(tmp) / "cup_synth.glb").clips[0].rotations)}
    print(json.dumps(out, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
