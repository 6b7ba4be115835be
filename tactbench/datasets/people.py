"""The person model of ``synthetic-forearm`` version 2: people who differ, recordings
that start before contact and end after release.

Every simulated person has a *style* (:class:`Person`), drawn once from
``sha256(seed, "person", index)``: hand size, strength, tempo, where they touch, which
parts of the hand land, how far their fingers spread, how fast force builds and how it is
released, which variant of each gesture they use (a fingertip or a whole-hand pull, a
flat-hand or a fingertip push, one twist stroke or two), and how consistent they are from
one repetition to the next (``sloppiness`` scales every per-repetition variation). On top
of that style, each person has their own way of doing each gesture (:class:`Habit`, from
``sha256(seed, "person-gesture", index, gesture)``): where on the arm round their spot,
how hard, how fast, and which parts of the hand land, the same in all their repetitions of
that gesture and different from other people's. A session (the person at one position)
shifts the style a little. Each recording has a
lead-in without contact and a tail after release whose lengths are per-person habits.

The distributions and their sources are listed in ``docs/simulator.md`` ("People,
version 2"); the numbers are the constants below. The contact, skin and sensor models are
version 1's (:mod:`tactbench.datasets.synthetic`), so the two versions differ only in the
people and in what a recording spans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tactbench.data.recording import Recording
from tactbench.datasets import synthetic as v1
from tactbench.datasets.synthetic import (
    LENGTH_MM,
    RATE_HZ,
    TOP_X,
    Hand,
    Patches,
    _ar_noise,
    _rng,
    _smoothstep,
    _strokes,
    push_parts,
)
from tactbench.errors import check_choice

# ---- the person (drawn once per person)
HAND_LENGTH_MM = (180.0, 10.0, 160.0, 200.0)  # normal mean, sd, clipped to the study's range
STRENGTH_SIGMA = 0.30  # lognormal, median 1 (grip strength varies ~30 % between adults)
TEMPO_SIGMA = 0.25  # lognormal duration factor, median 1
RIGHT_HANDED = 0.85
SLOPPINESS_SIGMA = 0.5  # lognormal, median 1: scales every per-repetition variation
SPREAD_SIGMA = 0.12  # lognormal factor on the finger spacing along the arm
TAU_S = (0.05, 0.12)  # force build-up time constant, uniform, × tempo
OVERSHOOT = (0.0, 0.3)  # grip overshoot before settling, uniform
RELEASE_TAU_S = (0.06, 0.25)  # how fast the hand lets go, uniform, × tempo
LEAD_IN_S = (0.6, 0.45, 0.1, 2.0)  # median lead-in: lognormal median, σ, clip
TAIL_S = (0.5, 0.45, 0.1, 2.0)  # median tail after release: same
HABIT_ROUND_MM = 15.0  # where round the arm a person habitually puts the hand (sd)
FINGERTIP_GRIP = 0.4  # a person grasps, twists or pulls with the fingertips only (each)

# ---- a person's own way of doing each gesture (drawn once per person and gesture):
# where on the arm around their spot, how hard, how fast; see docs/simulator.md
GESTURE_PLACE_MM = (12.0, 25.0)  # sd round / along the arm
GESTURE_FORCE_SIGMA = 0.25  # lognormal force factor on top of the person's strength
GESTURE_TEMPO_SIGMA = 0.15  # lognormal tempo factor on top of the person's tempo

# ---- a session (one person at one position) shifts the style a little
SESSION_PLACE_MM = 5.0  # sd of the placement shift
SESSION_FORCE_SIGMA = 0.08  # lognormal force factor
SESSION_TEMPO_SIGMA = 0.05  # lognormal tempo factor

# ---- one repetition, for a person of sloppiness 1 (scaled by the person's sloppiness)
REP_PLACE_MM = (6.0, 8.0)  # sd round / along the arm
REP_FORCE_SIGMA = 0.12
REP_TIME_SIGMA = 0.10  # durations and time constants
REP_AMOUNT_SIGMA = 0.15  # how far a twist or pull moves
REP_PART_FLIP = 0.06  # probability that one part of the hand lands otherwise than usual
REP_VARIANT_FLIP = 0.08  # probability of the other variant of a gesture
REP_LEAD_SIGMA = 0.30  # lead-in and tail around the person's medians, lognormal

# ---- what a recording spans (the contact part is version 1's length distribution)
MAX_FRAMES = 80


def _lognormal_clipped(r: np.random.Generator, spec: tuple[float, float, float, float]
                       ) -> float:
    median, sigma, lo, hi = spec
    return float(np.clip(r.lognormal(math.log(median), sigma), lo, hi))


@dataclass(frozen=True)
class Habit:
    """A person's own way of doing one gesture: placement shift (mm), force and tempo
    factors on top of their general style."""

    dx: float  # round the arm
    dy: float  # along the arm
    force: float
    tempo: float
    parts: tuple[bool, bool, bool, bool, bool]  # palm, little, middle, proximal, thumb


def make_habit(seed: int, index: int, gesture: str,
               part_p: tuple[float, float, float, float, float]) -> Habit:
    """Person ``index``'s habit for ``gesture`` (its own random stream, so the person's
    other draws are those of a model without habits); which parts of the hand land in
    this gesture, each with the person's probability ``part_p``."""
    r = _rng("person-gesture", seed, index, gesture)
    return Habit(float(r.normal(0.0, GESTURE_PLACE_MM[0])),
                 float(r.normal(0.0, GESTURE_PLACE_MM[1])),
                 float(r.lognormal(0.0, GESTURE_FORCE_SIGMA)),
                 float(r.lognormal(0.0, GESTURE_TEMPO_SIGMA)),
                 tuple(bool(b) for b in r.random(5) < np.asarray(part_p)))


@dataclass(frozen=True)
class Person:
    """One simulated person's style (see the module docstring)."""

    name: str
    hand_mm: float
    strength: float
    tempo: float
    right_handed: bool
    sloppiness: float
    spread: float  # factor on finger spacing
    finger_weights: np.ndarray  # (4,) index..little
    part_p: tuple[float, float, float, float, float]  # how often each part lands (habits)
    fingertips: tuple[bool, bool, bool]  # Grasp, Twist, Pull with the fingertips only
    y_pref: float  # along the arm, mm
    x_habit: float  # round the arm from the top, mm
    x_side: float  # how far round the arm the side position is
    tau: float  # force build-up time constant, s
    overshoot: float
    release_tau: float  # s
    lead_in: float  # median lead-in, s
    tail: float  # median tail after release, s
    stroke_start: float  # s after contact when a twist or pull starts
    stroke_duration: float  # s
    twist_sign: float
    twist_mm: float
    twist_strokes: int
    twist_kappa: float  # how much fingertip pressure rises while twisting
    pull_sign: tuple[float, float]  # per position
    pull_mm: float
    pull_kappa: float
    push_flat: bool  # flat-hand push, else fingertips
    push_along: bool  # hand along the arm when pushing, else across
    push_duration: float  # s
    push_ease: float
    two_hand_mm: float  # separation of the hands in 2hGrasp
    two_hand_delay: float  # s
    habits: tuple[Habit, ...] = ()  # per gesture, in the order of CLASSES

    def habit(self, gesture: str) -> Habit:
        return self.habits[v1.CLASSES.index(gesture)]


def make_person(seed: int, index: int) -> Person:
    """Person ``index``'s style: the same for any number of people generated."""
    r = _rng("person", seed, index)
    right = bool(r.random() < RIGHT_HANDED)
    mean, sd, lo, hi = HAND_LENGTH_MM
    tempo = float(r.lognormal(0.0, TEMPO_SIGMA))
    part_p = tuple(float(r.uniform(lo, hi))  # palm, little, middle, proximal, thumb
                   for lo, hi in ((0.1, 0.7), (0.6, 1.0), (0.15, 0.85), (0.05, 0.6),
                                  (0.5, 1.0)))
    return Person(
        name=f"u{index:02d}",
        hand_mm=float(np.clip(r.normal(mean, sd), lo, hi)),
        strength=float(r.lognormal(0.0, STRENGTH_SIGMA)),
        tempo=tempo,
        right_handed=right,
        sloppiness=float(r.lognormal(0.0, SLOPPINESS_SIGMA)),
        spread=float(r.lognormal(0.0, SPREAD_SIGMA)),
        finger_weights=np.array([1.0, 1.0, 0.85, 0.65]) * r.lognormal(0.0, 0.2, 4),
        part_p=part_p,
        fingertips=tuple(bool(f) for f in r.random(3) < FINGERTIP_GRIP),
        y_pref=float(r.uniform(0.3, 0.7) * LENGTH_MM),
        x_habit=float(r.normal(0.0, HABIT_ROUND_MM)),
        x_side=float(r.uniform(35.0, 75.0)) * (1 if right else -1),
        tau=float(r.uniform(*TAU_S) * tempo),
        overshoot=float(r.uniform(*OVERSHOOT)),
        release_tau=float(r.uniform(*RELEASE_TAU_S) * tempo),
        lead_in=_lognormal_clipped(r, LEAD_IN_S),
        tail=_lognormal_clipped(r, TAIL_S),
        stroke_start=float(r.uniform(0.1, 0.35) * tempo),
        stroke_duration=float(r.uniform(0.5, 1.6) * tempo),
        twist_sign=(1.0 if right else -1.0) * float(r.choice([1.0, 1.0, -1.0])),
        twist_mm=float(r.uniform(6.0, 16.0)),
        twist_strokes=1 if r.random() < 0.6 else 2,
        twist_kappa=float(r.uniform(0.3, 0.8)),
        pull_sign=(float(r.choice([-1.0, 1.0])), float(r.choice([-1.0, 1.0]))),
        pull_mm=float(r.uniform(5.0, 15.0)),
        pull_kappa=float(r.uniform(0.1, 0.4)),
        push_flat=bool(r.random() < 0.55),
        push_along=bool(r.random() < 0.5),
        push_duration=float(r.uniform(0.5, 1.6) * tempo),
        push_ease=float(r.uniform(0.0, 0.35)),
        two_hand_mm=float(r.uniform(85.0, 110.0)),
        two_hand_delay=float(r.uniform(0.0, 0.35)),
        habits=tuple(make_habit(seed, index, g, part_p) for g in v1.CLASSES),
    )


@dataclass(frozen=True)
class Session:
    """A person at one position: the style shifted a little."""

    dx: float
    dy: float
    force: float
    tempo: float


def make_session(seed: int, person: Person, position: str) -> Session:
    r = _rng("person-session", seed, person.name, position)
    return Session(float(r.normal(0, SESSION_PLACE_MM)), float(r.normal(0, SESSION_PLACE_MM)),
                   float(r.lognormal(0, SESSION_FORCE_SIGMA)),
                   float(r.lognormal(0, SESSION_TEMPO_SIGMA)))


class _Rep:
    """One repetition's variation around a person's style (scaled by their sloppiness)."""

    def __init__(self, r: np.random.Generator, person: Person) -> None:
        self.r, self.s = r, person.sloppiness

    def factor(self, sigma: float) -> float:
        return float(self.r.lognormal(0.0, sigma * self.s))

    def shift(self, sd: float) -> float:
        return float(self.r.normal(0.0, sd * self.s))

    def flip(self, p: float) -> bool:
        return bool(self.r.random() < min(0.4, p * self.s))


class _Patches(Patches):
    """Patches whose pressure is computed only for frames where something touches."""

    def pressure(self, xy: np.ndarray) -> np.ndarray:
        out = np.zeros((self.t, len(xy)), dtype=np.float32)
        if not self.rows:
            return out
        amp = np.stack([row[4] for row in self.rows])
        live = np.flatnonzero(np.abs(amp).max(axis=0) > 1e-3)
        if len(live) == 0:
            return out
        sub = Patches(len(live))
        sub.rows = [tuple(a[live] for a in row[:5]) + (row[5],) for row in self.rows]
        out[live] = sub.pressure(xy)
        return out


def grip_hand(person: Person, parts: tuple[bool, ...], rep: _Rep, x0: float, y0: float,
              d: float, mirror: bool = False, fingertips: bool = False) -> Hand:
    """A hand wrapped around the arm (as :func:`~tactbench.datasets.synthetic.wrap_hand`),
    its ``parts`` those the person usually lands in this gesture, each landing otherwise
    with a probability that grows with sloppiness; ``fingertips``: only the finger and
    thumb tips."""
    k = person.hand_mm / 180.0
    spread = 19.0 * k * person.spread * (-1 if mirror else 1)
    lengths = np.array([0.93, 1.0, 0.96, 0.78])
    palm, little, middle, proximal, thumb = (p != rep.flip(REP_PART_FLIP)
                                             for p in parts)
    if fingertips:
        palm = middle = proximal = False
    xs, ys, sxs, sys_, amps, kinds = [], [], [], [], [], []

    def put(x, y, sx, sy, amp, kind):
        xs.append(x), ys.append(y), sxs.append(sx), sys_.append(sy), amps.append(amp)
        kinds.append(kind)

    if palm:
        put(x0, y0 + 0.2 * spread, 13 * k, 20 * k, 0.45, "palm")
    for i in range(4):
        if i == 3 and not little:
            continue
        fy = y0 + (i - 1.5) * spread + rep.shift(1.0)
        lk = lengths[i] * k
        w = person.finger_weights[i]
        if proximal:
            put(x0 + d * (40 * k + 22 * lk), fy, 12 * lk, 6 * k, 0.35 * w, "proximal")
        if middle:
            put(x0 + d * (40 * k + 58 * lk), fy, 8 * lk, 6 * k, 0.55 * w, "middle")
        put(x0 + d * (40 * k + 79 * lk), fy, 6 * k, 5.5 * k, (1.2 if fingertips else 1.0) * w,
            "tip")
    if thumb or fingertips:
        ty = y0 - 1.9 * spread + rep.shift(1.5)
        if not fingertips:
            put(x0 - d * 48 * k, ty, 10 * k, 7 * k, 0.4, "thumb")
        put(x0 - d * 78 * k, ty + 0.3 * spread, 7 * k, 6 * k, 0.9, "thumb_tip")
    n = len(xs)
    jitter = np.array([rep.factor(0.08) for _ in range(n)])
    return Hand(np.array(xs), np.array(ys), np.array(sxs), np.array(sys_),
                np.array(amps) * jitter, kinds, np.zeros(n))


def _grip(p: Patches, hand: Hand, t: np.ndarray, force: float, tau: float, overshoot: float,
          rep: _Rep, *, dx=None, dy=None, gain=None, lead=None) -> None:
    """Version 1's grip (:func:`tactbench.datasets.synthetic._grip`) with the person's
    overshoot and the repetition's finger timing."""
    onset = np.array([rep.shift(0.02) for _ in range(len(hand.x))])
    v1.press_hand(p, hand, t, force, tau, overshoot, onset, rep.r, dx=dx, dy=dy, gain=gain,
                  lead=lead)


def simulate_pressure(gesture: str, person: Person, session: Session, position: str,
                      r: np.random.Generator, t: np.ndarray, xy: np.ndarray,
                      contact_s: float) -> np.ndarray:
    """Pressure (kPa) at the taxels ``xy`` over contact times ``t`` (s; < 0 before
    contact), the hand pressing for ``contact_s`` s (before its release): ``(T, N)``."""
    check_choice(gesture, "gesture", v1.CLASSES)
    rep = _Rep(r, person)
    habit = person.habit(gesture)
    p = _Patches(len(t))
    k = person.hand_mm / 180.0
    tempo = habit.tempo * session.tempo * rep.factor(REP_TIME_SIGMA)
    side = position == "side"
    x0 = TOP_X + person.x_habit + habit.dx + (person.x_side if side else 0.0) + session.dx \
        + rep.shift(REP_PLACE_MM[0])
    y0 = float(np.clip(person.y_pref + habit.dy + session.dy + rep.shift(REP_PLACE_MM[1]),
                       60, LENGTH_MM - 60))
    d = 1.0 if person.right_handed else -1.0
    force = person.strength * habit.force * session.force * rep.factor(REP_FORCE_SIGMA)
    tau = person.tau * tempo
    overshoot = float(np.clip(person.overshoot + rep.shift(0.04), 0.0, 0.4))
    x0 -= d * 40 * k

    if gesture in ("Grasp", "Twist", "Pull"):  # the person's variant, now and then the other
        tips_only = person.fingertips[("Grasp", "Twist", "Pull").index(gesture)] \
            != rep.flip(REP_VARIANT_FLIP)
    if gesture == "Grasp":
        _grip(p, grip_hand(person, habit.parts, rep, x0, y0, d, fingertips=tips_only), t,
              force, tau, overshoot, rep)
    elif gesture == "2hGrasp":
        sep = person.two_hand_mm * k * rep.factor(0.05)
        delay = max(0.0, person.two_hand_delay + rep.shift(0.05))
        share = np.array([rep.factor(0.1), rep.factor(0.1)]) * 0.65
        h1 = grip_hand(person, habit.parts, rep, x0, y0 - sep / 2, d)
        h2 = grip_hand(person, habit.parts, rep, x0 + rep.shift(5.0), y0 + sep / 2, -d,
                       mirror=True)
        _grip(p, h1, t, force * share[0], tau, overshoot, rep)
        _grip(p, h2, t - delay, force * share[1], tau * rep.factor(0.1), overshoot, rep)
    elif gesture in ("Twist", "Pull"):
        twist = gesture == "Twist"
        hand = grip_hand(person, habit.parts, rep, x0, y0, d, fingertips=tips_only)
        n = len(hand.x)
        start = person.stroke_start * tempo
        duration = min(person.stroke_duration * tempo, max(0.3, 0.8 * contact_s - start))
        strokes = person.twist_strokes if twist else 1
        if twist and rep.flip(REP_VARIANT_FLIP):
            strokes = 3 - strokes
        phi, rate = _strokes(t, start, duration, strokes, r)
        rate_n = rate / (rate.max() + 1e-9)
        tips = np.array([kd in ("tip", "thumb_tip") for kd in hand.kind])
        if twist:
            sign = person.twist_sign
            amount = person.twist_mm * rep.factor(REP_AMOUNT_SIGMA) * sign
            kappa = person.twist_kappa
            ripple = 0.15 * np.sin(2 * np.pi * r.uniform(1.0, 2.5) * t + r.uniform(0, 2 * np.pi))
            gate = 4 * phi * (1 - phi)
            gain = np.where(tips[:, None], 1 + kappa * phi + ripple * gate, 1 - 0.3 * phi)
            dx = np.outer(np.where(tips, 1.0, 0.7), amount * phi)
            lead = np.zeros((n, len(t), 3))
            lead[:, :, 0] = sign * 0.8 * hand.sx[:, None]
            lead[:, :, 2] = 0.5 * kappa * rate_n[None, :] + 0.15 * phi[None, :]
            _grip(p, hand, t, force * 0.82, tau, overshoot, rep, dx=dx, gain=gain, lead=lead)
        else:
            sign = person.pull_sign[int(side)]
            amount = person.pull_mm * rep.factor(REP_AMOUNT_SIGMA) * sign
            kappa = person.pull_kappa
            gain = np.broadcast_to(1 + kappa * phi, (n, len(t)))
            dy = np.outer(np.ones(n), amount * phi)
            lead = np.zeros((n, len(t), 3))
            lead[:, :, 1] = sign * 0.8 * hand.sy[:, None]
            lead[:, :, 2] = 0.4 * rate_n[None, :] + 0.2 * phi[None, :]
            _grip(p, hand, t, force * 0.88, tau, overshoot, rep, dy=dy, gain=gain, lead=lead)
    else:
        _push(p, person, rep, t, TOP_X + person.x_habit + habit.dx
              + (person.x_side if side else 0.0) + session.dx + rep.shift(REP_PLACE_MM[0]),
              y0, force, tempo, contact_s)
    return p.pressure(xy)


def _push(p: Patches, person: Person, rep: _Rep, t: np.ndarray, x0: float, y0: float,
          force: float, tempo: float, contact_s: float) -> None:
    """Version 1's push (:func:`tactbench.datasets.synthetic._push`) in the person's
    variant: flat hand or fingertips, along or across the arm, their own ramp."""
    r = rep.r
    k = person.hand_mm / 180.0
    start = rep.shift(0.05)
    duration = min(person.push_duration * tempo, max(0.3, 0.85 * contact_s - start))
    ramp = _smoothstep((t - start) / duration) ** rep.factor(0.15)
    ease = 1.0 - person.push_ease * _smoothstep((t - start - duration) / 0.6)
    f = force * 0.8 * ramp * ease * (1 + 0.04 * _ar_noise(r, (len(t),)))
    spreading = 0.45 + 0.75 * np.sqrt(np.clip(ramp, 0, 1))
    angle = rep.shift(0.15)
    along = person.push_along != rep.flip(REP_VARIANT_FLIP)
    flat = person.push_flat != rep.flip(REP_VARIANT_FLIP)
    put = push_parts(p, r, len(t), (x0, y0), angle, along, ramp, f, spreading)
    if flat:
        put(0, -30 * k, 8 * k, 22 * k, 0.5 * rep.factor(0.1), 0.0)
        for i in range(4):
            off = (i - 1.5) * 17 * k * person.spread
            put(off, 35 * k, 4.5 * k, 20 * k, 0.5 * person.finger_weights[i] * rep.factor(0.1),
                0.15 * abs(i - 1.5))
    else:
        for i in range(4):
            off = (i - 1.5) * 18 * k * person.spread
            put(off, rep.shift(2.0), 5 * k, 5.5 * k,
                0.9 * person.finger_weights[i] * rep.factor(0.1), 0.1 * abs(i - 1.5))


def release(t: np.ndarray, contact_s: float, tau: float) -> np.ndarray:
    """The hand letting go: 1 while pressing, then ``e^{-(t - contact)/τ}``, exactly 0 once
    below 1 % (the tail has no contact)."""
    env = np.exp(-np.maximum(t - contact_s, 0.0) / tau)
    return np.where(env < 0.01, 0.0, env)


def simulate_sample(device: v1.Device, person: Person, gesture: str, position: str,
                    repetition: int, seed: int) -> Recording:
    """One recording: lead-in without contact, the gesture and its hold, the release,
    and a tail without contact; at most :data:`MAX_FRAMES` frames at 10 Hz."""
    r = _rng("sample-v2", seed, person.name, gesture, position, repetition)
    session = make_session(seed, person, position)
    rep = _Rep(r, person)
    contact = float(np.clip(r.lognormal(math.log(v1.LENGTH_MEDIAN_S), v1.LENGTH_SIGMA)
                            * person.tempo * person.habit(gesture).tempo * session.tempo,
                            *v1.LENGTH_RANGE_S))
    lead = float(np.clip(person.lead_in * rep.factor(REP_LEAD_SIGMA), 0.0, 3.0))
    tail = float(np.clip(person.tail * rep.factor(REP_LEAD_SIGMA), 0.0, 3.0))
    rel_tau = person.release_tau * rep.factor(REP_TIME_SIGMA)
    seconds = lead + contact + 4.6 * rel_tau + tail  # e^-4.6 = 1 %: released
    n_frames = int(np.clip(round(seconds * RATE_HZ), 5, MAX_FRAMES))
    sensor = _rng("session", seed, person.name, position)  # the sensor's, as in version 1
    clock = 1.0 + sensor.normal(0.0, 0.002)
    session_offset = sensor.normal(0.0, v1.SESSION_OFFSET_SD, device.module.max() + 1)
    stamps = np.arange(n_frames) / RATE_HZ * clock
    stamps[1:] += r.normal(0.0, 0.0008, n_frames - 1)
    stamps = np.maximum.accumulate(stamps)
    t = stamps - lead
    pressure = simulate_pressure(gesture, person, session, position, r, t,
                                 device.layout.positions, contact)
    pressure *= release(t, contact, rel_tau)[:, None].astype(np.float32)
    counts = v1.read_sensor(device, pressure, stamps, r, session_offset)
    return Recording(counts, np.round(stamps, 6), device.layout.ids)

