"""Fuzz: mutated dataset folders (manifest values replaced or removed, arrays.npz bytes
flipped or truncated, members added or replaced) only ever raise tactbench's own error,
stay under a memory cap, and are never changed by the failed read."""

from __future__ import annotations

import io
import json
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.data.dataset import Dataset
from tactbench.errors import TactbenchError
from tactbench.fuzzing import json_mutation as _json_mutation
from tactbench.fuzzing import json_values
from tactbench.integrity import hash_file

FUZZ = settings(max_examples=60, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
CAP_MIB = 200

#: JSON values a hostile or careless edit could leave in a field.
JSON_VALUES = json_values(())


def json_mutation(doc):
    return _json_mutation(doc, values=JSON_VALUES, at_most=1)


def _dataset():
    rng = np.random.default_rng(0)
    from tactbench.data.layout import TaxelLayout
    from tactbench.data.recording import Recording, Sample

    ids = np.arange(12) + 100
    layout = TaxelLayout(ids=ids, positions=np.column_stack([ids % 4, ids // 4]) * 7.5,
                         name="grid")
    samples = [Sample(Recording(rng.integers(0, 60000, (4 + k, 12)).astype(np.float32),
                                0.1 * np.arange(4 + k), ids), k % 2, user=f"u{k % 2}")
               for k in range(4)]
    return Dataset("fuzz", samples, ("a", "b"), layout, "fixed")


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A real dataset folder, written by tactbench."""
    return _dataset().save(tmp_path_factory.mktemp("fuzz-store") / "d")


def _folder_hash(folder: Path) -> dict[str, str]:
    return {p.name: hash_file(p) for p in sorted(folder.iterdir())}


def _check_read(folder: Path, memory_cap) -> None:
    """Reading ``folder`` raises nothing but TactbenchError, under the cap; the folder is
    the same before and after. A read that succeeds passed the content-hash check."""
    before = _folder_hash(folder)
    with memory_cap(CAP_MIB):
        try:
            Dataset.load(folder)
        except TactbenchError as exc:
            assert "\n" not in str(exc)
    assert _folder_hash(folder) == before


def _copy(saved: Path, root: str) -> Path:
    return Path(shutil.copytree(saved, Path(root) / "d"))


@FUZZ
@given(data=st.data())
def test_mutated_manifest(saved, memory_cap, data):
    manifest = json.loads((saved / "manifest.json").read_text())
    mutated = data.draw(json_mutation(manifest))
    with tempfile.TemporaryDirectory() as root:
        folder = _copy(saved, root)
        (folder / "manifest.json").write_text(json.dumps(mutated))
        _check_read(folder, memory_cap)


@FUZZ
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      min_size=1, max_size=8),
       cut=st.one_of(st.none(), st.floats(0, 1, exclude_max=True)))
def test_npz_bytes_flipped_or_truncated(saved, memory_cap, flips, cut):
    data = bytearray((saved / "arrays.npz").read_bytes())
    for where, mask in flips:
        data[int(where * len(data))] ^= mask
    if cut is not None:
        data = data[:int(cut * len(data))]
    with tempfile.TemporaryDirectory() as root:
        folder = _copy(saved, root)
        (folder / "arrays.npz").write_bytes(bytes(data))
        _check_read(folder, memory_cap)


NPY_HEADERS = st.fixed_dictionaries({
    "descr": st.sampled_from(["<f8", "<f4", "<u2", "<i8", ">i4", "|u1", "|b1", "<c16",
                              "<U3", "|V4"]),
    "fortran_order": st.booleans(),
    "shape": st.lists(st.one_of(st.integers(0, 50), st.sampled_from([20_000_000_000, 2**40])),
                      max_size=3).map(tuple)})


@st.composite
def member(draw):
    """Bytes of an npy member: a header with any shape/dtype and a short payload, or junk."""
    from numpy.lib import format as npy

    if draw(st.booleans()):
        return draw(st.binary(max_size=200))
    buf = io.BytesIO()
    npy.write_array_header_1_0(buf, draw(NPY_HEADERS))
    return buf.getvalue() + draw(st.binary(max_size=400))


@FUZZ
@given(name=st.one_of(st.sampled_from(["values", "timestamps", "offsets", "taxel_ids",
                                       "labels", "repetitions", "layout_ids",
                                       "layout_positions", "layout_bounds", "layout_normals"]),
                      st.text("abcxyz_", min_size=1, max_size=6)),
       content=member(), compress=st.booleans())
def test_npz_members_replaced_or_added(saved, memory_cap, name, content, compress):
    with tempfile.TemporaryDirectory() as root:
        folder = _copy(saved, root)
        path = folder / "arrays.npz"
        with zipfile.ZipFile(saved / "arrays.npz") as z:
            members = {i.filename: z.read(i) for i in z.infolist()}
        members[f"{name}.npy"] = content
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED if compress
                             else zipfile.ZIP_STORED) as z:
            for filename, payload in members.items():
                z.writestr(filename, payload)
        _check_read(folder, memory_cap)


def test_the_fuzzed_folder_itself_loads(saved):
    """The fuzz starts from a valid folder (else every read would fail the same way)."""
    assert Dataset.load(saved).content_hash() == _dataset().content_hash()
