"""Built-in commands: a plugin like any other, registered through ``register_commands``.

Each command's module is imported only when the command runs: the hook registers every
built-in as a lazy command (``cli.add_lazy_command``, :class:`tactbench.cli.TactbenchGroup`),
which ``tactbench --help`` lists from its summary here without importing it. A new
built-in command is one entry of :data:`COMMANDS` (``tests/test_cli.py`` checks that every
module of this package is named there and that each summary is its command's own short
help).
"""

from __future__ import annotations

from tactbench import hookimpl

#: command name → (``"module:attribute"`` of its click command, its one-line summary as
#: ``tactbench --help`` lists it).
COMMANDS: dict[str, tuple[str, str]] = {
    "list": ("tactbench.commands.inspect:list_cmd",
             "List registered sensors, datasets, encoders, classifiers, splits and "
             "test windows."),
    "plugins": ("tactbench.commands.inspect:plugins_cmd",
                "List plugins (built-in and installed), their versions and load errors."),
    "data": ("tactbench.commands.data:data_group", "Inspect, simulate and preview datasets."),
    "can": ("tactbench.commands.can:can_group",
            "CySkin taxel traffic on a CAN bus: simulate, record, bus load, log info."),
    "live": ("tactbench.commands.live:live_cmd",
             "Classify gestures live: each sweep is encoded once and the last L frames "
             "classified."),
    "layout": ("tactbench.commands.layout:layout_group", "Inspect and generate taxel layouts."),
    "run": ("tactbench.commands.run:run_cmd",
            "Run a benchmark grid and report accuracy beside its cost."),
    "plan": ("tactbench.commands.plan:plan_cmd",
             "Plan a run before it trains: its cells, time and memory, and the power of "
             "each primary question."),
    "report": ("tactbench.commands.report:report_cmd",
               "Render a run folder's report again from its stored cell rows, training "
               "nothing."),
    "reproduce": ("tactbench.commands.reproduce:reproduce_cmd",
                  "Train a run folder's stored cells again here and compare every test "
                  "prediction."),
    "cache": ("tactbench.commands.cache:cache_group",
              "Inspect, prune or clear cached encodings (TACTBENCH_CACHE, default "
              "~/.cache/tactbench)."),
    "encode": ("tactbench.commands.encode:encode_cmd",
               "Encode a (T, H, W) sequence into (T, C, H, W) feature images."),
    "flowbench": ("tactbench.commands.flowbench:flowbench_cmd",
                  "Endpoint error, angular error and ms per frame pair of flow encoders."),
    "stability": ("tactbench.commands.stability:stability_cmd",
                  "Every encoder on stiff and extreme inputs: pass or fail, with the reason."),
}


@hookimpl
def register_commands(cli):
    for name, (target, summary) in COMMANDS.items():
        cli.add_lazy_command(name, target, summary=summary)
