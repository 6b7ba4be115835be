"""Live classification: incremental encoding equals full encoding; live = offline predictions."""

from __future__ import annotations

import threading
import uuid

import numpy as np
import pytest

from tactbench.classifiers.io import live_metadata
from tactbench.live import (
    IncrementalEncoder,
    LiveClassifier,
    LiveModel,
    reorder_index,
    run_summary,
)
from tactbench.plugins import load_registry

REGISTRY = load_registry()


def blob_sequence(t: int = 6, h: int = 20, w: int = 24, seed: int = 0) -> np.ndarray:
    """A Gaussian contact (σ 3 px) moving and pressing harder: float32 (T, H, W) in [0, 1]."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    cy, cx = rng.uniform(6, h - 6), rng.uniform(6, 10)
    seq = [np.exp(-((y - cy - 0.5 * k) ** 2 + (x - cx - 1.5 * k) ** 2) / (2 * 3.0 ** 2))
           * min(1.0, 0.3 + 0.15 * k) for k in range(t)]
    return np.clip(np.stack(seq), 0, 1).astype(np.float32)


@pytest.mark.parametrize("name", REGISTRY.names("encoder"))
def test_incremental_encoding_equals_full_encoding(name):
    """Frame k of encode(seq) == frame 1 of encode([I_{k-1}, I_k]), for every encoder."""
    comp = REGISTRY.get("encoder", name)
    if comp.missing_requirements():
        pytest.skip(f"{name} needs {comp.missing_requirements()}")
    encoder = REGISTRY.build("encoder", name)
    seq = blob_sequence()
    full = encoder.encode(seq)
    inc = IncrementalEncoder(encoder)
    stream = np.stack([inc.push(frame) for frame in seq])
    assert stream.shape == full.shape and stream.dtype == np.float32
    np.testing.assert_allclose(stream, full, atol=1e-5, rtol=0,
                               err_msg=f"{name}: incremental encoding differs")
    # and via the generic two-frame path, not only a flow shortcut
    pair = np.stack([encoder.encode(seq[k - 1:k + 1])[1] for k in range(1, len(seq))])
    np.testing.assert_allclose(pair, full[1:], atol=1e-5, rtol=0)
    inc.reset()
    np.testing.assert_allclose(inc.push(seq[0]), full[0], atol=1e-5, rtol=0)


# ------------------------------------------------------------- a tiny trained model

def tiny_dataset():
    """Two classes of contacts sliding left or right over an 8 × 8 taxel patch."""
    from tactbench.data.dataset import Dataset
    from tactbench.data.layout import TaxelLayout
    from tactbench.data.recording import Recording, Sample

    ids = np.array([m * 16 + s for m in range(1, 7) for s in range(11)])[:64]
    gy, gx = np.divmod(np.arange(64), 8)
    layout = TaxelLayout(ids=ids, positions=np.column_stack([gx, gy]) * 7.5, name="patch")
    rng = np.random.default_rng(3)
    samples = []
    for i in range(16):
        label = i % 2
        t = 6 + i % 3
        cx0 = 10.0 if label == 0 else 42.0
        vx = 5.0 if label == 0 else -5.0
        cy = rng.uniform(15, 40)
        frames = [20000 * np.exp(-((gx * 7.5 - cx0 - vx * k) ** 2 + (gy * 7.5 - cy) ** 2)
                                 / (2 * 8.0 ** 2)) for k in range(t)]
        values = np.round(np.stack(frames) + rng.uniform(0, 50, (t, 64))).astype(np.float32)
        rec = Recording(values=values, timestamps=0.1 * np.arange(t), taxel_ids=ids)
        samples.append(Sample(recording=rec, label=label, user=str(i % 4)))
    return Dataset("tiny", samples, ["right", "left"], layout=layout,
                   normalisation="fixed:scale=20000")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from tactbench.data.windows import training_windows

    dataset = tiny_dataset()
    encoder_spec, L, px = "frame-diff", 3, 5.0
    encoder = REGISTRY.build("encoder", encoder_spec)
    encoded = [encoder.encode(img) for img in dataset.images(pixel_mm=px)]
    train = training_windows(encoded, dataset.labels, L)
    clf = REGISTRY.build("classifier", "small-cnn-lstm:epochs=2,windows_per_epoch=0,input_size=16,width=4,"
                                       "layers=2,hidden=8,fc=16", classes=2)
    clf.fit(train, None, seed=0, device="cpu", progress=None)
    path = tmp_path_factory.mktemp("model") / "tiny.safetensors"
    clf.save(path, live_metadata(dataset, encoder=encoder_spec, L=L, pixel_mm=px))
    return dataset, encoded, path


def test_live_predictions_equal_offline_predictions(trained):
    dataset, encoded, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    assert model.classes == ["right", "left"] and model.L == 3
    live = LiveClassifier(model)
    sample = dataset.samples[5]
    preds = [live.push(v, t) for t, v in zip(sample.recording.timestamps,
                                             sample.recording.values)]
    assert preds[:2] == [None, None]  # warm-up: wait for L frames
    enc = encoded[5]
    windows = np.stack([enc[k - 2:k + 1] for k in range(2, len(enc))])
    offline = model.clf.predict_proba(windows)
    got = np.stack([p.probabilities for p in preds[2:]])
    np.testing.assert_allclose(got, offline, atol=1e-5)
    p = preds[-1]
    assert p.label == model.classes[int(np.argmax(offline[-1]))]
    assert p.confidence == pytest.approx(float(offline[-1].max()))
    assert p.frames == len(enc) and p.latency_ms > 0
    assert set(p.to_dict(model.classes)["probabilities"]) == {"right", "left"}


def test_cached_frame_features_give_the_same_predictions(trained):
    dataset, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    cached, plain = LiveClassifier(model), LiveClassifier(model, cache_features=False)
    assert cached.caches_features and not plain.caches_features
    for v in dataset.samples[7].recording.values:
        a, b = cached.push(v), plain.push(v)
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_allclose(a.probabilities, b.probabilities, atol=1e-5)


def test_pad_warmup_predicts_from_the_first_sweep(trained):
    dataset, encoded, path = trained
    live = LiveClassifier(LiveModel.from_file(path, registry=REGISTRY), warmup="pad")
    first = live.push(dataset.samples[0].recording.values[0])
    padded = np.zeros((1, 3, *encoded[0].shape[1:]), np.float32)
    padded[0, 0] = encoded[0][0]
    np.testing.assert_allclose(first.probabilities, live.model.clf.predict_proba(padded)[0],
                               atol=1e-5)


def test_live_over_the_virtual_bus(trained):
    """Simulated CAN traffic → cyskin-can sensor → predictions, same as from the array."""
    import can

    from tactbench.can.simulate import as_sim_sample, play, traffic
    from tactbench.sensors.cyskin_can import CySkinCAN

    dataset, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    sample = dataset.samples[2]
    direct = LiveClassifier(model)
    expected = [p for p in (direct.push(v) for v in sample.recording.values) if p is not None]
    channel = f"live-{uuid.uuid4().hex[:8]}"
    with CySkinCAN(channel=channel, taxel_ids=model.taxel_ids, idle_timeout=0.5) as sensor:
        def send():
            with can.Bus(interface="virtual", channel=channel) as bus:
                play(bus, traffic([as_sim_sample(sample, classes=dataset.classes)],
                                  sensor.taxel_map), speed=10)

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        preds = list(LiveClassifier(model).run(sensor.frames()))
        sender.join()
    assert [p.label for p in preds] == [p.label for p in expected]
    np.testing.assert_allclose([p.probabilities for p in preds],
                               [p.probabilities for p in expected], atol=1e-5)


def test_model_without_live_metadata_is_refused(trained, tmp_path):
    from tactbench.errors import TactbenchError

    _, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    bare = tmp_path / "bare.safetensors"
    model.clf.save(bare, {"note": "no live metadata"})
    with pytest.raises(TactbenchError, match="no 'classes'"):
        LiveModel.from_file(bare, registry=REGISTRY)
    with pytest.raises(ValueError, match="60 values"):
        LiveClassifier(model).push(np.zeros(60))
    with pytest.raises(TactbenchError, match="classifier expects frames"):
        LiveModel.from_file(path, registry=REGISTRY, encoder="raw")


# ------------------------------------------------------------- LiveClassifier.run

def test_run_reindexes_a_sensor_in_another_taxel_order(trained):
    """A sensor with the taxels shuffled (and one extra) predicts as the model's order."""
    from tactbench.can.assembler import Sweep

    dataset, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    values = dataset.samples[6].recording.values  # (T, 64) in the model's order
    direct = LiveClassifier(model)
    expected = [p for p in (direct.push(v) for v in values) if p is not None]
    perm = np.random.default_rng(0).permutation(values.shape[1])
    sensor_ids = np.append(model.taxel_ids[perm], 9999)  # 9999: a taxel the model lacks
    frames = [Sweep(timestamp=0.1 * k, values=np.append(v[perm], 123.0), sequence=k,
                    counter=k, missing=k % 2, first_timestamp=0.1 * k,
                    label="Twist" if k > 3 else None)
              for k, v in enumerate(values)]
    seen = []
    preds = list(LiveClassifier(model).run(frames, taxel_ids=sensor_ids,
                                           on_prediction=seen.append))
    assert [id(p) for p in seen] == [id(p) for p in preds]
    assert len(preds) == len(expected) == len(values) - 2
    np.testing.assert_allclose([p.probabilities for p in preds],
                               [p.probabilities for p in expected], atol=1e-6)
    assert [p.marker for p in preds] == [None, None] + ["Twist"] * (len(values) - 4)
    assert [p.missing for p in preds] == [k % 2 for k in range(2, len(values))]
    assert preds[-1].to_dict(model.classes)["marker"] == "Twist"
    assert "marker" not in preds[0].to_dict(model.classes)
    assert [p.timestamp for p in preds] == pytest.approx([0.1 * k for k in range(2, len(values))])


def test_run_stops_after_max_sweeps_and_summarises(trained):
    from tactbench.data.recording import Frame

    dataset, _, path = trained
    live = LiveClassifier(LiveModel.from_file(path, registry=REGISTRY))
    rec = dataset.samples[0].recording
    frames = (Frame(t, v) for t, v in zip(rec.timestamps, rec.values))
    preds = list(live.run(frames, max_sweeps=4))
    assert live.frames == 4 and len(preds) == 2
    summary = run_summary(live, [p.latency_ms for p in preds])
    assert summary["sweeps"] == 4 and summary["predictions"] == 2
    assert 0 < summary["latency_ms"]["p50"] <= summary["latency_ms"]["max"]
    assert "bus" not in summary
    assert run_summary(live, [])["latency_ms"] is None


def test_reorder_index():
    assert reorder_index([3, 1, 2], [3, 1, 2]) is None
    index = reorder_index([5, 3, 1, 2], [1, 2, 3])
    assert np.asarray([5, 3, 1, 2])[index].tolist() == [1, 2, 3]
    with pytest.raises(ValueError, match="the sensor lacks 2 of the model's taxels "
                                         r"\(first: 7, 8\)"):
        reorder_index([1, 2], [1, 7, 8])


def test_a_vector_model_of_either_rank_runs_live(tmp_path):
    """logreg takes images or vectors (frame_rank None): fitted on vectors, live feeds vectors."""
    from tactbench.data.windows import training_windows

    dataset = tiny_dataset()
    vectors = dataset.vectors()
    clf = REGISTRY.build("classifier", "logreg", classes=2)
    clf.fit(training_windows(vectors, dataset.labels, 3), None, seed=0, device="cpu",
            progress=None)
    path = tmp_path / "vectors.safetensors"
    clf.save(path, live_metadata(dataset, encoder="raw", L=3, pixel_mm=5.0))
    model = LiveModel.from_file(path, registry=REGISTRY)
    assert not model.uses_images
    preds = [p for p in LiveClassifier(model).run(
        _frames(dataset.samples[1].recording)) if p is not None]
    offline = clf.predict_proba(np.stack([vectors[1][k - 2:k + 1]
                                          for k in range(2, len(vectors[1]))]))
    np.testing.assert_allclose([p.probabilities for p in preds], offline, atol=1e-5)
    fewer = dict(model.info, taxel_ids=model.info["taxel_ids"][:60],
                 normalisation={"scale": 20000.0})
    fewer.pop("layout")
    from tactbench.errors import TactbenchError

    with pytest.raises(TactbenchError, match=r"expects taxel vectors \(64,\), the metadata "
                                         "names 60 taxels"):
        LiveModel.from_parts(clf, fewer, registry=REGISTRY)


def _frames(rec):
    from tactbench.data.recording import Frame

    return [Frame(t, v) for t, v in zip(rec.timestamps, rec.values)]


def test_live_metadata_records_what_live_needs(trained):
    from tactbench.classifiers.io import load_model
    from tactbench.data.layout_io import layout_from_dict

    dataset, _, path = trained
    _, meta = load_model(path, registry=REGISTRY)
    assert meta["classes"] == ["right", "left"] and meta["L"] == 3
    assert meta["encoder"] == "frame-diff" and meta["imaging"] == {"pixel_mm": 5.0,
                                                                   "method": "linear"}
    assert meta["taxel_ids"] == dataset.taxel_ids.tolist() and meta["dataset"] == "tiny"
    assert meta["normalisation"]["scale"] == 20000.0
    layout = layout_from_dict(meta["layout"], "test")
    np.testing.assert_array_equal(layout.positions, dataset.layout.positions)
    np.testing.assert_array_equal(layout.ids, dataset.layout.ids)


# ------------------------------------------------------------- the command line

def test_live_command_on_a_can_log(trained, tmp_path):
    import json

    from click.testing import CliRunner

    from tactbench.can.codec import TaxelMap
    from tactbench.can.logs import write_log
    from tactbench.can.simulate import as_sim_sample, schedule_messages, traffic
    from tactbench.cli import cli

    dataset, _, path = trained
    picked = [dataset.samples[i] for i in (0, 1)]
    log = tmp_path / "two.blf"
    write_log(log, schedule_messages(traffic([as_sim_sample(s, classes=dataset.classes)
                                              for s in picked], TaxelMap(dataset.taxel_ids))))
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor", "replay", str(log),
                                   "--json"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    n = sum(s.recording.n_frames for s in picked)
    assert doc["summary"]["sweeps"] == n
    # The window rolls across the two samples: one prediction per sweep after the first L - 1.
    assert doc["summary"]["predictions"] == n - 2
    assert [p["marker"] for p in doc["predictions"]][-1] == dataset.classes[picked[1].label]
    assert all(abs(sum(p["probabilities"].values()) - 1) < 1e-4 for p in doc["predictions"])
    # Human output: one line per prediction on stdout.
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor", "replay", str(log),
                                   "--max-sweeps", "4"], catch_exceptions=False)
    assert res.exit_code == 0 and len(res.stdout.strip().splitlines()) == 2
    # The window length is -L, as in `run`; the old --length is refused, naming it.
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor", "replay", str(log),
                                   "-L", "2", "--json"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["L"] == 2 and doc["summary"]["predictions"] == n - 1
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--length", "2"])
    assert res.exit_code == 2 and res.output.splitlines() == ["Error: --length is now -L"]


def test_live_command_on_the_virtual_bus(trained):
    import json

    import can
    from click.testing import CliRunner

    from tactbench.can.codec import TaxelMap
    from tactbench.can.simulate import as_sim_sample, play, traffic
    from tactbench.cli import cli

    dataset, _, path = trained
    channel = f"cli-{uuid.uuid4().hex[:8]}"
    sample = dataset.samples[4]

    done = threading.Event()

    def send():  # the sample over and over until the command has had its sweeps
        with can.Bus(interface="virtual", channel=channel) as bus:
            while not done.is_set():
                play(bus, traffic([as_sim_sample(sample, classes=dataset.classes)],
                                  TaxelMap(dataset.taxel_ids)), speed=20,
                     should_stop=done.is_set)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor",
                                       "cyskin-can:idle_timeout=5", "--channel", channel,
                                       "--max-sweeps", "8", "--jsonl"], catch_exceptions=False)
    finally:
        done.set()
        sender.join()
    assert res.exit_code == 0, res.output
    rows = [json.loads(line) for line in res.stdout.splitlines()]
    assert len(rows) == 8 - 2
    assert {r.get("marker") for r in rows} <= {dataset.classes[sample.label], None}
    assert all(r["latency_ms"] > 0 for r in rows)


def test_live_command_refuses_source_for_a_bus_sensor(trained):
    from click.testing import CliRunner

    from tactbench.cli import cli

    _, _, path = trained
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor", "cyskin-can",
                                   "some.blf"])
    assert res.exit_code != 0 and "SOURCE is only for '--sensor replay'" in res.output


def test_live_command_on_a_dataset_replay(trained, tmp_path):
    import json

    from click.testing import CliRunner

    from tactbench.cli import cli

    dataset, _, path = trained
    dataset.save(tmp_path / "tiny")
    res = CliRunner().invoke(cli, ["live", "--model", str(path), "--sensor",
                                   "replay:sample=3", str(tmp_path / "tiny"), "--jsonl"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    rows = [json.loads(line) for line in res.stdout.splitlines()]
    assert len(rows) == dataset.samples[3].recording.n_frames - 2
    assert all("marker" not in r for r in rows)  # a dataset sample carries no markers


# ------------------------------------------------------------- models that are refused


def _corrupted(src, dst, how):
    """A copy of model ``src`` spoiled ``how``: NaN weights (checksum recomputed, so the
    finite check is what refuses it), a flipped tensor byte, or 1 class name for a
    2-output network (a consistent file, as an old tactbench could write)."""
    import json

    from safetensors import safe_open
    from safetensors.torch import save_file

    from tactbench.classifiers.io import payload_digest

    if how == "flipped":
        data = bytearray(src.read_bytes())
        data[-5] ^= 0x01
        dst.write_bytes(bytes(data))
        return dst
    with safe_open(str(src), framework="pt") as f:
        h = json.loads(f.metadata()["tactbench"])
        t = {k: f.get_tensor(k).clone() for k in f.keys()}
    if how == "nan":
        name = next(k for k in sorted(t) if t[k].is_floating_point() and t[k].numel() > 1)
        t[name].view(-1)[0] = float("nan")
    else:
        h["metadata"]["classes"] = h["classes"] = ["right"]
    h["checksum"]["digest"] = payload_digest(h, t)
    save_file(t, str(dst), metadata={"tactbench": json.dumps(h)})
    return dst


@pytest.mark.parametrize("how, message", [
    ("nan", "holds 1 NaN or infinite value"),
    ("flipped", "checksum .* does not match"),
    ("classes", "lists 1 classes, but the network has 2 outputs"),
])
def test_live_command_refuses_a_bad_model_before_opening_the_sensor(trained, tmp_path,
                                                                    monkeypatch, how, message):
    import re

    from click.testing import CliRunner

    import tactbench.commands.live as live_command
    from tactbench.cli import cli

    _, _, path = trained
    bad = _corrupted(path, tmp_path / "bad.safetensors", how)

    def no_sensor(*args, **kwargs):
        raise AssertionError("the sensor was opened for a bad model")

    monkeypatch.setattr(live_command, "_build_sensor", no_sensor)
    res = CliRunner().invoke(cli, ["live", "--model", str(bad), "--sensor", "replay",
                                   str(tmp_path / "unused.blf")])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"Error: {bad}: ")
    assert re.search(message, lines[0])


def test_from_parts_refuses_class_names_that_do_not_fit_the_outputs(trained):
    from tactbench.errors import TactbenchError

    _, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    for classes in (["right"], ["right", "left", "up"]):
        with pytest.raises(TactbenchError, match=f"lists {len(classes)} classes, but the "
                                                 f"classifier has 2 outputs"):
            LiveModel.from_parts(model.clf, dict(model.info, classes=classes),
                                 registry=REGISTRY)
    with pytest.raises(TactbenchError, match="'classes' must be a list"):
        LiveModel.from_parts(model.clf, dict(model.info, classes="rl"), registry=REGISTRY)


def test_live_command_refuses_a_format_1_model(trained, tmp_path):
    """A model without a checksum cannot be verified: live cannot rebuild it, so refuses."""
    import json

    from click.testing import CliRunner
    from safetensors import safe_open
    from safetensors.torch import save_file

    from tactbench.cli import cli

    dataset, _, path = trained
    with safe_open(str(path), framework="pt") as f:
        h = json.loads(f.metadata()["tactbench"])
        t = {k: f.get_tensor(k) for k in f.keys()}
    h["version"] = 1
    for key in ("checksum", "classes", "cell"):
        h.pop(key)
    old = tmp_path / "old.safetensors"
    save_file(t, str(old), metadata={"tactbench": json.dumps(h)})
    folder = dataset.save(tmp_path / "ds")
    res = CliRunner().invoke(cli, ["live", "--model", str(old), "--sensor", "replay",
                                   str(folder), "--max-sweeps", "4"])
    assert res.exit_code == 2, res.output
    assert res.output.strip().splitlines() == [
        f"Error: {old}: model file of format 1 has no checksum and cannot be verified; "
        f"retrain it, or, if you trust it, read it with load_model(path, "
        f"allow_unverified=True) and save it again"]


@pytest.mark.parametrize("edit, message", [
    ({"normalisation": "fixed"}, "metadata 'normalisation' must be an object, got str"),
    ({"normalisation": {"offset": ["a"] * 64, "scale": 1.0}},
     "'normalisation.offset' must be a list of numbers"),
    ({"normalisation": {"offset": "0", "scale": 1.0}},
     "'normalisation.offset' must be a finite number"),
    ({"normalisation": {"offset": 0, "scale": 0}}, "'normalisation.scale' must be > 0"),
    ({"normalisation": {"offset": 0, "scale": float("nan")}},
     "'normalisation.scale' must be a finite number"),
    ({"imaging": [5.0]}, "metadata 'imaging' must be an object, got list"),
    ({"imaging": {"pixel_mm": "5"}}, "imaging pixel_mm must be a finite number"),
    ({"imaging": {"pixel_mm": 5.0, "method": 3}}, "'imaging.method' must be a name"),
    ({"L": "3"}, "window length L must be an integer"),
    ({"L": -2}, "window length L must be ≥ 1"),
    ({"encoder": 7}, "metadata 'encoder' must be an encoder spec"),
    ({"taxel_ids": [1.5] * 64}, "'taxel_ids' must hold integer taxel ids"),
    ({"taxel_ids": "0-63"}, "'taxel_ids' must be a list of numbers"),
])
def test_live_metadata_of_the_wrong_type_is_one_line(trained, edit, message):
    """Files of format 1 carry no checksum: their metadata is checked field by field."""
    from tactbench.errors import TactbenchError

    _, _, path = trained
    model = LiveModel.from_file(path, registry=REGISTRY)
    with pytest.raises(TactbenchError, match=message) as info:
        LiveModel.from_parts(model.clf, {**model.info, **edit}, registry=REGISTRY,
                             where="m.safetensors")
    assert str(info.value).startswith("m.safetensors: ") and "\n" not in str(info.value)


def test_frame_features_are_cached_only_for_a_classifier_whose_contract_offers_them():
    from tactbench.classifiers.classical import PooledLogReg
    from tactbench.classifiers.models import SmallCnnLstm
    from tactbench.live import _FeatureWindow

    assert _FeatureWindow.supported(SmallCnnLstm())
    assert not _FeatureWindow.supported(PooledLogReg())  # predict_proba on each window


def test_an_absurd_window_length_is_refused_by_the_memory_budget(trained, monkeypatch):
    """``live -L 100000`` on a model of images: the window and its batch are estimated
    and refused before the sensor opens, instead of allocating them sweep by sweep."""
    from tactbench.errors import BudgetError

    _, _, path = trained
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "64")
    model = LiveModel.from_file(path, registry=REGISTRY)
    with pytest.raises(BudgetError, match="live window of L = 100000 frames"):
        LiveModel.from_parts(model.clf, model.info, L=100_000, registry=REGISTRY)
    assert LiveModel.from_parts(model.clf, model.info, L=5, registry=REGISTRY).L == 5
