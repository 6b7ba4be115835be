"""The event hooks of plugins (``cell_finished``, ``look_finished``), called so that no
plugin can end, stall or corrupt a run.

Each plugin implementing an event hook gets a *lane*: a daemon thread that calls its
hooks one after another, in the order the events happened. :meth:`EventLanes.notify`
hands each lane its own deep copy of the event's arguments and returns at once, so the
row a hook edits is its own (neither the stored row nor the next plugin's) and a slow
or hung hook never holds back the storing of the next row. What a hook does wrong comes
back to the calling thread, where it is reported (:meth:`EventLanes.collect`):

- an exception, ``SystemExit`` included (a hook's ``sys.exit`` does not end the run), is
  reported once per plugin and hook; later failures of the same hook are counted and
  said in one line when the events settle (:meth:`EventLanes.settle`);
- a call that has not returned after :func:`hook_timeout` seconds
  (``TACTBENCH_HOOK_TIMEOUT``, default :data:`HOOK_TIMEOUT_S`) is reported and its
  plugin abandoned: its thread is left to itself and none of its hooks is called again
  by this plugin manager.

:meth:`EventLanes.settle` (at the end of each run and look) waits until every lane has
called what it was given, or has overrun its bound; the threads of idle lanes then end
(the next event starts them again), so no thread waits between runs.
"""

from __future__ import annotations

import copy
import math
import os
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from tactbench.errors import InputError

#: The environment variable bounding one event hook call, in seconds.
HOOK_TIMEOUT_ENV = "TACTBENCH_HOOK_TIMEOUT"
#: Seconds one event hook call may take when :data:`HOOK_TIMEOUT_ENV` is not set.
HOOK_TIMEOUT_S = 60.0

#: ``report(plugin, message)``: how a lane's problem is reported (a warning, or with
#: strict plugins an error).
Report = Callable[[str, str], None]


def hook_timeout() -> float:
    """Seconds one event hook call may take: :data:`HOOK_TIMEOUT_ENV` when set (a
    positive, finite number of seconds), else :data:`HOOK_TIMEOUT_S`; anything else is
    one line (an :class:`InputError`)."""
    text = os.environ.get(HOOK_TIMEOUT_ENV, "").strip()
    if not text:
        return HOOK_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{HOOK_TIMEOUT_ENV}={text!r}: give the seconds one plugin event "
                         f"hook call may take, a positive number (default "
                         f"{HOOK_TIMEOUT_S:g})")
    return value


@dataclass
class _Lane:
    """One plugin's event hooks: its thread, its queue and what came of its calls."""

    plugin: str
    calls: "queue.SimpleQueue[tuple[str, Callable[..., Any], dict[str, Any]] | None]" = field(
        default_factory=queue.SimpleQueue)
    pending: int = 0  # calls given and not yet returned (under EventLanes._lock)
    busy_since: float | None = None  # time.monotonic() of the call running now
    busy_with: str = ""
    abandoned: bool = False
    failures: list[tuple[str, str]] = field(default_factory=list)  # (hook, what)


class EventLanes:
    """The lanes of one plugin manager (see the module's docstring)."""

    def __init__(self, report: Report) -> None:
        self._report = report
        self._lanes: dict[str, _Lane] = {}
        self._lock = threading.Condition()
        self._failed: dict[tuple[str, str], int] = {}  # (plugin, hook) → failures
        self._said: dict[tuple[str, str], int] = {}  # failures already said

    def notify(self, hook: str, calls: list[tuple[str, Callable[..., Any], list[str]]],
               arguments: dict[str, Any]) -> None:
        """Give each ``(plugin, function, argument names)`` of ``calls`` its own copy of
        ``arguments``, to be called on its plugin's lane; returns without waiting."""
        self.collect()
        for plugin, function, names in calls:
            lane = self._lane(plugin)
            if lane.abandoned:  # kept, so that it is never called again
                continue
            kwargs = copy.deepcopy({k: arguments[k] for k in names})
            with self._lock:
                lane.pending += 1
            lane.calls.put((hook, function, kwargs))

    def _lane(self, plugin: str) -> _Lane:
        if plugin not in self._lanes:
            lane = self._lanes[plugin] = _Lane(plugin)
            threading.Thread(target=self._serve, args=(lane,), daemon=True,
                             name=f"tactbench-hooks-{plugin}").start()
        return self._lanes[plugin]

    def _serve(self, lane: _Lane) -> None:
        while True:
            call = lane.calls.get()
            if call is None:  # settled and idle: the thread ends (a new one if needed)
                return
            hook, function, kwargs = call
            if not lane.abandoned:
                with self._lock:
                    lane.busy_since, lane.busy_with = time.monotonic(), hook
                try:
                    function(**kwargs)
                except BaseException as exc:  # noqa: BLE001 — a hook ends nothing here
                    lane.failures.append((hook, _what(exc)))
            with self._lock:
                lane.busy_since = None
                lane.pending -= 1
                self._lock.notify_all()

    def collect(self, bound: float | None = None) -> None:
        """Report, in this thread, what the lanes' hooks did wrong since the last call:
        each plugin and hook's first failure, and every call over ``bound`` seconds
        (default :func:`hook_timeout`), whose plugin is then abandoned."""
        bound = hook_timeout() if bound is None else bound
        now = time.monotonic()
        for lane in list(self._lanes.values()):
            while lane.failures:
                hook, what = lane.failures.pop(0)
                key = (lane.plugin, hook)
                self._failed[key] = self._failed.get(key, 0) + 1
                if self._failed[key] == 1:
                    self._said[key] = 1
                    self._report(lane.plugin, f"hook {hook} {what} (a later failure of "
                                              f"this hook is counted, not repeated)")
            with self._lock:
                started, hook = lane.busy_since, lane.busy_with
            if not lane.abandoned and started is not None and now - started > bound:
                lane.abandoned = True
                self._report(lane.plugin, f"hook {hook} did not return within {bound:g} s "
                                          f"and is abandoned: no hook of this plugin is "
                                          f"called again here (more time: "
                                          f"{HOOK_TIMEOUT_ENV}=SECONDS)")

    def settle(self) -> None:
        """Wait until every lane has called what it was given (a lane over its bound is
        abandoned, not waited for), then report what went wrong, with one line per hook
        whose failures were not all said yet."""
        bound = hook_timeout()
        while True:
            self.collect(bound)
            with self._lock:
                busy = [lane for lane in self._lanes.values()
                        if lane.pending and not lane.abandoned]
                if not busy:
                    break
                now = time.monotonic()
                left = min(bound - (now - lane.busy_since) if lane.busy_since is not None
                           else bound for lane in busy)
                self._lock.wait(timeout=min(max(left, 0.0) + 0.01, 1.0))
        self.collect(bound)
        for plugin, lane in list(self._lanes.items()):
            if not lane.abandoned:  # idle now: no thread waits between runs
                lane.calls.put(None)
                del self._lanes[plugin]
        for key, count in self._failed.items():
            if count > self._said.get(key, 0):
                self._said[key] = count
                self._report(key[0], f"hook {key[1]} failed {count} time(s) in all (the "
                                     f"first is said above)")


def _what(exc: BaseException) -> str:
    """A hook's failure, as its report says it."""
    if isinstance(exc, SystemExit):
        return f"called sys.exit ({exc.code!r}); the run does not end for a plugin"
    text = " ".join(str(exc).split())[:300]
    return f"raised {type(exc).__name__}: {text}"
