"""Every command that writes goes through the one output rule (tactbench.paths:
check_output_file / check_output_folder / check_out_folder), found FROM THE CLI ITSELF:
every option named --out/--output/-o or of a click.Path type with writable=True, of
every command. For each: a file tactbench did not write is never replaced, nothing is
written inside the cache folder, the command's own input is never its output; two
writers into one new folder: one wins whole, the other is refused (paths.publish_folder).
A new writing command fails the first test until it is added to WRITERS."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import threading
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import InputError
from tactbench.paths import cache_root, publish_folder

#: (command path, option) → how to call it: ``args`` ({out}, {input} filled in), whether
#: it writes a ``file`` or a ``folder``, what it writes (the file itself, or names in the
#: folder), and whether {input} may be given as the output.
WRITERS: dict[tuple[str, str], dict] = {
    ("can record", "--out"): dict(args=["can", "record", "--out", "{out}", "--duration",
                                        "0.1"], kind="file", suffix=".asc"),
    ("can simulate", "--out"): dict(args=["can", "simulate", "{input}", "--out", "{out}",
                                          "--speed", "0"], kind="file", suffix=".asc",
                                    input="log"),
    ("data import", "--out"): dict(args=["data", "import", "{input}", "--out", "{out}"],
                                   kind="folder", writes="manifest.json", input="dataset"),
    ("data preview", "--out"): dict(args=["data", "preview", "{input}", "--out", "{out}"],
                                    kind="file", suffix=".png", input="dataset"),
    ("data synth", "--out"): dict(args=["data", "synth", "--out", "{out}", "--users", "1",
                                        "--repetitions", "1", "--positions", "1"],
                                  kind="folder", writes="manifest.json"),
    ("encode", "--out"): dict(args=["encode", "-i", "{input}", "-o", "{out}", "-e", "raw"],
                              kind="file", suffix=".npy", input="npy"),
    ("flowbench", "--out"): dict(args=["flowbench", "--out", "{out}", "-e", "farneback",
                                       "--size", "16x16", "--repeats", "1"],
                                 kind="folder", writes="flowbench.json"),
    ("layout generate", "--out"): dict(args=["layout", "generate", "--out", "{out}",
                                             "--taxels", "16"], kind="file", suffix=".csv"),
    ("reproduce", "--out"): dict(args=["reproduce", "{input}", "--out", "{out}"],
                                 kind="folder", writes="part1", input="dataset"),
    ("run", "--out"): dict(args=["run", "--dataset", "{input}", "--encoder", "raw",
                                 "--classifier", "logreg", "--out", "{out}"],
                           kind="folder", writes="report.md", input="dataset"),
}


def writing_options() -> set[tuple[str, str]]:
    """(command path, option) of every option that names something a command writes."""
    found: set[tuple[str, str]] = set()

    def walk(cmd: click.Command, path: list[str], ctx: click.Context) -> None:
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name], ctx)
            return
        for param in cmd.params:
            if not isinstance(param, click.Option):
                continue
            named = {"--out", "--output", "-o"} & set(param.opts)
            writable = isinstance(param.type, click.Path) and param.type.writable
            if named or writable:
                long = next(o for o in param.opts if o.startswith("--"))
                found.add((" ".join(path), long))

    walk(cli, [], click.Context(cli))
    return found


#: Options named like a writer's that only read: ``plan --out`` reads a pilot's rows from
#: the folder a run would write (tested below: it writes nothing there).
READS_ONLY = {("plan", "--out")}


def test_every_writing_option_of_the_cli_is_covered():
    assert writing_options() - READS_ONLY == set(WRITERS), \
        "a command writes through an option these tests do not cover: add it to WRITERS"


def test_plan_writes_nothing_into_its_out_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own")
    result = CliRunner().invoke(cli, ["plan", "--dataset", "synthetic-forearm:users=1",
                                      "--encoder", "raw", "--classifier", "logreg",
                                      "--out", str(out)])
    assert [p.name for p in out.iterdir()] == ["notes.txt"], result.output


def hashes(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """One input of each kind a writer reads: a dataset folder, a CAN log, a sequence."""
    from tactbench.data.dataset import Dataset
    from tactbench.data.layout import TaxelLayout
    from tactbench.data.recording import Recording, Sample

    root = tmp_path_factory.mktemp("inputs")
    rng = np.random.default_rng(0)
    layout = TaxelLayout.grid(3, 3, 5.0)
    samples = [Sample(Recording(rng.random((6, 9)).astype(np.float32),
                                np.arange(6) * 0.1, layout.ids), i % 2, user=f"u{i % 2}")
               for i in range(8)]
    Dataset("tiny", samples, ("a", "b"), layout).save(root / "dataset")
    np.save(root / "seq.npy", rng.random((3, 6, 6)).astype(np.float32))
    log = root / "traffic.asc"
    made = CliRunner().invoke(cli, ["can", "simulate", str(root / "dataset"), "--out",
                                    str(log), "--speed", "0"])
    assert made.exit_code == 0, made.output
    return {"dataset": root / "dataset", "npy": root / "seq.npy", "log": log}


def call(spec: dict, out: Path, inputs: dict) -> "click.testing.Result":
    given = str(inputs[spec["input"]]) if "input" in spec else ""
    args = [a.replace("{out}", str(out)).replace("{input}", given) for a in spec["args"]]
    return CliRunner().invoke(cli, args)


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_file_tactbench_did_not_write_is_never_replaced(tmp_path, inputs, writer):
    spec = WRITERS[writer]
    if spec["kind"] == "file":
        out = tmp_path / f"mine{spec['suffix']}"
        out.write_bytes(b"the user's own file")
        mine = out
    else:
        out = tmp_path / "folder"
        out.mkdir()
        mine = out / spec["writes"]
        mine.write_bytes(b"the user's own file")
    result = call(spec, out, inputs)
    assert result.exit_code == 2, result.output
    assert mine.read_bytes() == b"the user's own file"
    assert result.output.strip().splitlines()[-1].startswith("Error:"), result.output


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_nothing_is_written_inside_the_cache_folder(tmp_path, inputs, writer):
    spec = WRITERS[writer]
    root = cache_root()
    root.mkdir(parents=True, exist_ok=True)
    before = hashes(root)
    out = root / "sub" / ("out" + spec.get("suffix", ""))
    result = call(spec, out, inputs)
    assert result.exit_code == 2 and "cache folder" in result.output, result.output
    assert not (root / "sub").exists() and hashes(root) == before


@pytest.mark.parametrize("writer", sorted(w for w in WRITERS if "input" in WRITERS[w]))
def test_a_command_never_writes_over_its_own_input(tmp_path, inputs, writer):
    spec = WRITERS[writer]
    given = inputs[spec["input"]]
    before = hashes(given) if given.is_dir() else given.read_bytes()
    result = call(spec, given, inputs)
    assert result.exit_code == 2, result.output
    assert (hashes(given) if given.is_dir() else given.read_bytes()) == before


def test_two_writers_into_one_new_folder_one_wins_whole_the_other_is_refused(tmp_path):
    target = tmp_path / "new"
    entered = threading.Barrier(2)
    outcome: dict[str, object] = {}

    def write(name: str, delay: float) -> None:
        try:
            with publish_folder(target) as tmp:
                entered.wait()  # both have checked and started before either finishes
                (tmp / "who").write_text(name)
                (tmp / "payload").write_bytes(name.encode() * 1000)
                threading.Event().wait(delay)
            outcome[name] = "won"
        except InputError as exc:
            outcome[name] = str(exc)

    threads = [threading.Thread(target=write, args=(n, d)) for n, d in (("a", 0), ("b", .3))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert outcome["a"] == "won" and "filled by another process" in str(outcome["b"])
    assert (target / "who").read_text() == "a"
    assert (target / "payload").read_bytes() == b"a" * 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new"]  # no temporaries left


def test_two_data_synth_runs_into_one_new_folder_leave_one_whole_dataset(tmp_path):
    from tactbench.data.dataset import Dataset

    out = tmp_path / "synth"
    cmd = [sys.executable, "-m", "tactbench", "data", "synth", "--out", str(out),
           "--users", "1", "--repetitions", "1", "--positions", "1"]
    procs = [subprocess.Popen([*cmd, "--seed", str(seed)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=os.environ.copy())
             for seed in (1, 2)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    winner = next(err for code, err in results if code == 0)
    loser = next(err for code, err in results if code == 2)
    said = loser.strip().splitlines()[-1]  # after its progress lines: one error line
    assert said.startswith("Error:") and ("filled by another process" in said
                                          or "already holds" in said), loser
    stored = Dataset.load(out)  # verifies its content hash against the arrays
    assert f"content hash {stored.content_hash()[:16]}" in winner
    assert sorted(p.name for p in tmp_path.iterdir()) == ["synth"]
