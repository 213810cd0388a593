"""The commands' shared recording loader and checkpoint lookup."""

from __future__ import annotations

import pytest

from grip.cli.errors import CliError
from grip.cli.recordings import kin_checkpoint, load_recordings
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording


@pytest.fixture()
def files(tmp_path):
    out = []
    for i, n in enumerate((250, 120)):
        p = tmp_path / f"rec{i}.npz"
        save_recording(make_recording(n, seed=i), p)
        out.append(p)
    return out


def test_segments_crops_categories_and_limit(files):
    cat = load_recordings(files[:1])[0].category
    segs = load_recordings(files, segment_frames=100)
    assert [r.n_frames for r in segs] == [100, 100, 100]  # tails of 50 and 20 left out
    assert [r.n_frames for r in load_recordings(files, max_frames=110)] == [110, 110]
    assert len(load_recordings(files, segment_frames=100, limit=2)) == 2
    over = load_recordings(files, segment_frames=100, segment_stride=50)
    assert [r.n_frames for r in over] == [100] * 5  # starts 0..150 of the first, 0 of the second
    whole = load_recordings(files[:1])[0]
    assert (over[1].smpl_params.poses == whole.smpl_params.poses[50:150]).all()
    assert len(load_recordings(files, categories=[cat[:2] + "*"])) == 2
    with pytest.raises(CliError, match="no recordings of categories"):
        load_recordings(files, categories=["no-such-*"])


def test_unreadable_file_and_missing_checkpoint_name_the_path(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"junk")
    with pytest.raises(CliError, match=r"bad\.npz"):
        load_recordings([bad])
    with pytest.raises(CliError, match=r"none\.pt"):
        kin_checkpoint(tmp_path / "none.pt")
    assert kin_checkpoint(None).is_file()  # the shipped one
