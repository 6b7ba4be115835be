"""The runner's third room, **presentation**: numbers and verdicts shown.

Terminal and Markdown tables (:mod:`~tactbench.runner.presentation.tables`), the figures
(:mod:`~tactbench.runner.presentation.plots`), a folder's report files
(:mod:`~tactbench.runner.presentation.writers`: the :class:`Report`, results.json/csv,
report.md) and pandas data frames and Parquet (:mod:`~tactbench.runner.presentation.frames`).

Presentation imports the other two rooms; nothing in them imports it
(``tests/test_architecture.py``).
"""
