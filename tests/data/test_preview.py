"""Preview strips: one sample as a picture (tactile images, encoder channels or taxel bands)."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.preview import (
    Preview,
    preview_strip,
    taxel_bands,
    tile,
    to_rgb,
    write_png,
)


class Signed:
    """A two-channel encoder with values in [-1, 1]: the frame and its negative."""

    channels = ("pos", "neg")
    ranges = ((-1.0, 1.0), (-1.0, 1.0))

    def encode(self, seq):
        return np.stack([seq, -seq], axis=1).astype(np.float32)


def test_strip_of_tactile_images(make_dataset):
    ds = make_dataset()
    frames = ds[1].recording.n_frames
    shown = preview_strip(ds, 1, pixel_mm=2.0)
    assert isinstance(shown, Preview) and shown.frames == frames and shown.taxels == 16
    h, w = shown.frame_shape
    assert (h, w) == ds.imager(2.0, "linear").shape
    s = max(1, round(96 / max(h, w)))
    assert shown.image.shape == (s * h, frames * (s * w + 2) - 2, 3)
    assert shown.image.dtype == np.float32
    assert 0.0 <= shown.image.min() and shown.image.max() <= 1.0


def test_max_frames_keeps_the_first_frames(make_dataset):
    ds = make_dataset()
    full = preview_strip(ds, 1, pixel_mm=2.0)
    two = preview_strip(ds, 1, pixel_mm=2.0, max_frames=2)
    assert two.frames == 2 and np.array_equal(two.image, full.image[:, :two.image.shape[1]])


def test_encoder_channels_are_scaled_by_their_ranges(make_dataset):
    ds = make_dataset()
    shown = preview_strip(ds, 0, encoder=Signed(), pixel_mm=2.0)
    frame = shown.image[:, :shown.image.shape[1] // shown.frames - 2]
    assert frame[..., 0].min() >= 0.5 and frame[..., 1].max() <= 0.5  # +p and -p
    assert np.all(frame[..., 2] == 0)  # no third channel


def test_without_a_layout_the_taxel_values_are_shown_as_bands(make_dataset):
    ds = make_dataset(layout=False)
    shown = preview_strip(ds, 2)
    t = ds[2].recording.n_frames
    assert shown.frame_shape is None and shown.frames == t
    assert shown.image.shape == (8 * t, 16, 3)
    with pytest.raises(ValueError, match="'tiny' has no taxel layout"):
        preview_strip(ds, 2, encoder=Signed())


def test_sample_out_of_range(make_dataset):
    with pytest.raises(ValueError, match="sample 6 is out of range: dataset 'tiny' has 6"):
        preview_strip(make_dataset(), 6)


def test_to_rgb_grey_for_one_channel_and_unit_range_by_default():
    enc = np.array([[[[0.0, 0.5, 2.0]]]], dtype=np.float32)  # (1, 1, 1, 3)
    rgb = to_rgb(enc)
    assert rgb.shape == (1, 1, 3, 3)
    assert rgb[0, 0, :, 0].tolist() == [0.0, 0.5, 1.0]  # clipped to the range
    assert np.array_equal(rgb[..., 0], rgb[..., 2])
    with pytest.raises(ValueError, match=r"encoded frames must be \(T, C, H, W\)"):
        to_rgb(np.zeros((2, 3, 4)))


def test_tile_enlarges_by_a_whole_factor_with_white_gaps():
    frames = np.zeros((3, 10, 20, 3), dtype=np.float32)
    strip = tile(frames, min_side=40)
    assert strip.shape == (20, 3 * 40 + 2 * 2, 3)
    assert np.all(strip[:, 40:42] == 1.0) and np.all(strip[:, :40] == 0.0)


def test_taxel_bands_repeat_each_frame():
    bands = taxel_bands(np.array([[0.0, 1.0], [1.0, 0.0]]), band=3)
    assert bands.shape == (6, 2, 3)
    assert np.array_equal(bands[0], bands[2]) and not np.array_equal(bands[2], bands[3])


def test_write_png(tmp_path):
    from matplotlib.image import imread

    image = np.zeros((5, 7, 3), dtype=np.float32)
    image[:, :, 1] = 1.0
    write_png(tmp_path / "p.png", image)
    back = imread(tmp_path / "p.png")
    assert back.shape[:2] == (5, 7) and back[0, 0, 1] == 1.0
    assert [p.name for p in tmp_path.iterdir()] == ["p.png"]
