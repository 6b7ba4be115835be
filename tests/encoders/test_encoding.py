"""The encoding pass: a whole dataset through several encoders a chunk at a time, each
encoded sequence handed on in sample order; the storage precision of an encoding."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.datasets.loading import load_dataset
from tactbench.encoders.encoding import (
    Storage,
    chunk_bounds,
    encode_images,
    encode_vectors,
    image_storage,
    vector_storage,
    vector_width,
)
from tactbench.encoders.farneback import Farneback
from tactbench.encoders.simple import FrameDiff, Raw
from tactbench.errors import InputError

TINY = "synthetic-forearm:users=1,repetitions=1,positions=1"


@pytest.fixture(scope="module")
def dataset():
    return load_dataset(TINY)


@pytest.mark.parametrize("chunk_bytes", [1, 1 << 30])  # a sample per chunk; one chunk
def test_each_sink_gets_what_its_encoder_gives_each_whole_sequence(dataset, chunk_bytes):
    encoders = {"raw": Raw(), "frame-diff": FrameDiff()}
    got: dict[str, list[np.ndarray]] = {name: [] for name in encoders}
    times = encode_images(dataset, encoders, {n: got[n].append for n in encoders},
                          pixel_mm=10.0, method="linear", chunk_bytes=chunk_bytes)
    images = dataset.images(10.0, "linear")
    for name, encoder in encoders.items():
        assert len(got[name]) == len(images)
        for image, seq in zip(images, got[name]):
            np.testing.assert_array_equal(seq, encoder.encode(image))
    assert set(times.cpu_seconds) == set(encoders) and times.workers >= 1
    assert times.imaging_seconds > 0 and times.wall_seconds >= times.imaging_seconds


def test_a_sink_that_refuses_a_sequence_names_the_encoder_and_sample(dataset):
    def refuse(seq):
        raise InputError("no room")

    with pytest.raises(InputError, match="encoder 'raw', sample 0: no room"):
        encode_images(dataset, {"raw": Raw()}, {"raw": refuse}, pixel_mm=10.0,
                      method="linear")


def test_taxel_vectors_go_through_each_encoders_encode_vectors(dataset):
    for encoder in (Raw(), FrameDiff()):
        got: list[np.ndarray] = []
        encode_vectors(dataset, encoder.name, encoder, got.append, chunk_bytes=64)
        width = vector_width(encoder, dataset.n_taxels)
        for vec, seq in zip(dataset.vectors(), got):
            assert seq.shape == (len(vec), width)
            np.testing.assert_array_equal(seq, encoder.encode_vectors(vec))
    with pytest.raises(InputError, match="encoder 'farneback' encodes only images"):
        encode_vectors(dataset, "farneback", Farneback(), got.append)


def test_storage_follows_the_encoders_declared_ranges():
    image = image_storage(FrameDiff(), "uint8")  # pressure (0, 1), diff (-1, 1)
    np.testing.assert_allclose(image.offset, [0.0, -1.0])
    np.testing.assert_allclose(image.scale, [1 / 255, 2 / 255])
    vector = vector_storage(FrameDiff(), "uint8")  # one channel spanning both ranges
    np.testing.assert_allclose(vector.offset, [-1.0])
    np.testing.assert_allclose(vector.scale, [2 / 255])
    assert image_storage(FrameDiff(), "float32").describe()["scale"] == [1.0, 1.0]


def test_chunk_bounds_respect_the_budget_and_take_every_sample():
    assert chunk_bounds([3, 3, 3, 3], 10, budget=60) == [(0, 2), (2, 4)]
    assert chunk_bounds([3, 9, 1], 10, budget=40) == [(0, 1), (1, 2), (2, 3)]  # a long one
    assert chunk_bounds([2] * 5, 1, budget=1000) == [(0, 5)]
    assert chunk_bounds([], 4) == []


def test_taxel_vectors_are_one_channel():
    storage = Storage.for_channels("uint8", 1)
    vectors = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    back = storage.decode(storage.encode(vectors))
    assert back.shape == (3, 4) and np.abs(back - vectors).max() <= 0.5 / 255 + 1e-7
    with pytest.raises(ValueError, match="2 value ranges for 3 channels"):
        Storage.for_channels("uint8", 3, ((0, 1), (0, 1)))
    with pytest.raises(ValueError, match="precision"):
        Storage.for_channels("int4", 1)
