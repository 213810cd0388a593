"""``benchmarks/people_per_category.py``: people per category before and after the files added on
2026-12-04, on a small synthetic folder laid out like the shared one, and on the shared one."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from tests.motion.poselib_files import write_standing_clip

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "motions"

BVH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tEnd Site
\t{
\t\tOFFSET 0 50 0
\t}
}
MOTION
Frames: 2
Frame Time: 0.01
0 90 0 0 0 0
0 90 0 0 0 0
"""
NOTES = """# CMU
| file | category |
|---|---|
| bvh/02_01.bvh | walking_variety |

## Added 2026-12-04: two clips
| file here | repo @ commit : path | git blob |
|---|---|---|
| bvh/02_05.bvh | repo : `02/02_05.bvh` | `abc` |
| asf_amc/131.asf | repo : `131.asf` | `def` |
| bvh/06_06.bvh | repo : `06/06_06.bvh` | `123` |

## Later notes
| bvh/07_04.bvh | not an addition |
"""


def _script():
    path = REPO / "benchmarks" / "people_per_category.py"
    spec = importlib.util.spec_from_file_location("benchmarks_people_per_category", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _folder(root: Path) -> Path:
    cmu = root / "cmu"
    (cmu / "bvh").mkdir(parents=True)
    for name in ("02_01", "02_05", "06_06", "07_04"):
        (cmu / "bvh" / f"{name}.bvh").write_text(BVH)
    (cmu / "clips.csv").write_text("file,category\nbvh/02_01.bvh,walking_variety\n"
                                   "bvh/02_05.bvh,punch\nbvh/06_06.bvh,walk-back\n"
                                   "bvh/07_04.bvh,walking_variety\n")  # fmt: skip
    (cmu / "SOURCE_AND_LICENSE.md").write_text(NOTES)
    dm = root / "deepmimic"
    dm.mkdir()
    (dm / "sie_humanoid3d_punch_a.txt").write_text('{"Frames": []}')
    (dm / "clips.csv").write_text("file,category,person\nsie_humanoid3d_punch_a.txt,punch,sie\n")
    ase = root / "ase_reallusion"
    write_standing_clip(ase / "RL_Back.npy")
    (ase / "clips.csv").write_text("file,category,person\nRL_Back.npy,walk-back,reallusion\n")
    return root


def test_before_leaves_out_the_additions_and_counts_performers(tmp_path: Path) -> None:
    mod = _script()
    root = _folder(tmp_path / "motions")
    added = mod.added_on_2026_12_04(root)
    assert {p.name for p in added} == {"02_05.bvh", "06_06.bvh", "sie_humanoid3d_punch_a.txt",
                                       "RL_Back.npy"}  # fmt: skip
    res = mod.compare(root)
    assert res["added_clips"] == 4
    assert res["before"] == {"walk": ["cmu/02", "cmu/07"]}
    assert res["after"] == {"punch": ["cmu/02", "deepmimic/sie"], "walk": ["cmu/02", "cmu/07"],
                            "walk-back": ["ase_reallusion/reallusion", "cmu/06"]}  # fmt: skip
    assert res["named_after"] == res["after"]  # every group here is a named performer
    table = mod.format_table(res)
    assert "| walk-back | 0 | 2 | 0 | 2 | 0 | 2 | ase_reallusion/reallusion, cmu/06 |" in table
    assert "| **all** | 2 | 5 | 2 | 5 | 2 | 6 | |" in table
    js = tmp_path / "p.json"
    assert mod.main([str(root), "--json", str(js)]) == 0
    assert json.loads(js.read_text())["before"] == res["before"]
    (root / "cmu" / "SOURCE_AND_LICENSE.md").write_text(NOTES.replace("2026-12-04", "later"))
    with pytest.raises(SystemExit, match="Added 2026-12-04"):
        mod.compare(root)


def test_the_shared_folder_gains_people_and_loses_none() -> None:
    if not DATA.is_dir():
        pytest.skip("shared motion data not found")
    mod = _script()
    res = mod.compare(DATA)
    assert res["added_clips"] == len(mod.added_on_2026_12_04(DATA)) > 0
    for cat, people in res["before"].items():
        assert set(people) <= set(res["after"][cat]), cat
    assert "unknown" not in res["after"]
    assert "ase_reallusion/reallusion" in res["after"]["walk-back"]
    assert "deepmimic/sie" in res["after"]["punch"]
