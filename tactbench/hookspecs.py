"""The tactbench plugin API: the hooks a plugin may implement.

A plugin is any module (or object) with functions marked ``@tactbench.hookimpl``
whose names are hooks below. Installed plugins are found through the
entry-point group ``tactbench``; built-in components use the same hooks.

The ``register_*`` hooks of components receive one argument, ``register``, a callable::

    register(name, target, *, summary, requires=())

``name``
    the component's name on the command line (``farneback``); lower case
    letters, digits, ``-``, ``_`` and ``.``.
``target``
    ``"module.path:Attribute"``. Nothing is imported until the component is
    built, so a plugin's hook module must stay light.
``summary``
    one line shown by ``tactbench list``.
``requires``
    top-level modules the component needs (``("cv2",)``); ``tactbench list``
    shows whether each is installed.

This signature is public and stable: new keyword arguments may be added, with
defaults, but none will be removed or made mandatory.
"""

from __future__ import annotations

import pluggy

hookspec = pluggy.HookspecMarker("tactbench")


@hookspec
def register_sensors(register):
    """Register sensors: classes that stream frames ``(timestamp, values (N,))``."""


@hookspec
def register_datasets(register):
    """Register datasets: callables returning a labelled set of recordings."""


@hookspec
def register_encoders(register):
    """Register image encoders: ``(T, H, W)`` float32 → ``(T, C, H, W)`` float32."""


@hookspec
def register_classifiers(register):
    """Register classifiers: ``fit`` on encoded windows, ``predict`` class indices."""


@hookspec
def register_splits(register):
    """Register splits: ``split(data, *, seed)`` → train/test index sets, one per fold."""


@hookspec
def register_test_windows(register):
    """Register test windows: a recording's windows, and how their predictions combine."""


@hookspec
def register_paired_tests(register):
    """Register paired tests: ``test(d, *, ratio, confidence)`` → interval and p of the
    per-run differences, valid for the designs it declares (``--paired-test NAME``)."""


@hookspec
def register_commands(cli):
    """Add commands to the ``tactbench`` click group ``cli``."""


# ------------------------------------------------------------------ events
#
# Called while a benchmark runs, by ``tactbench run`` (with ``--until`` too) and by
# :func:`tactbench.runner.run`, in the process that stores the rows, each plugin on a
# thread of its own with its own copy of the arguments (:mod:`tactbench.events`). A hook
# that raises or calls sys.exit is reported once as a warning and the run goes on (with
# ``TACTBENCH_STRICT_PLUGINS=1`` it ends); one that does not return within
# ``TACTBENCH_HOOK_TIMEOUT`` seconds is reported and abandoned.


@hookspec
def cell_finished(row, out):
    """A cell's row was stored in ``out/cells`` (verified, ok or failed): ``row`` as stored
    (a dict, results.json's ``rows[]``), ``out`` the run folder (a ``Path``)."""


@hookspec
def look_finished(look, out):
    """A look of ``run --until answered`` ended and wrote its report: ``look`` is its
    record (a dict of plain values, :func:`~tactbench.runner.analysis.records.look_record`:
    ``look``, ``runs``, ``answered``, ``stopped``, ``decisions``, ``rows`` as stored and
    ``comparisons``, each a :func:`~tactbench.runner.comparison_record`, and ``record``,
    the run's resolved record, :meth:`~tactbench.runner.RunRecord.to_json`), ``out`` the
    run folder."""


@hookspec
def run_finished(summary, out):
    """A run ended and wrote its report, once per run (``tactbench run``,
    :func:`tactbench.runner.run`, and ``run --until answered`` after its last look):
    ``summary`` is its record (a dict of plain values,
    :func:`~tactbench.runner.analysis.records.run_summary`: ``rows`` as stored,
    ``comparisons``, the keys ``ok`` and ``failed``, ``computed``, ``skipped``,
    ``seconds``, ``until``: the last look of ``--until answered``, None for a plain
    run, and ``record``: the run's resolved record, as ``look_finished``'s), ``out`` the
    run folder. The place to close what ``cell_finished`` opened (a
    tracking run)."""
