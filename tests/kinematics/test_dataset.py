import numpy as np

from grip.kinematics.dataset import Normalizer, sample_windows, sequence_arrays
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
