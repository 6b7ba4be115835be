"""The plugin API: hooks, discovery, load errors, duplicates, misspellings, building."""

from __future__ import annotations

import json
import subprocess
import sys
import types
from pathlib import Path

import click
import pytest

from tactbench import hookimpl, hookspecs
from tactbench.errors import (
    ComponentLoadError,
    ContractError,
    InputError,
    PluginError,
    UnknownComponentError,
)
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.specs import format_spec, parse_spec

GOOD_PLUGIN = """
    from tactbench import hookimpl

    @hookimpl
    def register_encoders(register):
        register("negate", "{mod}_impl:Negate", summary="1 - pressure")
"""

IMPL = """
    import numpy as np
    from tactbench.encoders.base import Encoder

    class Negate(Encoder):
        channels = ("inverted",)
        ranges = ((0.0, 1.0),)
        def __init__(self, *, gain: float = 1.0):
            self.gain = gain
        def _encode(self, seq):
            return (1.0 - seq)[:, None].astype(np.float32)
"""


def registry_with(*plugins, strict=False):
    """A registry of the built-ins plus ``(name, object)`` plugins, ignoring installed ones."""
    pm = make_plugin_manager(entry_points=False, strict=strict, extra=plugins)
    return collect_registry(pm)


def namespace(**hooks):
    return types.SimpleNamespace(**{name: hookimpl(fn) for name, fn in hooks.items()})


def run_cli(*args, env=None):
    import os

    full_env = {**os.environ, **(env or {})}
    return subprocess.run([sys.executable, "-m", "tactbench", *args], capture_output=True,
                          text=True, env=full_env, timeout=120)


# --------------------------------------------------------------------- one test per hook


def test_hook_register_sensors():
    def register_sensors(register):
        register("fake-sensor", "somewhere.sensor:Fake", summary="a sensor",
                 requires=("somewhere",))

    reg = registry_with(("p", namespace(register_sensors=register_sensors)))
    comp = reg.get("sensor", "fake-sensor")
    assert (comp.kind, comp.plugin, comp.requires) == ("sensor", "p", ("somewhere",))
    assert comp.missing_requirements() == ["somewhere"]
    with pytest.raises(ComponentLoadError, match="needs somewhere, which is not installed"):
        reg.build("sensor", "fake-sensor")


def test_hook_register_datasets():
    def register_datasets(register):
        # a second name for the built-in simulator's source class
        register("tiny", "tactbench.datasets.synthetic_forearm:SyntheticForearm",
                 summary="a dataset factory")

    reg = registry_with(("p", namespace(register_datasets=register_datasets)))
    assert "tiny" in reg.names("dataset")
    built = reg.build("dataset", "tiny:users=3")
    assert built.options["users"] == 3  # the target was imported and called with the options
    assert callable(built.load)  # and it satisfies the dataset contract


def test_hook_register_encoders(plugin_dist):
    plugin_dist("neg-dist", "negplug", GOOD_PLUGIN.format(mod="negplug"))
    import pathlib
    root = pathlib.Path(sys.path[0])
    (root / "negplug_impl.py").write_text(__import__("textwrap").dedent(IMPL))
    reg = collect_registry(make_plugin_manager())
    comp = reg.get("encoder", "negate")
    assert (comp.plugin, comp.distribution) == ("negplug", "neg-dist")
    enc = reg.build("encoder", "negate:gain=2")
    assert enc.gain == 2
    import numpy as np
    out = enc.encode(np.full((2, 3, 3), 0.25, np.float32))
    assert out.shape == (2, 1, 3, 3) and np.allclose(out, 0.75)


def test_hook_register_classifiers():
    def register_classifiers(register):
        register("majority", "collections:Counter", summary="a classifier")

    reg = registry_with(("p", namespace(register_classifiers=register_classifiers)))
    assert reg.get("classifier", "majority").target == "collections:Counter"


def test_hook_register_splits():
    import numpy as np

    from tactbench.data.splits import Split, make_splits

    class Halves:  # the first half of the recordings trains, the second tests
        spec = "halves"

        def split(self, data, *, seed):
            n = len(data.labels)
            test = np.arange(n // 2, n)
            return [Split(np.arange(n // 2), test, [str(i) for i in test])]

    module = types.ModuleType("halves_plugin")
    module.Halves = Halves
    sys.modules["halves_plugin"] = module
    try:
        def register_splits(register):
            register("halves", "halves_plugin:Halves", summary="a split")

        reg = registry_with(("p", namespace(register_splits=register_splits)))
        assert reg.get("split", "halves").plugin == "p"
        assert {"paper", "users", "group", "kfold"} <= set(reg.names("split"))
        [s] = make_splits("halves", labels=[0, 1] * 3, users=[""] * 6, seed=0, registry=reg)
        assert (s.train.tolist(), s.test.tolist(), s.fold) == ([0, 1, 2], [3, 4, 5], 0)
        with pytest.raises(ContractError, match="split 'halves' .*no method 'split'"):
            module.Halves = object
            reg.build("split", "halves")
    finally:
        del sys.modules["halves_plugin"]


def test_hook_register_test_windows():
    def register_test_windows(register):
        register("middle", "somewhere.windows:Middle", summary="a test window")

    reg = registry_with(("p", namespace(register_test_windows=register_test_windows)))
    comp = reg.get("test-window", "middle")
    assert (comp.kind, comp.plugin) == ("test-window", "p")
    assert {"first", "onset", "vote"} <= set(reg.names("test-window"))
    built = reg.build("test-window", "vote")
    assert callable(built.training) and callable(built.combine)
    with pytest.raises(ComponentLoadError, match="test-window 'middle'.*cannot import"):
        reg.build("test-window", "middle")


def test_hook_register_commands(plugin_dist):
    plugin_dist("cmd-dist", "cmdplug", """
        import click
        from tactbench import hookimpl

        @hookimpl
        def register_commands(cli):
            @cli.command()
            def hello():
                "Say hello."
                click.echo("hello from a plugin")
    """)
    result = run_cli("hello")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "hello from a plugin"
    assert "hello" in run_cli("--help").stdout


def _events_plugin(seen):
    return namespace(cell_finished=lambda row, out: seen.append(("cell", row["key"], out)),
                     run_finished=lambda summary, out: seen.append(("run", summary, out)),
                     look_finished=lambda look, out: seen.append(("look", look, out)))


def test_hook_cell_finished(tmp_path):
    seen = []
    reg = registry_with(("events", _events_plugin(seen)))
    reg.notify("cell_finished", row={"key": "k1"}, out=tmp_path)
    reg.settle()  # hooks run on their plugin's thread; settle waits for them
    assert seen == [("cell", "k1", tmp_path)]


def test_hook_look_finished(tmp_path):
    seen = []
    reg = registry_with(("events", _events_plugin(seen)))
    reg.notify("look_finished", look="R", out=tmp_path)
    reg.settle()
    assert seen == [("look", "R", tmp_path)]


def test_hook_run_finished(tmp_path):
    seen = []
    reg = registry_with(("events", _events_plugin(seen)))
    reg.notify("run_finished", summary="R", out=tmp_path)
    reg.settle()
    assert seen == [("run", "R", tmp_path)]


def test_an_event_hook_that_raises_is_a_warning_and_the_others_still_hear(tmp_path, caplog):
    seen = []

    def broken(row, out):
        raise RuntimeError("tracking server down")

    reg = registry_with(("broken", namespace(cell_finished=broken)),
                        ("events", _events_plugin(seen)))
    reg.notify("cell_finished", row={"key": "k1"}, out=tmp_path)
    reg.settle()
    assert seen == [("cell", "k1", tmp_path)]
    assert "tracking server down" in caplog.text and "the run goes on" in caplog.text
    strict = registry_with(("broken", namespace(cell_finished=broken)), strict=True)
    strict.notify("cell_finished", row={}, out=tmp_path)
    with pytest.raises(PluginError, match="tracking server down"):
        strict.settle()


def hook_names():
    """Every hook of tactbench.hookspecs: the register_* hooks and the events."""
    return [n for n in dir(hookspecs)
            if callable(getattr(hookspecs, n)) and hasattr(getattr(hookspecs, n),
                                                           "tactbench_spec")]


def test_hook_register_paired_tests():
    import numpy as np

    class Median:  # no interval worth the name: the runs' range, p from a sign test
        label = "median test"
        designs = ("fixed",)

        def test(self, d, *, ratio, confidence):
            return {"low": float(np.min(d)), "high": float(np.max(d)), "p": 0.5, "df": None}

    module = types.ModuleType("median_plugin")
    module.Median = Median
    sys.modules["median_plugin"] = module
    try:
        def register_paired_tests(register):
            register("median", "median_plugin:Median", summary="a paired test")

        reg = registry_with(("p", namespace(register_paired_tests=register_paired_tests)))
        assert reg.get("paired-test", "median").plugin == "p"
        assert {"corrected-t", "wilcoxon"} <= set(reg.names("paired-test"))
        assert reg.build("paired-test", "median").test(np.array([0.1, 0.3]), ratio=0,
                                                       confidence=0.95)["high"] == 0.3
        Median.designs = ("fixed", "daily")
        with pytest.raises(ContractError, match="paired-test 'median' .*'designs' must be"):
            reg.build("paired-test", "median")
    finally:
        del sys.modules["median_plugin"]


def test_every_hook_has_its_own_test():
    hooks = hook_names()
    assert len(hooks) == 11
    missing = [h for h in hooks if f"test_hook_{h}" not in globals()]
    assert not missing, f"hooks without a test: {missing}"


# --------------------------------------------------------------------- problems reported


BROKEN_ON_IMPORT = """
    raise RuntimeError("this plugin is broken on purpose")
"""


def test_plugin_that_fails_to_import_is_reported_and_skipped(plugin_dist):
    plugin_dist("broken-dist", "brokenplug", BROKEN_ON_IMPORT)
    result = run_cli("plugins", "--json")
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    broken = [p for p in doc["plugins"] if p["name"] == "brokenplug"]
    assert broken and broken[0]["distribution"] == "broken-dist"
    assert "this plugin is broken on purpose" in broken[0]["errors"][0]

    listed = run_cli("list", "--json")
    assert listed.returncode == 0
    names = {c["name"] for c in json.loads(listed.stdout)["components"]}
    assert {"raw", "frame-diff"} <= names
    assert "brokenplug" in listed.stderr  # a one-line warning, stdout stays pure JSON


def test_strict_mode_makes_a_broken_plugin_fatal(plugin_dist):
    plugin_dist("broken-dist", "brokenplug2", BROKEN_ON_IMPORT)
    result = run_cli("list", env={"TACTBENCH_STRICT_PLUGINS": "1"})
    assert result.returncode != 0
    assert "brokenplug2" in result.stderr and "broken on purpose" in result.stderr
    with pytest.raises(PluginError, match="brokenplug2"):
        make_plugin_manager(strict=True)


def test_hook_that_raises_skips_only_that_plugin():
    def bad(register):
        register("half-done", "x.y:Z", summary="registered before the failure")
        raise KeyError("boom")

    reg = registry_with(("bad", namespace(register_encoders=bad)))
    assert "half-done" not in reg.names("encoder")  # all or nothing per hook call
    assert "raw" in reg.names("encoder")
    (problem,) = reg.problems
    assert problem.plugin == "bad" and "register_encoders raised KeyError" in problem.message


def test_duplicate_names_name_both_plugins():
    def first(register):
        register("same", "a.b:C", summary="first")

    def second(register):
        register("same", "d.e:F", summary="second")

    reg = registry_with(("one", namespace(register_encoders=first)),
                        ("two", namespace(register_encoders=second)))
    assert reg.get("encoder", "same").plugin == "one"
    (problem,) = reg.problems
    text = str(problem)
    assert "'same'" in text and "'one'" in text and "'two'" in text
    with pytest.raises(PluginError, match="already registered by plugin 'one'"):
        registry_with(("one", namespace(register_encoders=first)),
                      ("two", namespace(register_encoders=second)), strict=True)


def test_duplicate_of_a_builtin_cannot_replace_it():
    def hijack(register):
        register("raw", "a.b:C", summary="pretends to be raw")

    reg = registry_with(("hijack", namespace(register_encoders=hijack)))
    assert reg.get("encoder", "raw").plugin == "tactbench.encoders"
    assert "already registered" in reg.problems[0].message


def test_misspelled_hook_is_reported():
    def register_encoder(register):  # missing the final "s"
        register("never", "a.b:C", summary="never called")

    reg = registry_with(("typo", namespace(register_encoder=register_encoder)))
    (problem,) = reg.problems
    assert "unknown hook 'register_encoder'" in problem.message
    assert "did you mean 'register_encoders'" in problem.message
    with pytest.raises(PluginError, match="register_encoder"):
        registry_with(("typo", namespace(register_encoder=register_encoder)), strict=True)


def test_hook_with_wrong_arguments_is_reported():
    def register_encoders(registrar):  # not an argument of the spec
        pass

    reg = registry_with(("wrongargs", namespace(register_encoders=register_encoders)))
    assert reg.problems and "registrar" in reg.problems[0].message


def test_target_that_does_not_import_gives_a_clear_error():
    def register_encoders(register):
        register("ghost", "no_such_module_anywhere.sub:Ghost", summary="missing code")

    reg = registry_with(("g", namespace(register_encoders=register_encoders)))
    with pytest.raises(ComponentLoadError) as err:
        reg.build("encoder", "ghost")
    msg = str(err.value)
    assert "encoder 'ghost'" in msg and "plugin 'g'" in msg
    assert "no_such_module_anywhere.sub:Ghost" in msg and "ModuleNotFoundError" in msg


@pytest.mark.parametrize("args, message", [
    (("Bad Name", "a.b:C"), "name 'Bad Name' is invalid"),
    (("ok", "a.b.C"), "must look like 'package.module:Attribute'"),
    (("ok", "a.b:C", ""), "summary must be a non-empty string"),
])
def test_register_validates_its_arguments(args, message):
    def register_encoders(register):
        name, target, *summary = args
        register(name, target, summary=summary[0] if summary else "fine")

    reg = registry_with(("v", namespace(register_encoders=register_encoders)))
    assert message in reg.problems[0].message


# --------------------------------------------------------------------- names and options


def test_unknown_name_suggests_the_closest():
    reg = registry_with()
    with pytest.raises(UnknownComponentError, match="did you mean 'frame-diff'") as err:
        reg.get("encoder", "frame-dif")
    assert "raw" in str(err.value)


def test_unknown_option_lists_accepted_options(plugin_dist):
    reg = registry_with()
    with pytest.raises(ValueError, match="encoder 'raw' has no option 'winsize'"):
        reg.build("encoder", "raw:winsize=3")


@pytest.mark.parametrize("spec, expected", [
    ("farneback", ("farneback", {})),
    ("farneback:winsize=9,levels=2", ("farneback", {"winsize": 9, "levels": 2})),
    ("x:a=0.5,b=true,c=none,d=text", ("x", {"a": 0.5, "b": True, "c": None, "d": "text"})),
    (" x : a = 1 ", ("x", {"a": 1})),
])
def test_parse_spec(spec, expected):
    assert parse_spec(spec) == expected


@pytest.mark.parametrize("spec", ["", ":a=1", "x:a,b", "x:1a=2", "x:a=1,,b=2"])
def test_parse_spec_rejects_malformed(spec):
    with pytest.raises(ValueError):
        parse_spec(spec)


@pytest.mark.parametrize("spec, match", [
    ("farneback:winsize=9,winsize=11", "option 'winsize' is given twice in "
                                       "'farneback:winsize=9,winsize=11'"),
    ("x:a=1, a =1", "option 'a' is given twice"),
])
def test_an_option_given_twice_is_refused_not_overridden(spec, match):
    with pytest.raises(InputError, match=match):
        parse_spec(spec)


@pytest.mark.parametrize("spec", [1, None, ["raw"], {"raw": 1}, 1.5, True])
def test_a_spec_that_is_not_text_is_one_clear_error(spec):
    with pytest.raises(InputError, match="a component is named by text"):
        parse_spec(spec)


def test_format_spec_round_trips():
    name, opts = parse_spec("farneback:winsize=9,levels=2,fast=true,pyr=0.5")
    assert parse_spec(format_spec(name, opts)) == (name, opts)


def _group_with(*plugins):
    """A fresh ``tactbench`` group and a context whose plugin manager holds the built-ins
    and ``(name, object)`` plugins."""
    from tactbench.cli import TactbenchGroup

    pm = make_plugin_manager(entry_points=False, extra=plugins)
    group = TactbenchGroup(name="tactbench")
    return group, click.Context(group, obj={"pm": pm}), pm


def test_plugin_commands_cannot_replace_builtin_commands():
    def register_commands(cli):
        @cli.command("list")
        def fake():
            pass

    group, ctx, pm = _group_with(("x", namespace(register_commands=register_commands)))
    group.list_commands(ctx)
    assert group.get_command(ctx, "list").callback.__module__ == "tactbench.commands.inspect"
    assert any(p.plugin == "x" and "command 'list' is already registered by plugin "
               "'tactbench.commands'" in p.message for p in pm.problems)


def test_a_command_hook_that_raises_adds_no_command():
    def register_commands(cli):
        @cli.command("half")
        def half():
            pass
        raise RuntimeError("broken after one command")

    group, ctx, pm = _group_with(("x", namespace(register_commands=register_commands)))
    assert "half" not in group.list_commands(ctx) and "run" in group.list_commands(ctx)
    assert any(p.plugin == "x" and "broken after one command" in p.message
               for p in pm.problems)


def test_a_plugin_can_add_a_lazy_command_too(tmp_path, monkeypatch):
    """``cli.add_lazy_command`` keeps a plugin's module out of ``--help``, as the
    built-ins' are; the command is imported when it runs."""
    (tmp_path / "lazyplug_cmd.py").write_text(
        "import click\n\n@click.command('hi')\ndef hi():\n    \"Say hi.\"\n"
        "    click.echo('hi there')\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    def register_commands(cli):
        cli.add_lazy_command("hi", "lazyplug_cmd:hi", summary="Say hi.")

    group, ctx, _pm = _group_with(("x", namespace(register_commands=register_commands)))
    help_text = group.get_help(ctx)
    assert "Say hi." in help_text and "lazyplug_cmd" not in sys.modules
    assert group.get_command(ctx, "hi").callback.__module__ == "lazyplug_cmd"
    monkeypatch.delitem(sys.modules, "lazyplug_cmd")


def test_hook_reference_documents_every_hook_with_its_signature():
    import inspect

    REPO = Path(__file__).resolve().parents[1]

    doc = (REPO / "docs" / "plugins.md").read_text()
    for name in hook_names():
        params = ", ".join(inspect.signature(getattr(hookspecs, name)).parameters)
        assert f"### `{name}({params})`" in doc, f"docs/plugins.md lacks hook {name}"


def test_a_bare_leading_value_fills_the_components_positional_option():
    from tactbench.plugins import load_registry
    from tactbench.specs import POSITIONAL, parse_spec

    assert parse_spec("sklearn:SVC,C=10") == ("sklearn", {POSITIONAL: "SVC", "C": 10})
    with pytest.raises(InputError, match="bad option 'C' in"):
        parse_spec("sklearn:SVC,C")  # only the first item may be bare
    registry = load_registry()
    assert registry.resolve("classifier", "sklearn:SVC,C=10") == "sklearn:C=10,estimator=SVC"
    assert registry.resolve("encoder", "farneback:winsize=9") == "farneback:winsize=9"
    with pytest.raises(InputError, match="encoder 'farneback' takes no value without a name"):
        registry.build("encoder", "farneback:9")
    with pytest.raises(InputError, match="option 'estimator' is given twice"):
        registry.build("classifier", "sklearn:SVC,estimator=SVC")


def test_the_names_plugin_authors_import_keep_their_place():
    """The plugin layer is three modules (loader, registry, spec grammar); what the docs
    tell plugin authors to import is where they say."""
    import tactbench
    import tactbench.testing as face
    from tactbench import plugins, registry, specs
    from tactbench.classifiers.conformance import check_classifier
    from tactbench.encoders.evaluation.conformance import check_encoder, conformance_cases

    assert tactbench.hookimpl.project_name == plugins.ENTRY_POINT_GROUP == "tactbench"
    assert plugins.Registry is registry.Registry and plugins.Component is registry.Component
    assert callable(plugins.make_plugin_manager) and callable(plugins.load_registry)
    assert (face.check_encoder, face.check_classifier, face.conformance_cases) == (
        check_encoder, check_classifier, conformance_cases)
    assert specs.format_spec(*specs.parse_spec("dis:preset=fast,a=1")) == "dis:a=1,preset=fast"
