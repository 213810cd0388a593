import numpy as np
import pytest

from grip.kinematics.dataset import (
    Normalizer,
    sample_windows,
    sequence_arrays,
)
from grip.kinematics.features import FeatureConfig
from prism_tools.synthetic import make_recording


def test_windows_shapes_padding_and_normalizer():
    cfg = FeatureConfig()
    seqs = [sequence_arrays(make_recording(n, seed=n), cfg) for n in (120, 40)]
    assert seqs[0].y["fa"].shape == (120, 144) and seqs[0].y["lv"].shape == (120, 18)
    rng = np.random.default_rng(0)
    x, y = sample_windows(seqs, 16, 60, rng)
    assert x.shape == (16, 60, cfg.n_features) and y["lp"].shape == (16, 60, 15)
    # The 40-frame sequence is padded by repeating its last frame, never mixed with another.
    short = [w for w in x if np.all(w[40:] == w[39])]
    assert short, "no window came from the short sequence"
    norm = Normalizer.fit(seqs)
    z = norm(np.concatenate([s.x for s in seqs]))
    np.testing.assert_allclose(z.mean(0)[norm.std > 1e-3], 0.0, atol=1e-4)


def test_clip_of_strips_variant_and_chunk_suffixes():
    from grip.kinematics.dataset import clip_of

    assert clip_of("cmu__07_05_v0_seq003") == "cmu__07_05"
    assert clip_of("cmu__07_05_v12_seq000") == "cmu__07_05"
    assert clip_of("cmu__07_05_c_seq001") == "cmu__07_05"
    assert clip_of("subj001_take002_seq003") == "subj001_take002"
    assert clip_of("walk") == "walk"


def test_holdout_split_keeps_each_clip_on_one_side():
    from types import SimpleNamespace

    from grip.kinematics.dataset import clip_of, holdout_split

    seqs = [SimpleNamespace(name=f"clip{c:02d}_v{v}_seq{i:03d}")
            for c in range(20) for v in range(2) for i in range(3)]  # fmt: skip
    train, val = holdout_split(seqs, 0.1, seed=0)
    assert len(train) + len(val) == len(seqs)
    held = {clip_of(s.name) for s in val}
    assert len(held) == 2 and not held & {clip_of(s.name) for s in train}
    assert len(val) == 2 * 2 * 3  # every chunk and variant of a held-out clip
    again, _ = holdout_split(seqs, 0.1, seed=0)
    assert [s.name for s in again] == [s.name for s in train]  # deterministic
    assert {clip_of(s.name) for s in holdout_split(seqs, 0.1, seed=1)[1]} != held
    # a small fraction still holds out one whole clip; one that would leave a side empty fails
    assert len({clip_of(s.name) for s in holdout_split(seqs[:12], 0.01, seed=0)[1]}) == 1
    with pytest.raises(ValueError, match="nothing to train or validate"):
        holdout_split(seqs[:12], 0.99, seed=0)
    with pytest.raises(ValueError, match="at least 2 clips"):
        holdout_split(seqs[:6], 0.5, seed=0)


def test_holdout_split_keeps_each_group_on_one_side(tmp_path):
    """With the groups of a folder split by person, a held-out person takes all their clips."""
    import json
    from types import SimpleNamespace

    from grip.kinematics.dataset import clip_of, dataset_groups, holdout_split

    members = {f"src/p{p}": [f"src/p{p}_clip{c}" for c in range(3)] for p in range(8)}
    (tmp_path / "split.json").write_text(json.dumps(
        {"format": "grip-prism-split", "version": 1, "train": [], "test": [],
         "split_by": "person", "members": members}))  # fmt: skip
    groups = dataset_groups(tmp_path)
    assert groups["src__p3_clip1"] == "src/p3" and len(groups) == 24
    seqs = [SimpleNamespace(name=f"src__p{p}_clip{c}_v0_seq{i:03d}")
            for p in range(8) for c in range(3) for i in range(2)]  # fmt: skip
    train, val = holdout_split(seqs, 0.25, seed=3, groups=groups)
    held = {groups[clip_of(s.name)] for s in val}
    assert 1 <= len(held) < 8 and not held & {groups[clip_of(s.name)] for s in train}
    assert len(val) == 6 * len(held)  # every clip and chunk of a held-out person
    # per clip, the same draw splits people across the two sides
    _, val_clip = holdout_split(seqs, 0.25, seed=3)
    by_clip = {groups[clip_of(s.name)] for s in val_clip}
    assert len(val_clip) < 6 * len(by_clip) or by_clip != held
    # a folder split by clip has no groups
    (tmp_path / "split.json").write_text(json.dumps(
        {"format": "grip-prism-split", "version": 1, "train": [], "test": [],
         "split_by": "clip"}))  # fmt: skip
    assert dataset_groups(tmp_path) == {}


def test_source_weights_share_sources_by_balance_and_draws_follow_them():
    from types import SimpleNamespace

    from grip.kinematics.dataset import sequence_sources, source_weights, training_weights

    # Source "big" has 900 frames in three sequences, "small" 100 in one.
    seqs = [SimpleNamespace(name=f"big__c{i}_v0_seq000", x=np.zeros((300, 1))) for i in range(3)]
    seqs.append(SimpleNamespace(name="small__c_v0_seq000", x=np.zeros((100, 1))))
    sources = sequence_sources(seqs, {})
    assert set(sources.values()) == {"big", "small"}
    w0 = source_weights(seqs, sources, 0.0)
    np.testing.assert_allclose(w0, [0.3, 0.3, 0.3, 0.1])  # in proportion to length
    w1 = source_weights(seqs, sources, 1.0)
    np.testing.assert_allclose(w1, [1 / 6, 1 / 6, 1 / 6, 0.5])  # every source the same share
    w5 = source_weights(seqs, sources, 0.5)
    np.testing.assert_allclose(w5[3], 10 / (30 + 10))  # sqrt(100) against sqrt(900)
    # Groups name the source of a split by person: "hdm05/bd" -> "hdm05".
    named = sequence_sources(seqs[:1], {"big__c0": "hdm05/bd"})
    assert named == {"big__c0_v0_seq000": "hdm05"}
    with pytest.raises(ValueError, match="balance"):
        source_weights(seqs, sources, 1.5)
    # Categories multiply in: "rare" has 100 of the 1,000 frames, all in the "big" source.
    for q, cat in zip(seqs, ("walk", "walk", "rare", "walk"), strict=True):
        q.category = cat
    np.testing.assert_allclose(training_weights(seqs, sources, 0.0, 0.0), w0)
    np.testing.assert_allclose(training_weights(seqs, sources, 1.0, 0.0), w1)
    wc = training_weights(seqs, sources, 0.0, 1.0)  # walk 700 frames, rare 300: equal shares
    np.testing.assert_allclose([wc[0] + wc[1] + wc[3], wc[2]], [0.5, 0.5])
    both = training_weights(seqs, sources, 1.0, 1.0)  # len * src^-1 * cat^-1, normalised
    raw = np.array([300 / 900 / 700, 300 / 900 / 700, 300 / 900 / 300, 100 / 100 / 700])
    np.testing.assert_allclose(both, raw / raw.sum())
    # A share of the windows starts at its sequence's first frame; 0 draws as before.
    real3 = [sequence_arrays(make_recording(n, seed=n), FeatureConfig()) for n in (90, 120)]
    a, _ = sample_windows(real3, 50, 30, np.random.default_rng(5))
    b, _ = sample_windows(real3, 50, 30, np.random.default_rng(5), first_share=0.0)
    np.testing.assert_array_equal(a, b)
    firsts, _ = sample_windows(real3, 50, 30, np.random.default_rng(5), first_share=1.0)
    assert all(any(np.array_equal(w, q.x[:30]) for q in real3) for w in firsts)
    half, _ = sample_windows(real3, 400, 30, np.random.default_rng(6), first_share=0.5)
    share = np.mean([any(np.array_equal(w, q.x[:30]) for q in real3) for w in half])
    assert 0.4 < share < 0.65  # (a random start is the first frame now and then too)
    # The sampler draws with those weights.
    real = [sequence_arrays(make_recording(n, seed=n), FeatureConfig()) for n in (80, 80)]
    x, _ = sample_windows(real, 200, 20, np.random.default_rng(0), np.array([0.0, 1.0]))
    assert all(np.any(np.all(w[0] == real[1].x, axis=1)) for w in x)


def test_split_sequences_are_named_by_their_file_so_groups_find_them(tmp_path):
    """The split's groups key clips by file name; a recording's own name may differ."""
    import dataclasses
    import json

    from grip.kinematics.dataset import clip_of, dataset_groups, load_split_sequences
    from prism_tools.io import save_recording

    (tmp_path / "sequences").mkdir()
    stem = "src__p1_clip0_v0_seq000"
    rec = make_recording(40, seed=1)
    rec = dataclasses.replace(rec, extras={**rec.extras, "chunk_id": "synthetic_src/p1_clip0"})
    save_recording(rec, tmp_path / "sequences" / f"{stem}.npz")
    (tmp_path / "split.json").write_text(json.dumps(
        {"format": "grip-prism-split", "version": 1, "train": [stem], "test": [],
         "split_by": "person", "members": {"src/p1": ["src/p1_clip0"]}}))  # fmt: skip
    (seq,) = load_split_sequences(tmp_path, "train", FeatureConfig())
    assert seq.name == stem and dataset_groups(tmp_path)[clip_of(seq.name)] == "src/p1"
