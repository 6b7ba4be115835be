"""Encodings on disk: whole folders or none, keyed by everything that decides them."""

from __future__ import annotations

import numpy as np

from tactbench.runner import EncodingCache, load_encoding


def test_write_and_load_round_trip(tmp_path):
    cache = EncodingCache(tmp_path)
    seqs = [np.full((t, 2, 3, 4), t, np.float32) for t in (3, 1, 5)]
    key = cache.key("hash", {"kind": "images", "pixel_mm": 5.0}, "raw", "1")
    assert not cache.has(key)
    cache.write(key, seqs, {"encoder": "raw", "frames": 9})
    assert cache.has(key)
    loaded, meta = load_encoding(cache.path(key))
    assert [s.shape for s in loaded] == [s.shape for s in seqs]
    assert all(np.array_equal(a, b) for a, b in zip(loaded, seqs))
    assert meta["encoder"] == "raw" and "created" in meta
    (entry,) = cache.entries()
    assert entry["key"] == key and entry["bytes"] > 9 * 24 * 4
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftovers
    assert cache.clear() == 1 and cache.entries() == []


def test_keys_change_with_imaging_encoder_and_version():
    cache_key = EncodingCache.key
    base = cache_key(None, "h", {"kind": "vectors"}, "raw", "1")
    assert base != cache_key(None, "h2", {"kind": "vectors"}, "raw", "1")
    assert base != cache_key(None, "h", {"kind": "images"}, "raw", "1")
    assert base != cache_key(None, "h", {"kind": "vectors"}, "frame-diff", "1")
    assert base != cache_key(None, "h", {"kind": "vectors"}, "raw", "2")
