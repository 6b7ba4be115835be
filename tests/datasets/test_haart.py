"""The HAART reader, on the challenge's two files written here in its format (the corpus
is not shipped): every field read back, participants as users, substrate, cover and set
as attributes, the challenge's own division as a fixed split, and every refusal."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tactbench.data.splits import SplitData, make_splits
from tactbench.data.strategies import GroupSplit, UsersSplit
from tactbench.datasets.haart import GESTURES, HAART, gesture_name, read_haart

HEADER = "ParticipantID, Substrate, Cover, Gesture," + ",".join(
    f" ch{k}" for k in range(1, 65))  # stray spaces, as in some copies


def capture(participant, substrate, cover, gesture, frames=4, value=0):
    return [",".join([participant, substrate, cover, gesture]
                     + [str((value + f + k) % 1024) for k in range(64)]) for f in range(frames)]


def haart_folder(tmp_path, training, test, header=HEADER):
    folder = tmp_path / "haart"
    folder.mkdir(exist_ok=True)
    for name, lines in (("training.csv", training), ("testWITHLABELS.csv", test)):
        (folder / name).write_text("\n".join(([header] if header else []) + lines) + "\n")
    return folder


def small(tmp_path, frames=4):
    training = [r for p in ("1", "2") for g in ("Pat", "Stroke")
                for r in capture(p, "flat", "none", g, frames)]
    training += capture("2", "curved", "fur", "Pat", frames, value=50)
    test = [r for g in ("Pat", "Stroke") for r in capture("9", "foam", "minkee", g, frames)]
    return haart_folder(tmp_path, training, test)


def test_every_field_read_back(tmp_path):
    ds = read_haart(small(tmp_path), frames=4)
    assert len(ds) == 7 and ds.name == "haart"
    assert ds.classes == ("pat", "stroke")
    assert ds.labels.tolist() == [0, 1, 0, 1, 0, 0, 1]
    assert ds.users == ["1", "1", "2", "2", "2", "9", "9"]
    assert ds.attributes == {
        "substrate": ["flat"] * 4 + ["curved", "foam", "foam"],
        "cover": ["none"] * 4 + ["fur", "minkee", "minkee"],
        "set": ["training"] * 5 + ["test"] * 2}
    assert ds.sources[4] == "training.csv#capture5" and ds.sources[5] == \
        "testWITHLABELS.csv#capture1"
    rec = ds[4].recording
    assert rec.n_frames == 4 and rec.timestamps[1] == pytest.approx(1 / 54)
    assert rec.values[2].tolist() == [(52 + k) % 1024 for k in range(64)]
    assert ds.layout.name == "haart-8x8" and ds.layout.n_taxels == 64
    assert ds.normalisation.spec == "fixed:offset=0,scale=1023"
    assert ds.summary()["frame_rate_hz"] == 54.0
    assert ds.summary()["attributes"]["set"] == {"test": 2, "training": 5}


def test_captures_have_432_frames_by_default(tmp_path):
    ds = read_haart(small(tmp_path, frames=432))
    assert ds.lengths().tolist() == [432] * 7


def test_the_challenge_division_is_a_fixed_split_beside_people_out(tmp_path):
    ds = read_haart(small(tmp_path), frames=4)
    data = SplitData.of(ds)
    fixed = GroupSplit(key="set", test="test")
    assert fixed.design == "fixed" and fixed.spec == "group:set:test=test"
    a = fixed.split(data, seed=0)[0]
    assert a.test.tolist() == [5, 6] and a.train.tolist() == [0, 1, 2, 3, 4]
    assert fixed.split(data, seed=7)[0].test.tolist() == [5, 6]  # the same every seed
    # as a run draws it (checked against its declared design and group key)
    drawn = make_splits("group:set:test=test", labels=ds.labels, users=ds.users, seed=1,
                        groups={"set": ds.attributes["set"]})
    assert drawn[0].test.tolist() == [5, 6]
    for split in UsersSplit().split(data, seed=2):
        assert {ds.users[i] for i in split.train}.isdisjoint(ds.users[i] for i in split.test)


def test_gesture_spellings():
    assert [gesture_name(t) for t in ("Constant", "press", "No Touch", "notouch", "no_touch",
                                      " TICKLE ")] == \
        ["constant", "constant", "no-touch", "no-touch", "no-touch", "tickle"]
    assert gesture_name("hug") is None and len(GESTURES) == 7


def test_converted_once_then_read_from_the_store(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    folder = small(tmp_path)
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        first = HAART(path=str(folder), frames=4).load()
        again = HAART(path=str(folder), frames=4).load()
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "7 captures of 3 people, 2 gestures" in said[0]
    assert "at 54 Hz" in said[0] and "set: test, training" in said[0]
    assert again.content_hash() == first.content_hash()
    assert again.attributes == first.attributes


@pytest.mark.parametrize("edit, message", [
    (lambda t, s: (t, s[:-1]), r"testWITHLABELS.csv, line 6: capture 2 has 3 frames; "
                               r"HAART's have 4"),
    (lambda t, s: (t + capture("1", "flat", "none", "Pat"), s),
     r"training.csv, capture 6: participant 1, substrate flat, cover none, gesture Pat "
     r"again \(first as training.csv capture 1\): a duplicated capture"),
    (lambda t, s: (t, s + capture("1", "flat", "none", "pat")),
     r"testWITHLABELS.csv, capture 3: participant 1.*numbers its participants anew"),
    (lambda t, s: (t + capture("3", "flat", "none", "hug"), s),
     r"training.csv, line 22: gesture 'hug' is not one of HAART's 7"),
    (lambda t, s: (t, [r.replace(",9,", ",x,", 1) if i == 2 else r for i, r in enumerate(s)]),
     r"testWITHLABELS.csv, line 4: ch\d+ value 'x' is not a number"),
    (lambda t, s: (t, [",".join(r.split(",")[:-1]) if i == 2 else r
                       for i, r in enumerate(s)]),
     r"testWITHLABELS.csv, line 4: 67 fields; every HAART row has 68"),
])
def test_refusals_name_the_file_and_line(tmp_path, edit, message):
    training = [r for p in ("1", "2") for g in ("Pat", "Stroke")
                for r in capture(p, "flat", "none", g)]
    training += capture("2", "curved", "fur", "Pat", value=50)
    test = [r for g in ("Pat", "Stroke") for r in capture("9", "foam", "minkee", g)]
    folder = haart_folder(tmp_path, *edit(training, test))
    with pytest.raises(ValueError, match=message) as info:
        read_haart(folder, frames=4)
    assert "\n" not in str(info.value)


def test_refused_headers_and_folders(tmp_path):
    folder = haart_folder(tmp_path, capture("1", "a", "b", "pat"), capture("2", "a", "b", "pat"),
                          header=HEADER.replace("Cover,", ""))
    with pytest.raises(ValueError, match=r"training.csv, line 1: no column 'cover'"):
        read_haart(folder, frames=4)
    (folder / "testWITHLABELS.csv").unlink()
    with pytest.raises(FileNotFoundError, match="no testWITHLABELS.csv"):
        HAART(path=str(folder)).load()
    with pytest.raises(FileNotFoundError, match="no such folder"):
        read_haart(tmp_path / "absent")
    with pytest.raises(ValueError, match="frames"):
        HAART(path=str(folder), frames=-1)


def test_no_header_and_any_length(tmp_path):
    folder = haart_folder(tmp_path, capture("1", "a", "b", "pat", 3) + capture("1", "a", "b",
                                                                             "rub", 5),
                          capture("2", "a", "b", "pat", 2), header=None)
    ds = read_haart(folder, frames=0)
    assert ds.lengths().tolist() == [3, 5, 2] and ds.classes == ("pat", "rub")
    assert np.array_equal(ds[2].recording.values[1], np.arange(1, 65, dtype=np.float32))


def test_a_haart_folder_is_loaded_by_its_path(tmp_path):
    from tactbench.datasets.loading import detect_format, load_dataset

    folder = haart_folder(tmp_path, capture("1", "a", "b", "pat", 432),
                          capture("2", "a", "b", "pat", 432))
    assert detect_format(folder) == "haart"
    assert load_dataset(folder).attributes["set"] == ["training", "test"]


def with_frames(rows, frames):
    return [",".join(r.split(",")[:4] + [str(f)] + r.split(",")[4:]) for f, r in zip(frames, rows)]


def test_a_copy_with_a_frame_column(tmp_path):
    header = HEADER.replace("Gesture,", "Gesture, Frame,")
    training = with_frames(capture("1", "a", "b", "pat", 3) + capture("1", "a", "b", "rub", 3),
                           [1, 2, 3, 1, 2, 3])
    test = with_frames(capture("2", "a", "b", "pat", 3, value=9), [6, 7, 8])
    ds = read_haart(haart_folder(tmp_path, training, test, header=header), frames=3)
    assert ds.lengths().tolist() == [3, 3, 3] and ds.classes == ("pat", "rub")
    assert ds[2].recording.values[0].tolist() == [9 + k for k in range(64)]
    assert ds[2].recording.timestamps.tolist() == pytest.approx([0, 1 / 54, 2 / 54])
    # the frame restarts inside one participant, substrate, cover and gesture: two captures
    again = with_frames(capture("1", "a", "b", "pat", 6), [1, 2, 3, 1, 2, 3])
    with pytest.raises(ValueError, match="training.csv, capture 2: participant 1.*again"):
        read_haart(haart_folder(tmp_path, again, test, header=header), frames=3)
