"""``synthetic-forearm``: the gesture simulator, tactbench's built-in dataset.

Five gestures of the study (Grasp, 2hGrasp, Twist, Push, Pull) performed by
simulated users on the generated 1558-taxel CySkin forearm
(:func:`tactbench.datasets.forearm.cyskin_forearm`), read by a simulated capacitive
sensor at 10 Hz. Default: 38 users × 5 gestures × 2 positions × 5 repetitions
= 1900 samples. The model and its parameters are documented in
``docs/simulator.md``; the numbers live in the constants below.

This module is version 1 of the simulator: its users and gestures, recordings of 5–27
frames starting near first contact (kept so past results stay reproducible:
``synthetic-forearm:version=1``); the skin, contacts and sensor it defines are shared
with version 2, the person model of :mod:`tactbench.datasets.people`. The dataset of
either version is :mod:`tactbench.datasets.synthetic_forearm`.

Fairness (what the study's claim needs): Grasp, Twist and Pull share the same
hand-posture model, so their contact shapes overlap frame by frame; they differ
in their dynamics only. No class is told apart by one trivial cue: sequence
length is drawn from one distribution for all classes, force from per-user
strength, placement from per-user habits.

Everything is deterministic: each user's and each sample's random numbers come
from a SHA-256 of ``(seed, user, ...)``, so a user's samples do not depend on
how many users are generated.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from tactbench.data.layout import SLOTS_PER_ID, TaxelLayout
from tactbench.data.recording import Recording
from tactbench.datasets.forearm import cyskin_forearm
from tactbench.errors import check_choice

CLASSES = ("Grasp", "2hGrasp", "Twist", "Push", "Pull")
POSITIONS = ("front", "side")
RATE_HZ = 10.0

# ---- sheet (unrolled forearm): x around the arm (0..C, wraps), y along it (0..L)
CIRCUMFERENCE_MM = 334.0
LENGTH_MM = 357.0
TOP_X = CIRCUMFERENCE_MM / 2  # the top of the arm (the underside seam is at x = 0)

# ---- users
HAND_LENGTH_MM = (160.0, 200.0)  # uniform
STRENGTH_SIGMA = 0.30  # lognormal, median 1
TEMPO_SIGMA = 0.20  # lognormal duration factor, median 1
RIGHT_HANDED = 0.85

# ---- lengths: one distribution for every gesture
LENGTH_MEDIAN_S, LENGTH_SIGMA, LENGTH_RANGE_S = 1.35, 0.40, (0.5, 2.7)

# ---- sensor
PRESSURE_REF_KPA = 35.0  # peak pressure of a firm fingertip at strength 1
RESPONSE_MAX = 42000.0  # counts at saturation
RESPONSE_KPA = 60.0  # pressure scale of the saturating response
GAIN_SIGMA = 0.12  # per-taxel gain, lognormal
BASELINE_MEAN, BASELINE_SD = 3000.0, 350.0  # counts
SESSION_OFFSET_SD = 80.0  # per (user, position) and module, counts
DRIFT_SD = 30.0  # per sample and module, counts / s
NOISE_SD = 45.0  # white, counts
DEAD_TAXELS = 5  # stuck at their baseline
FOOTPRINT_MM = 2.0  # electrode size, widens each contact (added in quadrature)
SLIP_MM = 0.6  # micro-slips of a held contact: random walk, mm per √s


def _rng(*keys) -> np.random.Generator:
    """A generator seeded from a SHA-256 of ``keys`` (stable across processes)."""
    digest = hashlib.sha256(repr(keys).encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _rise(t: np.ndarray, tau: float) -> np.ndarray:
    """Contact force building up: 0 before contact, ``(1 - e^{-t/τ})²`` after."""
    return (1.0 - np.exp(-np.maximum(t, 0.0) / tau)) ** 2


def _ar_noise(rng: np.random.Generator, shape: tuple[int, ...], rho: float = 0.7) -> np.ndarray:
    """Smooth unit-variance noise along the last axis (AR(1) with coefficient rho)."""
    e = rng.standard_normal(shape)
    out = np.empty(shape)
    out[..., 0] = e[..., 0]
    scale = math.sqrt(1 - rho * rho)
    for k in range(1, shape[-1]):
        out[..., k] = rho * out[..., k - 1] + scale * e[..., k]
    return out


# ------------------------------------------------------------------ users


@dataclass(frozen=True)
class User:
    name: str
    hand_mm: float  # hand length
    strength: float
    tempo: float  # > 1: slower
    right_handed: bool
    p_middle: float  # probability that middle phalanges touch
    p_proximal: float
    p_palm: float
    p_thumb: float
    p_little: float
    finger_weights: np.ndarray  # (4,) index..little
    y_pref: float  # where along the arm
    x_side: float  # how far round the arm the side position is
    pull_sign: tuple[float, float]  # direction of pulling, per position
    twist_sign: float
    push_style: float  # probability of a flat-hand push (else fingertips)
    push_along: float  # probability the hand lies along the arm when pushing


def make_user(seed: int, index: int) -> User:
    r = _rng("user", seed, index)
    right = bool(r.random() < RIGHT_HANDED)
    return User(
        name=f"u{index:02d}",
        hand_mm=float(r.uniform(*HAND_LENGTH_MM)),
        strength=float(r.lognormal(0.0, STRENGTH_SIGMA)),
        tempo=float(r.lognormal(0.0, TEMPO_SIGMA)),
        right_handed=right,
        p_middle=float(r.uniform(0.15, 0.85)),
        p_proximal=float(r.uniform(0.05, 0.6)),
        p_palm=float(r.uniform(0.1, 0.7)),
        p_thumb=float(r.uniform(0.5, 1.0)),
        p_little=float(r.uniform(0.6, 1.0)),
        finger_weights=np.array([1.0, 1.0, 0.85, 0.65]) * r.lognormal(0.0, 0.2, 4),
        y_pref=float(r.uniform(0.3, 0.7) * LENGTH_MM),
        x_side=float(r.uniform(35.0, 75.0)) * (1 if right else -1),
        pull_sign=(float(r.choice([-1.0, 1.0])), float(r.choice([-1.0, 1.0]))),
        twist_sign=(1.0 if right else -1.0) * float(r.choice([1.0, 1.0, -1.0])),
        push_style=float(r.uniform(0.2, 0.9)),
        push_along=float(r.uniform(0.2, 0.8)),
    )


# ----------------------------------------------------------------- patches


class Patches:
    """Contact patches: anisotropic Gaussians whose parameters vary over time.

    Each attribute is ``(K, T)`` except ``angle`` ``(K,)``: centre ``cx, cy``
    (mm), widths ``sx, sy`` (σ, mm, along the patch's own axes), orientation
    ``angle`` (rad, from the x axis) and peak pressure ``amp`` (kPa).
    """

    def __init__(self, n_frames: int) -> None:
        self.t = n_frames
        self.rows: list[tuple[np.ndarray, ...]] = []

    def add(self, cx, cy, sx, sy, amp, angle: float = 0.0) -> None:
        t = self.t
        self.rows.append(tuple(np.broadcast_to(np.asarray(a, dtype=np.float64), (t,))
                               for a in (cx, cy, sx, sy, amp)) + (float(angle),))

    def pressure(self, xy: np.ndarray) -> np.ndarray:
        """Pressure (kPa) at taxel positions ``xy`` ``(N, 2)``: float32 ``(T, N)``."""
        if not self.rows:
            return np.zeros((self.t, len(xy)), dtype=np.float32)
        cx, cy, sx, sy, amp = (np.stack([r[i] for r in self.rows]).astype(np.float32)
                               for i in range(5))
        ang = np.array([r[5] for r in self.rows], dtype=np.float32)
        sx = np.sqrt(sx ** 2 + FOOTPRINT_MM ** 2)
        sy = np.sqrt(sy ** 2 + FOOTPRINT_MM ** 2)
        x = xy[:, 0].astype(np.float32)
        y = xy[:, 1].astype(np.float32)
        half = np.float32(CIRCUMFERENCE_MM / 2)
        dx = np.remainder(x[None, None, :] - cx[:, :, None] + half,
                          np.float32(CIRCUMFERENCE_MM)) - half  # wraps around the arm
        dy = y[None, None, :] - cy[:, :, None]
        c, s = np.cos(ang)[:, None, None], np.sin(ang)[:, None, None]
        u = (dx * c + dy * s) / sx[:, :, None]
        v = (dy * c - dx * s) / sy[:, :, None]
        q = np.exp(-0.5 * (u * u + v * v))
        return np.einsum("kt,ktn->tn", amp, q, optimize=False).astype(np.float32)


@dataclass
class Hand:
    """Where a hand's contacts sit, in sheet coordinates, and how hard each presses."""

    x: np.ndarray  # (K,) centres
    y: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    amp: np.ndarray  # relative, ~1 for a fingertip
    kind: list  # "tip", "middle", "proximal", "palm", "thumb_tip", "thumb"
    angle: np.ndarray


def wrap_hand(user: User, r: np.random.Generator, x0: float, y0: float, d: float,
              mirror: bool = False) -> Hand:
    """A hand wrapped around the arm: palm at ``(x0, y0)``, fingers going round in
    direction ``d`` (±1) and spread along the arm, the thumb going the other way.
    Which parts touch is drawn from the user's habits."""
    k = user.hand_mm / 180.0
    spread = 19.0 * k * (-1 if mirror else 1)  # finger spacing along the arm
    lengths = np.array([0.93, 1.0, 0.96, 0.78])  # index..little
    xs, ys, sxs, sys_, amps, kinds = [], [], [], [], [], []

    def put(x, y, sx, sy, amp, kind):
        xs.append(x), ys.append(y), sxs.append(sx), sys_.append(sy), amps.append(amp)
        kinds.append(kind)

    if r.random() < user.p_palm:
        put(x0, y0 + 0.2 * spread, 13 * k, 20 * k, 0.45, "palm")
    little = r.random() < user.p_little
    for i in range(4):
        if i == 3 and not little:
            continue
        fy = y0 + (i - 1.5) * spread + r.normal(0, 1.5)
        lk = lengths[i] * k
        w = user.finger_weights[i]
        if r.random() < user.p_proximal:
            put(x0 + d * (40 * k + 22 * lk), fy, 12 * lk, 6 * k, 0.35 * w, "proximal")
        if r.random() < user.p_middle:
            put(x0 + d * (40 * k + 45 * lk + 13 * lk), fy, 8 * lk, 6 * k, 0.55 * w, "middle")
        put(x0 + d * (40 * k + 71 * lk + 8 * lk), fy, 6 * k, 5.5 * k, 1.0 * w, "tip")
    if r.random() < user.p_thumb:
        ty = y0 - 1.9 * spread + r.normal(0, 2.0)
        put(x0 - d * 48 * k, ty, 10 * k, 7 * k, 0.4, "thumb")
        put(x0 - d * 78 * k, ty + 0.3 * spread, 7 * k, 6 * k, 0.9, "thumb_tip")
    n = len(xs)
    jitter = r.lognormal(0.0, 0.15, n)  # how each part happens to press this time
    return Hand(np.array(xs), np.array(ys), np.array(sxs), np.array(sys_),
                np.array(amps) * jitter, kinds, np.zeros(n))


# ------------------------------------------------------------- gestures


def _grip(p: Patches, hand: Hand, t: np.ndarray, force: float, tau: float,
          r: np.random.Generator, *, dx=None, dy=None, gain=None, lead=None) -> None:
    """Add a hand's patches: contact builds up with time constant ``tau`` and settles.

    ``dx``/``dy`` ``(K, T)`` move the contacts; ``gain`` ``(K, T)`` scales their
    pressure; ``lead`` ``(K, T, 3)`` adds a second, smaller patch offset by
    ``(ox, oy)`` mm with relative weight ``w`` (pressure piling up on the
    leading edge of a contact under shear).
    """
    n = len(hand.x)
    onset = r.normal(0.0, 0.03, n)  # the fingers land at slightly different times
    overshoot = r.uniform(0.0, 0.25)
    press_hand(p, hand, t, force, tau, overshoot, onset, r, dx=dx, dy=dy, gain=gain,
               lead=lead)


def press_hand(p: Patches, hand: Hand, t: np.ndarray, force: float, tau: float,
               overshoot: float, onset: np.ndarray, r: np.random.Generator, *, dx=None,
               dy=None, gain=None, lead=None) -> None:
    """The contacts of :func:`_grip` once each finger's ``onset`` (s) and the grip's
    ``overshoot`` are chosen: force builds up with ``tau`` and settles, with tremor and
    slip drawn from ``r``; the person model of version 2 chooses onset and overshoot its
    own way and presses the same."""
    n = len(hand.x)
    tremor = 1.0 + 0.03 * _ar_noise(r, (n, len(t)))
    dt = np.diff(t, prepend=t[0] - 1 / RATE_HZ).clip(1e-3)
    slip = np.cumsum(r.normal(0.0, 1.0, (2, n, len(t))) * SLIP_MM * np.sqrt(dt), axis=2)
    for j in range(n):
        tj = t - onset[j]
        env = _rise(tj, tau)
        env = env * (1.0 + overshoot * np.exp(-np.maximum(tj, 0) / (1.5 * tau))) * tremor[j]
        amp = force * PRESSURE_REF_KPA * hand.amp[j] * env
        if gain is not None:
            amp = amp * gain[j]
        grow = 0.75 + 0.25 * np.cbrt(np.clip(env, 0, None))  # Hertz: radius ∝ F^(1/3)
        cx = hand.x[j] + slip[0, j] + (0 if dx is None else dx[j])
        cy = hand.y[j] + slip[1, j] + (0 if dy is None else dy[j])
        sx, sy = hand.sx[j] * grow, hand.sy[j] * grow
        p.add(cx, cy, sx, sy, amp, hand.angle[j])
        if lead is not None:
            ox, oy, w = lead[j, :, 0], lead[j, :, 1], lead[j, :, 2]
            p.add(cx + ox, cy + oy, 0.6 * sx, 0.6 * sy, amp * w, hand.angle[j])


def _strokes(t: np.ndarray, start: float, duration: float, n: int,
             r: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Progress 0→1 over ``duration`` s in ``n`` strokes, and its rate (1/s)."""
    bounds = np.sort(r.uniform(0.3, 0.7, n - 1)) if n > 1 else np.array([])
    edges = np.concatenate([[0.0], bounds, [1.0]])
    share = np.diff(edges)
    phi = np.zeros_like(t)
    for i in range(n):
        a = start + duration * edges[i]
        phi += share[i] * _smoothstep((t - a) / (duration * share[i]))
    rate = np.gradient(phi, t) if len(t) > 1 else np.zeros_like(t)
    return phi, rate


def simulate_pressure(gesture: str, user: User, position: str, r: np.random.Generator,
                      t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Pressure (kPa) at the taxels ``xy`` over contact times ``t`` (s): ``(T, N)``."""
    check_choice(gesture, "gesture", CLASSES)
    p = Patches(len(t))
    k = user.hand_mm / 180.0
    # where the hand goes: the user's habit, the position, and this repetition
    side = position == "side"
    x0 = TOP_X + (user.x_side if side else 0.0) + r.normal(0, 12)
    y0 = np.clip(user.y_pref + r.normal(0, 15), 60, LENGTH_MM - 60)
    d = 1.0 if user.right_handed else -1.0
    if side:  # from the side, fingers wrap over the top
        d = -d if r.random() < 0.3 else d
    force = user.strength * r.lognormal(0.0, 0.2)
    tau = r.uniform(0.06, 0.11) * user.tempo  # Grasp settles (95 %) in ~0.25–0.45 s
    length = t[-1] - t[0] + 1 / RATE_HZ
    n_strokes = 1 if r.random() < 0.6 else 2
    x0 -= d * 40 * k  # centre the wrapped hand (palm to fingertips) near x0

    if gesture == "Grasp":
        hand = wrap_hand(user, r, x0, y0, d)
        _grip(p, hand, t, force, tau, r)
    elif gesture == "2hGrasp":
        sep = r.uniform(85, 110) * k
        delay = r.uniform(0.0, 0.35)
        share = r.uniform(0.5, 0.8, 2)  # the two hands share the effort
        h1 = wrap_hand(user, r, x0, y0 - sep / 2, d)
        h2 = wrap_hand(user, r, x0 + r.normal(0, 10), y0 + sep / 2, -d, mirror=True)
        _grip(p, h1, t, force * share[0], tau, r)
        _grip(p, h2, t - delay, force * share[1], tau * r.uniform(0.8, 1.25), r)
    elif gesture in ("Twist", "Pull"):
        hand = wrap_hand(user, r, x0, y0, d)
        n = len(hand.x)
        start = r.uniform(0.1, 0.35) * user.tempo
        duration = min(r.uniform(0.5, 1.6) * user.tempo, max(0.3, 0.8 * length - start))
        phi, rate = _strokes(t, start, duration, n_strokes, r)
        rate_n = rate / (rate.max() + 1e-9)
        tips = np.array([kd in ("tip", "thumb_tip") for kd in hand.kind])
        if gesture == "Twist":
            # the hand rolls round the arm's axis: contacts move round (x), the
            # fingertips press harder as torque builds, with ripples while turning
            sign = user.twist_sign
            amount = r.uniform(6.0, 16.0) * sign
            kappa = r.uniform(0.3, 0.8)
            ripple = 0.15 * np.sin(2 * np.pi * r.uniform(1.0, 2.5) * t + r.uniform(0, 2 * np.pi))
            gate = 4 * phi * (1 - phi)
            gain = np.where(tips[:, None], 1 + kappa * phi + ripple * gate,
                            1 - 0.3 * phi)[:, :]
            dx = np.outer(np.where(tips, 1.0, 0.7), amount * phi)
            lead = np.zeros((n, len(t), 3))
            lead[:, :, 0] = sign * 0.8 * hand.sx[:, None]
            lead[:, :, 2] = 0.5 * kappa * rate_n[None, :] + 0.15 * phi[None, :]
            _grip(p, hand, t, force * r.uniform(0.7, 0.95), tau, r, dx=dx, gain=gain,
                  lead=lead)
        else:
            # pulled along the arm: contacts shift along its axis (y), grip force
            # rises with the load, pressure piles up on the leading edges
            sign = user.pull_sign[int(side)]
            amount = r.uniform(5.0, 15.0) * sign
            kappa = r.uniform(0.1, 0.4)
            gain = np.broadcast_to(1 + kappa * phi, (n, len(t)))
            dy = np.outer(np.ones(n), amount * phi)
            lead = np.zeros((n, len(t), 3))
            lead[:, :, 1] = sign * 0.8 * hand.sy[:, None]
            lead[:, :, 2] = 0.4 * rate_n[None, :] + 0.2 * phi[None, :]
            _grip(p, hand, t, force * r.uniform(0.75, 1.0), tau, r, dy=dy, gain=gain,
                  lead=lead)
    else:  # Push
        _push(p, user, r, t, TOP_X + (user.x_side if side else 0.0) + r.normal(0, 15),
              y0, force, length)
    return p.pressure(xy)


def push_parts(p: Patches, r: np.random.Generator, n: int, centre: tuple[float, float],
               angle: float, along: bool, ramp: np.ndarray, force: np.ndarray,
               spreading: np.ndarray) -> Callable[..., None]:
    """``put(ox, oy, sx, sy, amp, reach)`` for a pushing hand (both simulator versions):
    adds to ``p`` a part at offset (ox, oy) mm from the hand's ``centre``, of widths
    (sx, sy), rotated by ``angle`` (fingers ``along`` the arm or across it), that touches
    once the push's ``ramp`` exceeds ``reach`` (0 = at once); ``force`` and ``spreading``
    are the push's over the ``n`` frames."""
    x0, y0 = centre
    c, s = math.cos(angle), math.sin(angle)

    def put(ox, oy, sx, sy, amp, reach):
        on = np.clip((ramp - reach) / 0.35, 0, 1) if reach > 0 else 1.0
        gx, gy = (ox, oy) if along else (oy, ox)
        wx, wy = (sx, sy) if along else (sy, sx)
        x = x0 + gx * c - gy * s
        y = y0 + gx * s + gy * c
        p.add(x + r.normal(0, 0.5, n).cumsum() * 0.3, y, wx * spreading,
              wy * (0.8 + 0.2 * spreading), PRESSURE_REF_KPA * amp * force * on, angle)
    return put


def _push(p: Patches, user: User, r: np.random.Generator, t: np.ndarray, x0: float,
          y0: float, force: float, length: float) -> None:
    """An open hand (or its fingertips) pushing the arm away: pressure rises over
    most of the gesture while the contact spreads, outer parts touching last."""
    k = user.hand_mm / 180.0
    start = r.uniform(-0.05, 0.1)
    duration = min(r.uniform(0.5, 1.6) * user.tempo, max(0.3, 0.85 * length - start))
    ramp = _smoothstep((t - start) / duration) ** r.uniform(0.8, 1.4)
    # the arm gives way a little once pushed: force eases off after the peak
    ease = 1.0 - r.uniform(0.0, 0.35) * _smoothstep((t - start - duration) / 0.6)
    f = force * r.uniform(0.6, 1.0) * ramp * ease * (1 + 0.04 * _ar_noise(r, (len(t),)))
    spreading = 0.45 + 0.75 * np.sqrt(np.clip(ramp, 0, 1))  # contact widens with force
    angle = r.normal(0.0, 0.3)
    along = r.random() < user.push_along  # fingers along the arm, or across it
    put = push_parts(p, r, len(t), (x0, y0), angle, along, ramp, f, spreading)
    if r.random() < user.push_style:  # flat hand
        put(0, -30 * k, 8 * k, 22 * k, 0.5 * r.lognormal(0, 0.2), 0.0)  # palm
        for i in range(4):
            off = (i - 1.5) * 17 * k
            put(off, 35 * k, 4.5 * k, 20 * k, 0.5 * r.lognormal(0, 0.2),
                0.15 * abs(i - 1.5))  # outer fingers meet the curved arm later
    else:  # fingertips
        for i in range(4):
            off = (i - 1.5) * 18 * k
            put(off, r.normal(0, 3), 5 * k, 5.5 * k, 0.9 * r.lognormal(0, 0.2),
                0.1 * abs(i - 1.5))


# -------------------------------------------------------------- the sensor


@dataclass(frozen=True)
class Device:
    """The simulated skin: layout, per-taxel gain and baseline, dead taxels."""

    layout: TaxelLayout
    gain: np.ndarray  # (N,)
    baseline: np.ndarray  # (N,) counts
    dead: np.ndarray  # (N,) bool
    module: np.ndarray  # (N,) module index 0..M-1


def make_device(seed: int, n_taxels: int = 1558) -> Device:
    layout = cyskin_forearm(n_taxels, circumference_mm=CIRCUMFERENCE_MM,
                            length_mm=LENGTH_MM, seed=seed)
    r = _rng("device", seed, n_taxels)
    n = layout.n_taxels
    dead = np.zeros(n, dtype=bool)
    dead[r.choice(n, size=min(DEAD_TAXELS, n // 50), replace=False)] = True
    _, module = np.unique(layout.ids // SLOTS_PER_ID, return_inverse=True)
    return Device(layout, r.lognormal(0.0, GAIN_SIGMA, n),
                  r.normal(BASELINE_MEAN, BASELINE_SD, n), dead, module)


def read_sensor(device: Device, pressure: np.ndarray, t: np.ndarray,
                r: np.random.Generator, session_offset: np.ndarray) -> np.ndarray:
    """Counts ``(T, N)``: saturating capacitive response, baseline + drift, noise,
    16-bit quantisation; dead taxels stuck at their baseline."""
    resp = RESPONSE_MAX * device.gain * (1.0 - np.exp(-pressure / RESPONSE_KPA))
    drift = r.normal(0.0, DRIFT_SD, device.module.max() + 1)[device.module]
    base = device.baseline + session_offset[device.module]
    counts = resp + base + np.outer(t - t[0], drift) + r.normal(0.0, NOISE_SD, resp.shape)
    counts[:, device.dead] = np.round(device.baseline[device.dead])
    return np.clip(np.round(counts), 0, 65535).astype(np.float32)


def simulate_sample(device: Device, user: User, gesture: str, position: str,
                    repetition: int, seed: int) -> Recording:
    """One recording: ``5–27`` frames at 10 Hz starting near first contact."""
    r = _rng("sample", seed, user.name, gesture, position, repetition)
    seconds = float(np.clip(r.lognormal(math.log(LENGTH_MEDIAN_S), LENGTH_SIGMA) * user.tempo,
                            *LENGTH_RANGE_S))
    n_frames = int(np.clip(round(seconds * RATE_HZ), 5, 27))
    session = _rng("session", seed, user.name, position)
    clock = 1.0 + session.normal(0.0, 0.002)
    session_offset = session.normal(0.0, SESSION_OFFSET_SD, device.module.max() + 1)
    stamps = np.arange(n_frames) / RATE_HZ * clock
    stamps[1:] += r.normal(0.0, 0.0008, n_frames - 1)
    stamps = np.maximum.accumulate(stamps)
    onset = r.uniform(-0.15, 0.1)  # contact starts just before or after the first frame
    pressure = simulate_pressure(gesture, user, position, r, stamps - onset,
                                 device.layout.positions)
    counts = read_sensor(device, pressure, stamps, r, session_offset)
    return Recording(counts, np.round(stamps, 6), device.layout.ids)
