"""The runner's second room, **analysis**: from stored rows to numbers and verdicts.

Summaries over seeds (:mod:`~tactbench.runner.analysis.summaries`), the statistics with the
training run as the unit (:mod:`~tactbench.runner.analysis.statistics`,
:mod:`~tactbench.runner.analysis.variance`, :mod:`~tactbench.runner.analysis.pairing`,
:mod:`~tactbench.runner.analysis.power`), paired comparisons of cells as records
(:mod:`~tactbench.runner.analysis.comparisons`), the sequential design and its looks
(:mod:`~tactbench.runner.analysis.sequential`, :mod:`~tactbench.runner.analysis.answering`),
a folder's whole analysis, everything a report shows and a run's loop stops on
(:mod:`~tactbench.runner.analysis.report`: ``analyse``, an ``Analysis``), the records
event hooks receive (:mod:`~tactbench.runner.analysis.records`) and what a plan forecasts,
decided: its records and pure rules (:mod:`~tactbench.runner.analysis.forecast`; the plan
itself, execution composed with them, is :mod:`tactbench.runner.forecasting`).

Analysis reads execution's records (rows, scenes, plans) and never imports presentation:
a verdict is the same whether it is printed, written or not shown at all
(``tests/test_architecture.py``).
"""
