"""The CoST reader, on files written here in the corpus's format (the corpus is not
shipped): every field read back, segmentation by frame discontinuity, stray spaces in
the header, subjects as users, the store's cache, and every refusal naming its line."""

from __future__ import annotations

import hashlib
import logging

import numpy as np
import pytest

from tactbench.data.splits import SplitData, dataset_groups
from tactbench.datasets.cost import (
    COLUMNS,
    GESTURES,
    CoST,
    cost_layout,
    read_cost_csv,
    write_cost_csv,
)

HEADER = ",".join(COLUMNS)


def row(subject, variant, gesture, frame, value=0):
    vals = [str((value + k) % 1024) for k in range(64)]
    return ",".join([subject, variant, gesture, str(frame)] + vals)


def with_ch2(line, text):
    """``line`` with its ch2 reading written as ``text``."""
    fields = line.split(",")
    fields[5] = text
    return ",".join(fields)


def cost_file(tmp_path, lines, header=HEADER, name="cost.csv"):
    path = tmp_path / name
    path.write_text("\n".join(([header] if header else []) + lines) + "\n")
    return path


def capture(subject, variant, gesture, n, first=1, value=0):
    return [row(subject, variant, gesture, first + f, value + f) for f in range(n)]


def test_every_field_read_back(tmp_path):
    # stray spaces and capitals in the header, as some copies have them
    header = ",".join(f" {c.capitalize()} " if k % 3 == 0 else c for k, c in enumerate(COLUMNS))
    lines = (capture("1", "gentle", "pat", 5)
             + capture("1", "gentle", "pat", 3, value=100)   # frame restarts: capture 2
             + capture("1", "rough", "grab", 3, first=7)
             + capture("2", "normal", "pat", 4, first=0))
    ds = read_cost_csv(cost_file(tmp_path, lines, header=header))
    assert len(ds) == 4
    assert ds.classes == ("grab", "pat")  # the corpus's order, the gestures present
    assert ds.labels.tolist() == [1, 1, 0, 1]
    assert ds.lengths().tolist() == [5, 3, 3, 4]
    assert ds.users == ["1", "1", "1", "2"]
    assert ds.attributes == {"variant": ["gentle", "gentle", "rough", "normal"]}
    assert ds.positions == [""] * 4
    assert ds.repetitions.tolist() == [1, 2, 1, 1]
    assert ds.sources == [f"cost.csv#capture{k}" for k in (1, 2, 3, 4)]
    rec = ds[2].recording
    assert rec.timestamps.tolist() == pytest.approx([0, 1 / 135, 2 / 135])
    assert rec.values.dtype == np.float32
    assert rec.values[1].tolist() == [(1 + k) % 1024 for k in range(64)]
    assert ds[1].recording.values[0, 63] == 163
    assert rec.taxel_ids.tolist() == list(range(64))
    assert ds.layout.n_taxels == 64 and ds.layout.name == "cost-8x8"
    assert ds.normalisation.spec == "fixed:offset=0,scale=1023"
    assert ds.summary()["frame_rate_hz"] == 135.0
    assert ds.images(pixel_mm=5.0)[0].shape == (5, 16, 16)


def test_a_capture_is_a_run_of_consecutive_frames(tmp_path):
    # one subject, variant and gesture throughout: only the frame numbers split them
    lines = (capture("3", "normal", "tap", 4, first=1) + capture("3", "normal", "tap", 2, first=9)
             + capture("3", "normal", "tap", 3, first=2))
    ds = read_cost_csv(cost_file(tmp_path, lines, header=None))  # no header: column order
    assert ds.lengths().tolist() == [4, 2, 3]
    assert ds.repetitions.tolist() == [1, 2, 3]


def test_gestures_and_frames_as_a_matlab_export_writes_them(tmp_path):
    lines = [row("3", "normal", "2.0", f"{f}.0") for f in (1, 2)]
    ds = read_cost_csv(cost_file(tmp_path, lines))
    assert ds.classes == ("hit",) and ds.lengths().tolist() == [2]


def test_gestures_as_numbers_are_the_corpus_names_in_order(tmp_path):
    lines = [r for g in (14, 2, 1) for r in capture("3", "normal", str(g), 2)]
    ds = read_cost_csv(cost_file(tmp_path, lines))
    assert ds.classes == ("grab", "hit", "tickle") and ds.labels.tolist() == [2, 1, 0]
    assert len(GESTURES) == 14


def test_subjects_are_users_and_variant_a_group(tmp_path):
    lines = [r for s in "1234" for v in ("gentle", "rough") for g in ("pat", "hit")
             for r in capture(s, v, g, 2)]
    ds = read_cost_csv(cost_file(tmp_path, lines))
    data = SplitData.of(ds)
    from tactbench.data.strategies import GroupSplit, UsersSplit

    for split in UsersSplit().split(data, seed=3):
        train = {ds.users[i] for i in split.train}
        assert train and train.isdisjoint(ds.users[i] for i in split.test)
    fixed = GroupSplit(key="variant", test="rough").split(data, seed=0)[0]
    assert {ds.attributes["variant"][i] for i in fixed.test} == {"rough"}
    assert dataset_groups(ds)["variant"] == ds.attributes["variant"]


def test_converted_once_then_read_from_the_store(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    path = cost_file(tmp_path, capture("1", "gentle", "pat", 3) + capture("2", "rough", "hit", 4))
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        first = CoST(path=str(path)).load()
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "2 captures of 2 people, 2 gestures" in said[0]
    assert "3–4 frames a capture" in said[0] and "at 135 Hz" in said[0]
    stored = list((tmp_path / "cache" / "datasets").glob("cost-*"))
    assert len(stored) == 1
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        again = CoST(path=str(path)).load()
    assert not caplog.records  # said once
    assert again.content_hash() == first.content_hash()
    assert again.attributes == first.attributes and again.users == first.users
    digests = list((tmp_path / "cache" / "datasets" / "digests").iterdir())
    assert len(digests) == 1  # the file's SHA-256, kept for the next load
    assert digests[0].read_text().strip() == hashlib.sha256(path.read_bytes()).hexdigest()
    digests[0].write_text("damaged")  # a damaged record is computed anew
    assert CoST(path=str(path)).load().content_hash() == first.content_hash()
    path.write_text(path.read_text().replace(",gentle,", ",normal,"))  # other content
    assert CoST(path=str(path)).load().attributes["variant"] == ["normal", "rough"]
    assert len(list((tmp_path / "cache" / "datasets").glob("cost-*"))) == 2


def test_write_and_read_back(tmp_path):
    lines = capture("1", "gentle", "pat", 4) + capture("2", "rough", "hit", 6, value=7)
    ds = read_cost_csv(cost_file(tmp_path, lines))
    write_cost_csv(ds, tmp_path / "again.csv")
    back = read_cost_csv(tmp_path / "again.csv")
    assert back.content_hash() == ds.content_hash()
    assert CoST(path=str(tmp_path / "again.csv"), cache=False).load().content_hash() == \
        ds.content_hash()


def test_layout_is_an_8x8_grid():
    lay = cost_layout(pitch_mm=12.0)
    assert lay.positions[9].tolist() == [12.0, 12.0]  # ch10: row 1, column 1
    assert lay.median_spacing() == pytest.approx(12.0)


def ok(n=2, **kw):
    return capture("1", "gentle", "pat", n, **kw)


@pytest.mark.parametrize("lines, header, message", [
    ([], "", "empty file"),
    (ok(), HEADER.replace("gesture,", "gest,"), r"line 1: no column 'gesture'"),
    (ok(), HEADER.replace(",ch64", ""), "line 1: 63 channel columns; CoST has 64"),
    (ok(), HEADER + ",ch65", "line 1: 65 channel columns"),
    (ok(), HEADER.replace("ch2,ch3,", "ch3,ch2,"), "channel column 2 is named 'ch3'"),
    (ok(), HEADER.replace("frame", "subject"), "column 'subject' appears twice"),
    ([row("1", "g", "pat", 1), row("1", "g", "pat", 2)[:-4]], HEADER,
     "line 3: 67 fields; every CoST row has 68 .truncated"),
    ([row("1", "g", "pat", 1), with_ch2(row("1", "g", "pat", 2), "x")],
     HEADER, "line 3: ch2 value 'x' is not a number"),
    ([row("1", "g", "pat", 1), with_ch2(row("1", "g", "pat", 2), "")],
     HEADER, "line 3: ch2 is empty or NaN"),
    ([row("1", "g", "pat", 1), with_ch2(row("1", "g", "pat", 2), "nan")],
     HEADER, "line 3: ch2 is empty or NaN"),
    ([row("1", "g", "pat", 1), with_ch2(row("1", "g", "pat", 2), "inf")],
     HEADER, "line 3: ch2 is inf"),
    ([row("1", "g", "pat", 1), row("1", "g", "pat", "two")], HEADER,
     "line 3: frame value 'two' is not a whole number"),
    ([row("1", "g", "pat", 1), row("1", "g", "pat", "2.5")], HEADER,
     "line 3: frame value 2.5 is not a whole number"),
    ([row("1", "g", "pat", 1), row(" ", "g", "pat", 2)], HEADER, "line 3: empty subject"),
    (ok() + capture("1", "g", "cuddle", 2), HEADER,
     "line 4: gesture 'cuddle' is not one of CoST's 14"),
    (ok() + capture("1", "g", "15", 2), HEADER, "line 4: gesture '15' is not one"),
    (ok(3) + [row("1", "gentle", "pat", 9)] + ok(2), HEADER,
     "line 5: capture 2 has one frame .frame 9."),
    (ok(3) + capture("1", "gentle", "hit", 2) + ok(3), HEADER,
     r"line 7: capture 3 repeats capture 1 \(subject 1, gentle, pat"),
    ([], HEADER, "no rows of data"),
])
def test_refusals_name_the_line(tmp_path, lines, header, message):
    path = cost_file(tmp_path, lines, header=header, name="bad.csv")
    if not lines and not header:
        path.write_text("")
    with pytest.raises(ValueError, match=message) as info:
        read_cost_csv(path)
    assert "bad.csv" in str(info.value) and "\n" not in str(info.value)


def test_blank_lines_do_not_shift_the_line_named(tmp_path):
    lines = ok(2) + ["", ""] + [row("1", "g", "pat", 1), row("1", "g", "pat", 2, 5)
                                .replace(",5,6,", ",5,?,", 1)]
    with pytest.raises(ValueError, match="line 7: ch2 value '[?]'"):
        read_cost_csv(cost_file(tmp_path, lines))


def test_a_ragged_row_after_blank_lines_is_named_by_its_line(tmp_path):
    lines = ok(2) + ["", ""] + [row("1", "g", "pat", 1) + ",7"]
    with pytest.raises(ValueError, match="line 6: 69 fields; every CoST row has 68 .a stray"):
        read_cost_csv(cost_file(tmp_path, lines))


def test_same_readings_under_other_labels_are_not_duplicates(tmp_path):
    lines = ok(3) + capture("2", "gentle", "pat", 3)  # same values, another subject
    assert len(read_cost_csv(cost_file(tmp_path, lines))) == 2


def test_writer_needs_64_taxels(tmp_path):
    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    ds = Dataset("d", [Sample(Recording(np.zeros((2, 3)), [0, 1], [1, 2, 3]), 0)], ("a",))
    with pytest.raises(ValueError, match="CoST files hold 64 channels"):
        write_cost_csv(ds, tmp_path / "x.csv")


def test_without_pyarrow_one_line_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(ImportError, match=r'pip install "tactbench\[export\]"'):
        read_cost_csv(cost_file(tmp_path, ok()))


def test_data_info_shows_the_variants(tmp_path):
    from click.testing import CliRunner

    from tactbench.cli import cli

    path = cost_file(tmp_path, capture("1", "gentle", "pat", 3) + capture("2", "rough", "pat", 3))
    res = CliRunner().invoke(cli, ["data", "info", f"cost:path={path}"])
    assert res.exit_code == 0, res.output
    assert "samples per variant: gentle: 1, rough: 1" in res.output
    assert "rate: 135.0 Hz" in res.output and "samples per user: 1: 1, 2: 1" in res.output


def test_a_file_beyond_the_memory_budget_is_refused_before_reading(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "0.001")
    with pytest.raises(ValueError, match=r"reading .*cost.csv \(.* of CSV\) would need about"):
        read_cost_csv(cost_file(tmp_path, ok()))
