"""The block sandwich with many objects: more parameters than the image's blocks of the usual side.

Each object's colour is three parameters, so a scene of many balls has more of them than a small photo has
blocks of a sixth of its side: the sandwich then takes smaller blocks, and where even the smallest are too few
it gives no bars and says why, in result.json, the command's summary and the report.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import rtloop
from rtloop.cli.outputs import result_json
from rtloop.cli.summary import summary
from rtloop.uncertainty.sandwich import BLOCK_PX, block_side


def many_balls(n: int, width: int, height: int) -> tuple[dict, dict]:
    """A truth scene of ``n`` coloured balls on a floor, and the scene to fit (light and every albedo)."""
    rng = np.random.default_rng(3)
    side = math.ceil(math.sqrt(n))
    objects = [{"name": f"b{i}", "shape": "sphere", "radius": 0.25,
                "center": [((i % side) - (side - 1) / 2) * 0.7, 0.25, ((i // side) - (side - 1) / 2) * 0.7],
                "material": {"albedo": [float(v) for v in rng.uniform(0.2, 0.8, 3)]}} for i in range(n)]
    objects.append({"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 1, 0],
                    "material": {"albedo": [0.5, 0.45, 0.4]}})
    span = side * 0.7
    truth = {"image": {"width": width, "height": height},
             "camera": {"position": [0, 1.3 * span, -1.6 * span], "look_at": [0, 0, 0], "vfov_deg": 45},
             "light": {"position": [1.0, span, -0.5], "intensity": 3 * span * span}, "objects": objects}
    scene = json.loads(json.dumps(truth))
    for o in scene["objects"]:
        o["material"] = {"albedo": [0.5, 0.5, 0.5]}
    scene["fit"] = {"light.position": {"min": [-2 * span, 0.5, -2 * span], "max": [2 * span, 3 * span, 2 * span]},
                    **{f"objects.{o['name']}.albedo": {"min": [0, 0, 0], "max": [1, 1, 1]} for o in objects}}
    return truth, scene


def fitted(n: int, width: int, height: int):
    truth, scene = many_balls(n, width, height)
    photo = rtloop.render(truth, spp=4)
    return rtloop.fit(scene, photo, environment="off", interreflection="off", highlights="off")


def test_more_parameters_than_blocks_takes_smaller_blocks() -> None:
    """16 balls and the floor (3 + 17 x 3 = 54 parameters) in a 128 x 96 photo: its 48 blocks of 16 px are
    fewer; blocks of 8 px (192) give every colour and the light a bar, and the record says why."""
    assert block_side(128, 96) == 16 and (128 // 16) * (96 // 16) < 54
    result = fitted(16, 128, 96)
    robust = result.uncertainty["robust"]
    assert robust["block_px"] == BLOCK_PX
    assert robust["blocks"] > 54
    assert "not 16 px" in robust["smaller_blocks"]
    assert all(robust["sigma"][n] is not None and robust["sigma"][n] > 0 for n in result.x)
    assert "why_none" not in robust
    text = summary(result, Path("out"), 1.0)
    assert "error bars (+-): block sandwich" in text
    assert "+- " in text.split("light.position.x", 1)[1].splitlines()[0]


def test_too_few_blocks_says_why_in_json_summary_and_report(tmp_path: Path) -> None:
    """16 balls in a 64 x 48 photo: 48 blocks of 8 px at most for 54 parameters. No bar, and the reason in
    result.json, in one line of the summary (not a note naming bars that are not there) and in the report."""
    result = fitted(16, 64, 48)
    robust = result.uncertainty["robust"]
    assert all(v is None for v in robust["sigma"].values())
    why = robust["why_none"]
    assert "too few image blocks" in why and "54 parameters" in why and f"of {BLOCK_PX} px" in why
    record = result_json(result, {})
    assert record["fit_report"]["uncertainty"]["robust"]["why_none"] == why
    text = summary(result, tmp_path, 1.0)
    lines = [ln for ln in text.splitlines() if ln.startswith(("error bars", "no error bars"))]
    assert lines == [f"no error bars: {why}"]
    rows = [ln for ln in text.splitlines() if ln.strip().split(" ", 1)[0] in result.x]
    assert len(rows) == len(result.x) and not any("+-" in ln for ln in rows)
    rtloop.report(result, tmp_path / "report.html")
    assert "No block-sandwich error bars: too few image blocks" in (tmp_path / "report.html").read_text()


@pytest.mark.parametrize("width, height", [(128, 96)])
def test_few_parameters_keep_the_usual_blocks(width: int, height: int) -> None:
    """Two balls: the blocks stay a sixth of the short side, with no note."""
    result = fitted(2, width, height)
    robust = result.uncertainty["robust"]
    assert robust["block_px"] == block_side(width, height)
    assert "smaller_blocks" not in robust and "why_none" not in robust
