"""Start-up cost of the CLI: `tactbench --help` and `tactbench list` against bare Python.

    python benchmarks/startup.py [--repeat 15] [--json out.json]

Each command runs in a fresh interpreter, interleaved round-robin so that machine noise
hits all of them alike; the median wall time of each is reported, and the difference to
`python -c pass`. Goal (issue 2): within 0.25 s of bare Python.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "tactbench --help": [sys.executable, "-m", "tactbench", "--help"],
    "tactbench list": [sys.executable, "-m", "tactbench", "list"],
    "tactbench list --json": [sys.executable, "-m", "tactbench", "list", "--json"],
}
GOAL_S = 0.25


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--json", dest="json_out")
    args = parser.parse_args()

    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    for _ in range(args.repeat):
        for name, argv in COMMANDS.items():
            start = time.perf_counter()
            subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           check=True)
            times[name].append(time.perf_counter() - start)

    base = statistics.median(times["python -c pass"])
    rows = []
    print(f"{'command':<24}{'median s':>10}{'over python':>14}   goal ≤ {GOAL_S} s over")
    for name, samples in times.items():
        med = statistics.median(samples)
        over = med - base
        ok = "" if name.startswith("python") else ("ok" if over <= GOAL_S else "MISSED")
        rows.append({"command": name, "median_s": med, "over_python_s": over,
                     "runs": len(samples)})
        print(f"{name:<24}{med:>10.3f}{over:>14.3f}   {ok}")
    doc = {"benchmark": "startup", "machine": platform.platform(),
           "cpus": __import__("os").cpu_count(), "python": sys.version.split()[0],
           "date": time.strftime("%Y-%m-%d"), "goal_over_python_s": GOAL_S, "rows": rows}
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(doc, fh, indent=2)


if __name__ == "__main__":
    main()
