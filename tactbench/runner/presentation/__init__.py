"""The runner's third room, **presentation**: numbers and verdicts shown, none decided.

Terminal and Markdown tables (:mod:`~tactbench.runner.presentation.tables`, the mark of a
cell that did not learn in :mod:`~tactbench.runner.presentation.marks`), the figures
(:mod:`~tactbench.runner.presentation.plots`), a folder's report files
(:mod:`~tactbench.runner.presentation.writers`: ``render``, the ``Report`` of an
:class:`~tactbench.runner.analysis.report.Analysis`, results.json/csv, report.md), a
finding in words (:mod:`~tactbench.runner.presentation.words`) and pandas data frames and
Parquet (:mod:`~tactbench.runner.presentation.frames`).

Presentation imports the other two rooms, and from analysis only its records and readers
of them, never a function that decides; nothing in the other rooms imports it
(``tests/test_architecture.py``).
"""
