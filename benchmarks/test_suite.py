"""What the test suite costs on this machine: the README's command, the slow tests, each room.

    python benchmarks/test_suite.py [--parts fast,slow,rooms] [--out docs/benchmarks/test-suite.json]
                                    [--docs-only]

Each part runs pytest in a subprocess from the repository root, one after another, with
``--durations=0`` so that every test's own time is kept:

- ``fast``: the README's test command (``python -m pytest``: the default options of
  pyproject.toml, i.e. every core and ``-m 'not slow'``);
- ``slow``: ``python -m pytest -m slow``, the tests CI runs after it;
- ``rooms``: ``python -m pytest tests/ROOM`` for each room (each folder of tests/, and the
  top-level files together as ``tests/*.py``), the command a contributor runs after
  changing one module.

It records each part's wall time, pytest's closing counts, the summed test time by room
(setup + call + teardown, which is more than the wall time on several cores), the ten
slowest tests, the machine and the date; a full measurement (all three parts, the default
--out) also writes the measured block of docs/testing.md. The goals (docs/testing.md): the fast suite
≤ 240 s, a room ≤ 60 s, on an idle 2-core machine. Nothing else should run meanwhile: on
2 cores a second busy process slows every test 2–7×.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import time
from collections import defaultdict
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GOALS = {"fast_s": 240.0, "room_s": 60.0}
DURATION = re.compile(r"^\s*([0-9.]+)s (setup|call|teardown)\s+(\S+)")
#: pytest's closing line, with -q ("3 passed in 1.2s") or without ("=== 3 passed in 1.2s ===")
CLOSING = re.compile(r"^=*\s*(\d+ (?:passed|failed|errors?|skipped|deselected).*?) in ([0-9.]+)s")


def rooms() -> list[str]:
    """The folders of tests/ with tests in them, and the top-level files as one room."""
    tests = REPO / "tests"
    found = sorted(p.name for p in tests.iterdir()
                   if p.is_dir() and any(p.glob("test_*.py")))
    return [f"tests/{name}" for name in found] + ["tests/*.py"]


def room_of(nodeid: str) -> str:
    parts = nodeid.split("::", 1)[0].split("/")
    return f"tests/{parts[1]}" if len(parts) > 2 else "tests/*.py"


def pytest_part(args: list[str]) -> dict:
    """Run ``python -m pytest ARGS --durations=0 -q`` and summarise what it printed."""
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
               "--durations=0", "--durations-min=0", *args]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - start
    by_room: dict[str, float] = defaultdict(float)
    by_test: dict[str, float] = defaultdict(float)
    closing = None
    for line in done.stdout.splitlines():
        if (m := DURATION.match(line)):
            seconds, node = float(m.group(1)), m.group(3)
            by_room[room_of(node)] += seconds
            by_test[node] += seconds
        elif (m := CLOSING.match(line)):
            closing = m.group(1)
    slowest = sorted(by_test.items(), key=lambda kv: -kv[1])[:10]
    return {"command": " ".join(["python", "-m", "pytest", *args]) or "python -m pytest",
            "returncode": done.returncode, "wall_s": round(wall, 1), "closing": closing,
            "tests": len(by_test),
            "test_seconds_by_room": {k: round(v, 1) for k, v in sorted(by_room.items())},
            "slowest": [{"test": k, "s": round(v, 2)} for k, v in slowest],
            "tail": done.stdout[-1500:] if done.returncode not in (0, 5) else ""}


def machine() -> dict:
    from tactbench.kernels import cpu_model

    return {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform()}


START, END = "<!-- suite:start -->", "<!-- suite:end -->"
DOC = REPO / "docs" / "testing.md"


def docs_text(record: dict) -> str:
    """The measured block of docs/testing.md, written from a record of :func:`main`."""
    m = record["machine"]
    lines = [f"Measured {record['date']} at commit {record['commit']}, on {m['cpu']} "
             f"({m['cores']} cores), Python {m['python']}:", ""]
    for name, what in (("fast", "the fast suite (the README's command)"),
                       ("slow", "the slow tests (`-m slow`)")):
        if name in record:
            part = record[name]
            lines.append(f"- {what}: **{part['wall_s']:.0f} s** wall, {part['closing']};")
    if "rooms" in record:
        rooms = record["rooms"]
        worst = max(rooms, key=lambda r: rooms[r]["wall_s"])
        lines.append("- one room at a time: " + ", ".join(
            f"`{r}` {v['wall_s']:.0f} s" for r, v in rooms.items()) +
            f" (the longest: `{worst}`).")
    if "fast" in record and record["fast"]["slowest"]:
        slow = record["fast"]["slowest"][:5]
        lines += ["", "The fast suite's five longest tests (setup + call + teardown): " +
                  "; ".join(f"`{t['test']}` {t['s']:.1f} s" for t in slow) + "."]
    return "\n".join(lines)


def write_docs(record: dict, doc: Path = DOC) -> None:
    text = doc.read_text()
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    doc.write_text(f"{head}{START}\n{docs_text(record)}\n{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", default="fast,slow,rooms")
    ap.add_argument("--out", type=Path, default=REPO / "docs/benchmarks/test-suite.json")
    ap.add_argument("--docs-only", action="store_true",
                    help="write docs/testing.md's block from --out again, measuring nothing")
    a = ap.parse_args(argv)
    if a.docs_only:
        if not a.out.is_file():
            ap.error(f"--docs-only writes docs/testing.md from {a.out}, which does not exist: "
                     f"measure first")
        write_docs(json.loads(a.out.read_text()))
        return 0
    parts = [p for p in a.parts.split(",") if p]
    unknown = set(parts) - {"fast", "slow", "rooms"}
    if unknown:
        ap.error(f"unknown part(s) {sorted(unknown)}: choose from fast, slow, rooms")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()
    record: dict = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                    "commit": commit, "machine": machine(), "goals": GOALS}
    if "fast" in parts:
        record["fast"] = pytest_part([])
        print(f"fast suite: {record['fast']['wall_s']} s, {record['fast']['closing']}")
    if "slow" in parts:
        record["slow"] = pytest_part(["-m", "slow"])
        print(f"slow tests: {record['slow']['wall_s']} s, {record['slow']['closing']}")
    if "rooms" in parts:
        record["rooms"] = {}
        for room in rooms():
            targets = ([str(p.relative_to(REPO)) for p in sorted((REPO / "tests").glob("test_*.py"))]
                       if room == "tests/*.py" else [room])
            part = pytest_part(targets)
            record["rooms"][room] = {k: part[k] for k in ("wall_s", "closing", "returncode")}
            print(f"{room:<22} {part['wall_s']:>7.1f} s  {part['closing']}")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {a.out}")
    if a.out == REPO / "docs/benchmarks/test-suite.json" and {"fast", "slow", "rooms"} <= set(parts):
        write_docs(record)
        print(f"wrote {DOC}")
    failed = [name for name in ("fast", "slow") if record.get(name, {}).get("returncode")]
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
