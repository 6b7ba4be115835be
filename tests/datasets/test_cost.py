"""The CoST CSV reader, on files written here in that format (the corpus is not shipped)."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.datasets.cost import COLUMNS, CoST, cost_layout, read_cost_csv, write_cost_csv

HEADER = ",".join(COLUMNS)


def row(subject, variant, gesture, frame, value=0):
    vals = [str((value + k) % 1024) for k in range(64)]
    return ",".join([subject, variant, gesture, str(frame)] + vals)


def cost_file(tmp_path, lines, header=True, name="cost.csv"):
    path = tmp_path / name
    path.write_text("\n".join(([HEADER] if header else []) + lines) + "\n")
    return path


def test_captures_start_where_the_frame_counter_restarts(tmp_path):
    lines = ([row("1", "gentle", "pat", f, f) for f in range(5)]
             + [row("1", "gentle", "pat", f, 100 + f) for f in range(3)]  # restart: capture 2
             + [row("1", "rough", "grab", f) for f in range(1, 4)]
             + [row("2", "normal", "pat", f) for f in range(4)])
    ds = read_cost_csv(cost_file(tmp_path, lines))
    assert len(ds) == 4
    assert ds.classes == ("grab", "pat")
    assert ds.labels.tolist() == [1, 1, 0, 1]
    assert [s.recording.n_frames for s in ds] == [5, 3, 3, 4]
    assert ds.users == ["1", "1", "1", "2"]
    assert ds.positions == ["gentle", "gentle", "rough", "normal"]  # variant
    assert ds.repetitions.tolist() == [1, 2, 1, 1]
    rec = ds[0].recording
    assert rec.timestamps[1] == pytest.approx(1 / 135)
    assert rec.values[2, 0] == 2 and rec.values[2, 63] == 65
    assert ds.layout.n_taxels == 64 and ds.normalisation.spec == "fixed:offset=0,scale=1023"
    assert ds.images(pixel_mm=5.0)[0].shape == (5, 16, 16)


def test_header_is_optional_and_numeric_gestures_sort_naturally(tmp_path):
    lines = [row("3", "normal", str(g), f) for g in (10, 2, 1) for f in range(2)]
    ds = read_cost_csv(cost_file(tmp_path, lines, header=False))
    assert ds.classes == ("1", "2", "10") and len(ds) == 3


def test_write_and_read_back(tmp_path):
    lines = [row("1", "gentle", "pat", f, f) for f in range(4)] + \
            [row("2", "rough", "hit", f, 7 * f) for f in range(6)]
    ds = read_cost_csv(cost_file(tmp_path, lines))
    write_cost_csv(ds, tmp_path / "again.csv")
    back = read_cost_csv(tmp_path / "again.csv")
    assert back.content_hash() == ds.content_hash()
    assert CoST(path=str(tmp_path / "again.csv")).load().content_hash() == ds.content_hash()


def test_layout_is_an_8x8_grid():
    lay = cost_layout(pitch_mm=12.0)
    assert lay.positions[9].tolist() == [12.0, 12.0]  # ch10: row 1, column 1
    assert lay.median_spacing() == pytest.approx(12.0)


@pytest.mark.parametrize("lines, message", [
    ([], "empty file"),
    (["subject,variant,gesture,frame,ch1"], "line 1: header must be"),
    ([HEADER, row("1", "g", "pat", 0)[:-4]], "line 2: expected 68 columns.*truncated"),
    ([HEADER, row("1", "g", "pat", 0).replace(",0,1,2", ",0,x,2", 1)], "line 2: ch2 value 'x'"),
    ([HEADER, row("1", "g", "pat", 0).replace(",0,1,2", ",0,nan,2", 1)], "line 2: ch2 is nan"),
    ([HEADER, row("1", "g", "pat", "one")], "line 2: frame 'one' is not a number"),
    ([HEADER, row("", "g", "pat", 0)], "line 2: empty subject or gesture"),
    ([HEADER], "no frames"),
])
def test_bad_files(tmp_path, lines, message):
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + ("\n" if lines else ""))
    with pytest.raises(ValueError, match=message) as info:
        read_cost_csv(path)
    assert "bad.csv" in str(info.value)


def test_writer_needs_64_taxels(tmp_path):
    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    ds = Dataset("d", [Sample(Recording(np.zeros((2, 3)), [0, 1], [1, 2, 3]), 0)], ("a",))
    with pytest.raises(ValueError, match="CoST files hold 64 channels"):
        write_cost_csv(ds, tmp_path / "x.csv")


def test_values_survive(tmp_path):
    lines = [row("1", "g", "pat", f, 1000) for f in range(2)]
    ds = read_cost_csv(cost_file(tmp_path, lines))
    expect = (1000 + np.arange(64)) % 1024
    assert np.array_equal(ds[0].recording.values[0], expect)
