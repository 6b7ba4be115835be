"""Sample attributes (a corpus's variant, substrate, cover): checked when made, kept by the
store, part of the content hash, and a group a split can leave out."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.data.splits import dataset_groups, make_splits


def dataset(attrs):
    rec = Recording(np.arange(6, dtype=np.float32).reshape(3, 2), [0, 1, 2], [0, 1])
    return Dataset("d", [Sample(rec, k % 2, user=f"u{k}", attributes=a)
                         for k, a in enumerate(attrs)], ("a", "b"))


def test_attributes_are_words_with_text_values():
    rec = Recording(np.zeros((2, 1)), [0, 1], [0])
    for bad in ({"user": "x"}, {"two words": "x"}, {1: "x"}):
        with pytest.raises(ValueError, match="a sample attribute is named by a word"):
            Sample(rec, 0, attributes=bad)
    with pytest.raises(ValueError, match="attribute 'cover' must be text, got int"):
        Sample(rec, 0, attributes={"cover": 3})


def test_kept_by_the_store_and_hashed(tmp_path):
    ds = dataset([{"variant": "gentle"}, {"variant": "rough", "cover": "fur"},
                  {"variant": "gentle"}, {}])
    assert ds.attributes == {"variant": ["gentle", "rough", "gentle", ""],
                             "cover": ["", "fur", "", ""]}
    back = Dataset.load(ds.save(tmp_path / "ds"))
    assert back.attributes == ds.attributes and back.content_hash() == ds.content_hash()
    assert [s.attributes for s in back] == [s.attributes for s in ds]
    other = dataset([{"variant": "gentle"}, {"variant": "gentle", "cover": "fur"},
                     {"variant": "gentle"}, {}])
    assert other.content_hash() != ds.content_hash()
    assert dataset([{}] * 4).content_hash() != ds.content_hash()
    assert "attributes" not in json.loads(
        (dataset([{}] * 4).save(tmp_path / "plain") / "manifest.json").read_text())


def test_a_damaged_attribute_list_is_refused(tmp_path):
    folder = dataset([{"variant": "a"}, {"variant": "b"}, {}, {}]).save(tmp_path / "ds")
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["attributes"]["variant"] = ["a"]
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="'attributes' must map names to lists of 4 strings"):
        Dataset.load(folder)


def test_a_split_leaves_an_attribute_out():
    ds = dataset([{"variant": v} for v in ("gentle", "rough", "gentle", "rough",
                                           "normal", "normal")])
    groups = dataset_groups(ds)
    assert groups["variant"] == ds.attributes["variant"]
    split = make_splits("group:variant:test=rough", labels=ds.labels, users=ds.users, seed=0,
                        groups=groups)[0]
    assert split.test.tolist() == [1, 3] and split.left_out == ("rough",)
