"""Plugin loading never lets a plugin take a command down or garble its output: a plugin
that calls sys.exit or prints at import is reported by `tactbench plugins` and skipped
(`--json` stays valid JSON); an entry point named like a built-in plugin is reported,
not silently skipped (tactbench.plugins._load_entry_points)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

GOOD = """
from tactbench import hookimpl

@hookimpl
def register_encoders(register):
    register("{name}", "tactbench.encoders.simple:RawEncoder", summary="a copy of raw")
"""


def tactbench(*args):
    return subprocess.run([sys.executable, "-m", "tactbench", *args], capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("prelude, said", [
    ("import sys; sys.exit(3)", "SystemExit: exit status 3"),
    ("raise SystemExit('bye')", "SystemExit: exit status 'bye'"),
    ("print('hello from a plugin')", "printed to stdout when imported"),
])
def test_a_plugin_exiting_or_printing_at_import_is_reported_and_skipped(
        plugin_dist, prelude, said):
    plugin_dist("tb-hostile", "tb_hostile", prelude + "\n" + GOOD.format(name="hostile-raw"))
    listed = tactbench("plugins", "--json")
    assert listed.returncode == 0, listed.stderr
    rows = {row["name"]: row for row in json.loads(listed.stdout)["plugins"]}  # valid JSON
    assert said in json.dumps(rows["tb_hostile"])
    names = tactbench("list", "--json")
    assert names.returncode == 0, names.stderr
    assert "'hostile-raw'" not in json.dumps(json.loads(names.stdout).get("components"))
    listing = tactbench("list")
    assert listing.returncode == 0 and "tb_hostile" in listing.stderr  # a warning line


def test_an_entry_point_named_like_a_built_in_plugin_is_reported(plugin_dist):
    plugin_dist("tb-clash", "tb_clash", GOOD.format(name="clash-raw"),
                entry_name="tactbench.encoders")
    listed = tactbench("plugins", "--json")
    assert listed.returncode == 0, listed.stderr
    text = listed.stdout
    assert "has the name of a built-in plugin" in text and "tb-clash" in text
    rows = {row["name"]: row for row in json.loads(text)["plugins"]}
    assert rows["tactbench.encoders"]["distribution"] == "tactbench"  # the built-in kept
