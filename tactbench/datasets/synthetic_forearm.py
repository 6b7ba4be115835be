"""``synthetic-forearm``: tactbench's built-in dataset, made by the gesture simulator.

Either version of the simulator (option ``version``): 1, :mod:`tactbench.datasets.synthetic`
(recordings of 5–27 frames starting near first contact, kept so past results stay
reproducible: ``synthetic-forearm:version=1``); 2, the person model of
:mod:`tactbench.datasets.people` (people with their own style, recordings with a lead-in
before contact and a tail after release) on the same skin, contacts and sensor. Generated
sets are cached on disk under ``tactbench.paths.cache_dir("datasets")``, keyed by the
options and :data:`GENERATOR_VERSION`.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Callable

from tactbench.budget import check_budget
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Sample
from tactbench.datasets import people
from tactbench.datasets.synthetic import (
    CLASSES,
    POSITIONS,
    make_device,
    make_user,
    simulate_sample,
)
from tactbench.errors import BudgetError, InputError, check_positive_int
from tactbench.machine import usable_cores
from tactbench.paths import atomic_folder, cache_dir
from tactbench.specs import format_spec

#: Bump when the generated data changes: it keys the cache (with the options).
GENERATOR_VERSION = 3
#: The simulator's versions (option ``version``) and the default: 2, the person model
#: (leaving people out costs accuracy on it, measured in docs/people.md); 1 stays
#: reachable by name so past results reproduce (docs/simulator.md).
VERSIONS = (1, 2)
DEFAULT_VERSION = 2
#: Normalisation per version. Version 2's recordings are mostly without contact (lead-in,
#: tail, the rest of the arm), so a taxel's median reading is its rest value; version 1's
#: start at contact, and its 5th percentile is.
NORMALISATION = {1: "baseline:low=5,high=99.99", 2: "baseline:low=50,high=99.99"}


def check_options(**options: Any) -> dict[str, int]:
    """The generator's options (``users``, ``positions``, ``repetitions``, ``seed``,
    ``n_taxels``, ``version``) checked and as ints; errors name the option."""
    minimum = {"users": 1, "positions": 1, "repetitions": 1, "seed": 0, "n_taxels": 1,
               "version": 1}
    out = {name: check_positive_int(value, f"synthetic-forearm option {name}",
                                    minimum=minimum[name])
           for name, value in options.items()}
    if out.get("positions", 1) > len(POSITIONS):
        raise InputError(f"synthetic-forearm option positions must be in 1..{len(POSITIONS)} "
                         f"({', '.join(POSITIONS)}), got {out['positions']}")
    if out.get("version", DEFAULT_VERSION) not in VERSIONS:
        raise InputError(f"synthetic-forearm option version must be one of "
                         f"{', '.join(map(str, VERSIONS))}, got {out['version']}")
    return out


#: Frames of a simulated recording, at most (v1: 26, v2: 35 measured; with a margin).
FRAMES_PER_SAMPLE = 40


def memory_estimate(options: dict[str, int]) -> int:
    """Bytes the simulated dataset takes, from the request alone: every sample's float32
    readings (:data:`FRAMES_PER_SAMPLE` frames × ``n_taxels``) and half as much again
    (timestamps, the copy while it is saved)."""
    samples = options["users"] * len(CLASSES) * options["positions"] * options["repetitions"]
    return samples * FRAMES_PER_SAMPLE * options.get("n_taxels", 1558) * 6


def generate(users: int = 38, positions: int = 2, repetitions: int = 5, seed: int = 0,
             n_taxels: int = 1558, version: int = DEFAULT_VERSION,
             progress: Callable[[int, int], None] | None = None,
             workers: int | None = None) -> Dataset:
    """Generate the dataset (no cache); see :class:`SyntheticForearm`.

    Each user's recordings depend only on the seed and the user (not on the other users),
    so users are generated in ``workers`` processes at once (default: the usable cores,
    one process for a set of fewer than :data:`PARALLEL_MIN_USERS` users): the same
    samples, in the same order, as one process makes. ``progress(done, total)`` is
    called per sample in one process, per user with several.
    """
    opts = check_options(users=users, positions=positions, repetitions=repetitions, seed=seed,
                         n_taxels=n_taxels, version=version)
    users, positions, repetitions = opts["users"], opts["positions"], opts["repetitions"]
    version = opts["version"]
    check_budget(memory_estimate(opts), f"simulating {users} users × {len(CLASSES)} "
                 f"gestures × {positions} positions × {repetitions} repetitions")  # first
    device = make_device(seed, n_taxels)
    per_user = len(CLASSES) * positions * repetitions
    total = users * per_user
    if workers is None:
        workers = usable_cores() if users >= PARALLEL_MIN_USERS else 1
    check_positive_int(workers, "workers")
    jobs = [(seed, n_taxels, version, u, positions, repetitions) for u in range(users)]
    samples: list[Sample] = []
    if workers == 1 or users == 1:
        def made(sample: Sample) -> None:  # progress per sample
            samples.append(sample)
            if progress is not None:
                progress(len(samples), total)

        for job in jobs:
            _user_samples(*job, device=device, made=made)
    else:
        # forkserver, not fork: the caller may hold torch/OpenMP threads (see
        # tactbench.encoders.parallel); results come back in user order.
        ctx = multiprocessing.get_context("forkserver")
        with ProcessPoolExecutor(max_workers=min(workers, users), mp_context=ctx) as pool:
            for part in pool.map(_user_samples_job, jobs):
                samples += part
                if progress is not None:
                    progress(len(samples), total)
    return Dataset("synthetic-forearm", samples, CLASSES, device.layout,
                   normalisation=NORMALISATION[version],
                   description=f"tactbench gesture simulator v{version}: "
                               f"{users} users x {len(CLASSES)} gestures x {positions} "
                               f"positions x {repetitions} repetitions, seed {seed}")


#: Fewer users than this are generated in one process (starting processes costs more).
PARALLEL_MIN_USERS = 8


def _user_samples(seed: int, n_taxels: int, version: int, u: int, positions: int,
                  repetitions: int, *, device=None,
                  made: Callable[[Sample], None] | None = None) -> list[Sample]:
    """User ``u``'s samples, in the dataset's order (gesture, position, repetition);
    ``made(sample)`` hears of each as it is made."""
    if device is None:
        device = make_device(seed, n_taxels)
    if version == 1:
        make, simulate = make_user, simulate_sample
    else:
        make, simulate = people.make_person, people.simulate_sample
    user = make(seed, u)
    out = []
    for label, gesture in enumerate(CLASSES):
        for position in POSITIONS[:positions]:
            for rep in range(1, repetitions + 1):
                rec = simulate(device, user, gesture, position, rep, seed)
                out.append(Sample(rec, label, user.name, position, rep,
                                  f"synthetic-forearm:seed={seed}/{user.name}/"
                                  f"{gesture}/{position}/{rep}"))
                if made is not None:
                    made(out[-1])
    return out


def _user_samples_job(job: tuple) -> list[Sample]:
    return _user_samples(*job)


#: Option ``people``: ``fixed`` (one data set, drawn with ``seed``) or ``per-run`` (each
#: run draws its own people: dataset seed = run seed; docs/simulator.md).
PEOPLE = ("fixed", "per-run")


class PerRunPeopleError(InputError):
    """``synthetic-forearm:people=per-run`` asked for something only one data set has."""


class SyntheticForearm:
    """Registered dataset ``synthetic-forearm``.

    Options: ``users`` (38), ``positions`` (2: front, side), ``repetitions``
    (5), ``seed`` (0), ``n_taxels`` (1558), ``version`` (1: the first simulator; 2: the
    person model, the default, see docs/simulator.md), ``cache`` (True: keep generated
    sets under ``cache_dir("datasets")``), ``people`` (``fixed``: one data set drawn with
    ``seed``; ``per-run``: every run of a benchmark draws new people, its dataset seed
    the run's seed, see :meth:`run_spec`). ``load()`` returns the
    :class:`~tactbench.data.recording.Dataset`.
    """

    def __init__(self, users: int = 38, positions: int = 2, repetitions: int = 5,
                 seed: int | None = None, n_taxels: int = 1558,
                 version: int = DEFAULT_VERSION, cache: bool = True,
                 people: str = "fixed") -> None:
        if people not in PEOPLE:
            raise InputError(f"synthetic-forearm option people must be one of "
                             f"{', '.join(PEOPLE)}, got {people!r}")
        if people == "per-run" and seed is not None:
            raise PerRunPeopleError(
                f"synthetic-forearm: people=per-run draws each run's people with the run's "
                f"seed; seed={seed} would fix them (give one or the other)")
        self.people = people
        fixed = {} if people == "per-run" else {"seed": 0 if seed is None else seed}
        self.options = check_options(users=users, positions=positions,
                                     repetitions=repetitions, n_taxels=n_taxels,
                                     version=version, **fixed)
        self.cache = bool(cache)

    def run_spec(self, seed: int) -> str | None:
        """The data set of run ``seed``: with ``people=per-run``, the spec of the fixed
        data set whose dataset seed is the run's seed (the other options as given), so
        runs are independent draws from the simulator's population; None with
        ``people=fixed`` (every run re-splits the one data set)."""
        if self.people == "fixed":
            return None
        seed = check_positive_int(seed, "run seed", minimum=0)
        return format_spec("synthetic-forearm", {**self.options, "seed": seed,
                                                 **({} if self.cache else {"cache": False})})

    def cache_key(self) -> str:
        text = json.dumps({"generator": GENERATOR_VERSION, **self.options}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def cache_path(self) -> Path:
        return cache_dir("datasets") / f"synthetic-forearm-{self.cache_key()}"

    def load(self, progress: Callable[[int, int], None] | None = None) -> Dataset:
        """The dataset: from the cache when there, else generated (and cached).

        ``progress(done, total)`` is called per sample generated (not when the cache
        answers).
        """
        if self.people == "per-run":
            raise PerRunPeopleError(
                "synthetic-forearm:people=per-run is a new data set for every run of a "
                "benchmark (tactbench run), not one data set to load; give seed=N for one")
        if self.cache:
            folder = self.cache_path()
            if (folder / "manifest.json").is_file():
                try:
                    return Dataset.load(folder)
                except BudgetError:  # too large for this budget: not a damaged cache
                    raise
                except (InputError, OSError):  # a bug elsewhere must not pass for a bad cache
                    shutil.rmtree(folder, ignore_errors=True)  # corrupt: make it again
            elif folder.exists():  # a leftover without a manifest
                shutil.rmtree(folder, ignore_errors=True)
        ds = generate(**self.options, progress=progress)
        if self.cache:
            with atomic_folder(folder) as tmp:  # another process may win the race: fine
                ds.save(tmp)
        return ds
