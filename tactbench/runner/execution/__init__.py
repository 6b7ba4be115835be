"""The runner's first room, **execution**: from a scene to stored rows.

What a run is (:mod:`~tactbench.runner.execution.scene`), what it needs and what each cell
is (:mod:`~tactbench.runner.execution.planning`; the cells' names and the questions asked
of them, :mod:`~tactbench.runner.execution.questions`), the encodings cached on disk
(:mod:`~tactbench.runner.execution.cache`, one entry :mod:`~tactbench.runner.execution.entries`),
one cell trained and tested (:mod:`~tactbench.runner.execution.cell`; whether its model
learned, :mod:`~tactbench.runner.execution.learning`), cells run side by side
(:mod:`~tactbench.runner.execution.executors`, :mod:`~tactbench.runner.execution.system`),
their time forecast (:mod:`~tactbench.runner.execution.estimate`) and the one store of a
run folder's rows (:mod:`~tactbench.runner.execution.results`).

Execution imports neither of the other rooms (:mod:`tactbench.runner.analysis`,
:mod:`tactbench.runner.presentation`): a row is what a cell measured, never a judgement of
it (``tests/test_architecture.py``).
"""
