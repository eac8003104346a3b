"""``--plot DIR`` never writes a PNG over an input (issue 8).

Every command with ``--plot`` names the PNGs it may write (``FILES`` of the plot modules,
the lists in ``correct`` and ``evaluate``); an input, side file or main file, that one of
them would land on (the same path, a symlink to it, a hard link of it) is refused before
any work: one line naming the PNG and the input, exit 2, the input unchanged.
"""

from __future__ import annotations

import os
import shutil

import pytest

from hostile import listing, run_batch, sha  # noqa: E402  (tests/ is on sys.path)

pytest.importorskip("matplotlib")


def test_a_png_named_like_an_input_is_never_written(sample_assets, tmp_path):
    plots = tmp_path / "plots"
    plots.mkdir()
    good = tmp_path / "good.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", good)
    body = tmp_path / "body.glb"
    shutil.copy(sample_assets / "conversation_bodyonly.glb", body)
    cup = tmp_path / "cup_grasp.glb"
    shutil.copy(sample_assets / "interaction" / "cup_grasp.glb", cup)
    table = sample_assets / "props" / "table.obj"
    hard = tmp_path / "config.json"
    hard.write_text("{}")
    os.link(hard, plots / "kfold_errors.png")  # a hard link of the --config file
    (plots / "left_graph.png").symlink_to(hard)  # a symlink to it
    side = {}
    for name in ("reduction_curves.png", "splice_right.png", "worst_frame.png"):
        side[name] = plots / name
        side[name].write_text("{}")
    cases = [
        (["reduce", good, "--handmap", side["reduction_curves.png"], "--plot", plots],
         "reduction_curves.png", "--handmap"),
        (["synthesize", body, "-o", tmp_path / "o.glb", "--config", hard, "--plot", plots],
         "left_graph.png", "--config"),
        (["splice", body, good, "-o", tmp_path / "o.glb", "--hands-markers", side["splice_right.png"], "--plot",
          plots], "splice_right.png", "--hands-markers"),
        (["correct", cup, "--props", table, "--handmap", side["worst_frame.png"], "-o", tmp_path / "o.glb",
          "--plot", plots], "worst_frame.png", "--handmap"),
        (["evaluate", good, body, "--labels", "(.)", "--config", hard, "--plot", plots],
         "kfold_errors.png", "--config"),
    ]
    inputs = [good, body, cup, hard, *side.values()]
    before = {p: sha(p) for p in inputs}
    listed = listing(tmp_path)
    for (argv, png, label), result in zip(cases, run_batch([c[0] for c in cases])):
        assert result["code"] == 2, (argv[0], result)
        assert result["stderr"].splitlines() == [
            f"usdhands: error: {plots / png}: --plot would write {png} over the {label} file; "
            "choose another folder"], (argv[0], result["stderr"])
    assert {p: sha(p) for p in inputs} == before
    assert listing(tmp_path) == listed


def test_the_listed_names_are_the_files_written(sample_assets, tmp_path):
    """The names checked are the names written (reduce, the quickest plotting command)."""
    from usdhands.cli import main
    from usdhands.jobs.plots.reduction import FILES

    good = tmp_path / "good.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", good)
    assert main(["-q", "reduce", str(good), "--plot", str(tmp_path / "plots"), "--json"]) == 0
    written = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert written and set(written) <= set(FILES), (written, FILES)
