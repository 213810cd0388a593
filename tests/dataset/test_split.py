"""``grip.dataset.build.dataset_split``: by person (stratified per source) and by clip."""

from __future__ import annotations

import json

import pytest

from grip.assets import REPO_ROOT
from grip.dataset.build import SPLIT_MODES, BuildConfig, ClipResult, dataset_split
from prism_tools.chunking import group_source, make_split

DATA = REPO_ROOT.parent / "shared" / "data" / "motions"


def _result(clip_id: str, group: str, n_seq: int = 1, category: str = "walk") -> ClipResult:
    name = clip_id.replace("/", "__")
    return ClipResult(clip_id, "done", category, sequences=[f"{name}_v0_seq{k:03d}"
                                                             for k in range(n_seq)],
                      sequence_frames=[1000] * n_seq, group=group)  # fmt: skip


def _corpus() -> list[ClipResult]:
    out = []
    for actor, n in (("bd", 12), ("bk", 11), ("dg", 10), ("mm", 8)):
        out += [_result(f"hdm05/HDM_{actor}_squat1Reps_{k:03d}_120", f"hdm05/{actor}",
                        category="squat") for k in range(n)]  # fmt: skip
    for style, n in (("active", 30), ("elderly", 20), ("normal", 25), ("youthful", 22)):
        out += [_result(f"bandai/dataset-2_run_{style}_{k:03d}", f"bandai/dataset-2/{style}",
                        category="run") for k in range(n)]  # fmt: skip
    out += [_result(f"deepmimic/{n}", "") for n in ("walk", "run", "jump", "kick", "roll")]
    out += [_result("cmu/13_01", "cmu/13", 3), _result("cmu/14_07", "cmu/14", 2)]
    out.append(ClipResult("cmu/02_01", "done", "walk", group="cmu/02"))  # no sequence
    out.append(ClipResult("cmu/05_03", "failed", "balance", group="cmu/05"))
    return out


def test_split_by_person_keeps_people_apart_within_each_source() -> None:
    results = _corpus()
    split = dataset_split(results, 0.2, 42, "person")
    assert split["split_by"] == "person"
    train, test = set(split["groups"]["train"]), set(split["groups"]["test"])
    assert not train & test
    assert "cmu/02" not in train | test and "cmu/05" not in train | test  # nothing to split
    assert split["members"]["hdm05/bd"] == sorted(r.clip_id for r in results
                                                  if r.group == "hdm05/bd")  # fmt: skip
    assert split["members"]["deepmimic/walk"] == ["deepmimic/walk"]  # no group: the clip
    for source in ("hdm05", "bandai/dataset-2", "deepmimic", "cmu"):
        parts = split["sources"][source]
        assert parts["train"]["groups"] and parts["test"]["groups"], source
        total = parts["train"]["sequences"] + parts["test"]["sequences"]
        assert 0.1 <= parts["test"]["sequences"] / total <= 0.4, source
    assert len(split["sources"]["hdm05"]["test"]["groups"]) == 1  # 1 of 4 people is nearest
    by_id = {r.clip_id: r for r in results}
    for seq_side in ("train", "test"):
        for g in split["groups"][seq_side]:
            for cid in split["members"][g]:
                assert set(by_id[cid].sequences) <= set(split[seq_side])
    assert dataset_split(results[::-1], 0.2, 42, "person") == split  # order does not matter
    json.dumps(split)


def test_split_by_clip_is_the_split_of_older_builds() -> None:
    results = _corpus()
    split = dataset_split(results, 0.2, 42, "clip")
    groups = {s: r.clip_id for r in results if r.status == "done" for s in r.sequences}
    frames = dict.fromkeys(groups, 1000)
    cats = {s: r.category for r in results if r.status == "done" for s in r.sequences}
    old = make_split(sorted(groups), 0.2, 42, categories=cats, frames_per_chunk=frames,
                     groups=groups)  # fmt: skip
    assert {k: split[k] for k in old} == old
    assert split["split_by"] == "clip" and all(len(m) == 1 for m in split["members"].values())
    assert set(split["sources"]) == {"hdm05", "bandai/dataset-2", "deepmimic", "cmu"}


def test_split_settings() -> None:
    assert group_source("hdm05/bd") == "hdm05"
    assert group_source("bandai_namco/dataset-2/active") == "bandai_namco/dataset-2"
    assert group_source("clip") == ""
    with pytest.raises(ValueError, match="split_by"):
        BuildConfig(split_by="subject")
    with pytest.raises(ValueError, match="split_by"):
        dataset_split(_corpus(), 0.2, 42, "style")
    from grip.cli.data import SPLIT_MODES as CLI_MODES

    assert CLI_MODES == SPLIT_MODES


@pytest.mark.slow
def test_the_shared_corpus_splits_by_person_in_every_source() -> None:
    """Every clip of the shared folders, one sequence per clip (the search only, no build)."""
    if not DATA.is_dir():
        pytest.skip("shared motion data not found")
    from grip.cli.data import default_category_map
    from grip.motion.catalog import find_clips

    refs = find_clips(DATA, default_category_map())
    results = [_result(r.clip_id, r.group, category=r.category) for r in refs]
    split = dataset_split(results, 0.2, 42, "person")
    assert not set(split["groups"]["train"]) & set(split["groups"]["test"])
    assert set(split["sources"]) == {"bandai_namco/dataset-1", "bandai_namco/dataset-2", "cmu",
                                     "deepmimic", "hdm05"}  # fmt: skip
    for source, parts in split["sources"].items():
        assert parts["train"]["groups"] and parts["test"]["groups"], source
        total = parts["train"]["clips"] + parts["test"]["clips"]
        assert 0.12 <= parts["test"]["clips"] / total <= 0.3, source
    assert abs(len(split["test"]) / len(results) - 0.2) < 0.03
