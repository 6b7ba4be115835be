"""load_dataset: one entry point for registered datasets and paths."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.datasets.loading import detect_format, load_dataset
from tactbench.errors import UnknownComponentError
from tactbench.plugins import load_registry


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def test_registered_name_with_options(registry):
    ds = load_dataset("synthetic-forearm:users=2,repetitions=1", registry=registry)
    assert isinstance(ds, Dataset) and len(ds) == 20


def test_dataset_folder_and_its_manifest(tmp_path):
    rec = Recording(np.ones((3, 2)), [0, 0.1, 0.2], [1, 2])
    Dataset("saved", [Sample(rec, 0)], ("a",)).save(tmp_path / "d")
    assert detect_format(tmp_path / "d") == "dataset"
    assert load_dataset(str(tmp_path / "d")).name == "saved"
    assert load_dataset(tmp_path / "d" / "manifest.json").name == "saved"


def test_cyskin_text_file_and_folder(tmp_path):
    folder = tmp_path / "cls"
    folder.mkdir()
    (folder / "a.txt").write_text("1 2\n0 0 1 2\n1 0.1 3 4\n")
    assert load_dataset(folder / "a.txt").classes == ("cls",)
    assert len(load_dataset(str(tmp_path))) == 1


def test_cost_csv(tmp_path):
    from tactbench.datasets.cost import COLUMNS

    path = tmp_path / "c.csv"
    path.write_text(",".join(COLUMNS) + "\n" + "".join(
        ",".join(["1", "gentle", "pat", str(frame)] + ["5"] * 64) + "\n" for frame in (0, 1)))
    assert load_dataset(path).classes == ("pat",)


def test_unknown_things(tmp_path, registry):
    with pytest.raises(FileNotFoundError, match="no such file or folder"):
        load_dataset(str(tmp_path / "absent"), registry=registry)
    with pytest.raises(FileNotFoundError):
        load_dataset("./nothing/here.txt", registry=registry)
    with pytest.raises(UnknownComponentError, match="did you mean 'synthetic-forearm'"):
        load_dataset("synthetic-forarm", registry=registry)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="neither a tactbench dataset folder"):
        load_dataset(tmp_path / "empty")
    (tmp_path / "x.bin").write_bytes(b"1")
    with pytest.raises(ValueError, match="unknown data format '.bin'"):
        load_dataset(tmp_path / "x.bin")


def test_the_real_fingers_set_by_path(shared_data):
    ds = load_dataset(shared_data / "cyskin-fingers")
    assert len(ds) == 373 and ds.layout is None


def test_a_can_log_of_cyskin_traffic(tmp_path):
    pytest.importorskip("can")
    from tactbench.can.codec import TaxelMap
    from tactbench.can.logs import write_log
    from tactbench.can.simulate import as_sim_sample, schedule_messages, traffic

    ids = np.array([16, 17, 18, 32, 33], dtype=np.int64)
    samples = [Sample(Recording(np.full((3, 5), 100.0 * (k + 1)), [0, 0.1, 0.2], ids), k,
                      user="u1") for k in range(2)]
    sims = [as_sim_sample(s, classes=("a", "b")) for s in samples]
    write_log(tmp_path / "s.asc", schedule_messages(traffic(sims, TaxelMap(ids))))
    assert detect_format(tmp_path / "s.asc") == "can-log"
    ds = load_dataset(tmp_path / "s.asc")
    assert ds.classes == ("a", "b") and len(ds) == 2
    assert np.array_equal(ds[1].recording.values, samples[1].recording.values)


PLAIN_PLUGIN = '''
import numpy as np
from tactbench import hookimpl
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample

class Plain:
    """A dataset written against the documented contract: load() takes nothing."""
    def load(self):
        rec = Recording(np.ones((2, 3)), [0.0, 0.1], [1, 2, 3])
        return Dataset("plain", [Sample(rec, 0)], ("a",))

class NotData:
    def load(self):
        return [1, 2, 3]

@hookimpl
def register_datasets(register):
    register("plain", "tb_c2_datasets:Plain", summary="load() without progress")
    register("not-data", "tb_c2_datasets:NotData", summary="load() returns a list")
'''


@pytest.fixture
def plugin_registry(tmp_path, monkeypatch):
    import importlib

    from tactbench.plugins import collect_registry, make_plugin_manager

    (tmp_path / "tb_c2_datasets.py").write_text(PLAIN_PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("tb_c2_datasets")
    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("tb_c2_datasets", module)]))


def test_progress_reaches_datasets_whose_load_takes_it(tmp_path, monkeypatch, registry):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path))
    calls = []
    ds = load_dataset("synthetic-forearm:users=1,repetitions=1,positions=1", registry=registry,
                      progress=lambda done, total, **info: calls.append((done, total)))
    assert len(ds) == 5 and calls[-1] == (5, 5)


def test_progress_is_not_forced_on_a_plain_load(plugin_registry):
    calls = []
    ds = load_dataset("plain", registry=plugin_registry,
                      progress=lambda done, total, **info: calls.append(done))
    assert ds.name == "plain" and calls == []


def test_a_load_that_returns_no_dataset_breaks_the_contract(plugin_registry):
    from tactbench.errors import ContractError

    with pytest.raises(ContractError, match="dataset 'not-data': load.. returned list"):
        load_dataset("not-data", registry=plugin_registry)
