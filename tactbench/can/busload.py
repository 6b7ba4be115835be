"""Bus load of CySkin sweeps: frames, bits and the share of the bus a layout needs.

Frame lengths in bits (ISO 11898-1), interframe space of 3 bits included:

- classic, 11-bit id: ``47 + 8n``; 29-bit id: ``67 + 8n`` (``n`` payload bytes);
- bit stuffing adds at most one bit per 4 after the first over SOF … CRC
  (``34 + 8n`` bits standard, ``54 + 8n`` extended): the *worst case* below;
  real payloads stuff far less, so the truth lies between *nominal* and *worst*;
- CAN FD: the arbitration phase (and ACK, EOF, IFS) at ``bitrate``, the data
  phase (ESI, DLC, payload, stuff count, CRC-17/21 with its fixed stuff bits)
  at ``data_bitrate`` (bit-rate switch on). Dynamic stuffing as above.

1558 taxels (modules of 11) at 10 Hz in the default format, 425 classic frames
with 29-bit ids per sweep, take 53 % of a 1 Mbit/s bus (65 % with worst-case stuffing).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from tactbench.can.codec import MAX_TAXELS, FrameFormat, TaxelMap
from tactbench.errors import InputError, check_positive_int

if TYPE_CHECKING:
    import numpy as np


def cyskin_like_ids(n_taxels: int) -> "np.ndarray":
    """Ids of ``n_taxels`` taxels on CySkin-like modules: 11 taxels in slots 0–10 of
    modules 0, 1, 2, ... (``module * 16 + slot``), int64 ``(n_taxels,)``."""
    import numpy as np

    check_positive_int(n_taxels, "the number of taxels")
    if n_taxels > MAX_TAXELS:
        raise InputError(f"{n_taxels} taxels: a CAN bus carries at most {MAX_TAXELS} "
                         f"(4096 modules × 16 slots)")
    k = np.arange(n_taxels, dtype=np.int64)
    return (k // 11) * 16 + k % 11


def frame_bits(n_bytes: int, *, extended: bool, fd: bool = False,
               bitrate: float = 1_000_000, data_bitrate: float | None = None,
               worst_case: bool = False) -> float:
    """Bit times of one data frame, in units of the nominal (arbitration) bit.

    For CAN FD the data-phase bits are scaled by ``bitrate / data_bitrate``.
    """
    if not fd:
        if n_bytes > 8:
            raise InputError(f"classic CAN carries at most 8 bytes, got {n_bytes}")
        bits = (67 if extended else 47) + 8 * n_bytes
        if worst_case:
            bits += ((54 if extended else 34) + 8 * n_bytes - 1) // 4
        return float(bits)
    data_bitrate = data_bitrate or bitrate
    # SOF, id (+SRR, IDE, id ext), RRS, IDE/FDF, res, BRS at the nominal rate.
    arb = 1 + 11 + 1 + 1 + 1 + 1 + 1 + (20 if extended else 0)
    crc = 17 if n_bytes <= 16 else 21
    data = 1 + 4 + 8 * n_bytes + 4 + crc + (crc + 4 + 3) // 4  # ESI..CRC, fixed stuffing
    tail = 1 + 2 + 7 + 3  # CRC delimiter (switches back), ACK, EOF, IFS
    if worst_case:
        arb += (arb - 1) // 4
        data += (5 + 8 * n_bytes) // 4
    return arb + tail + data * (bitrate / data_bitrate)


@dataclass(frozen=True)
class BusLoad:
    """Cost of one sweep on the bus and the share of it at ``rate_hz``."""

    taxels: int
    messages_per_sweep: int
    payload_bytes_per_sweep: int
    bits_per_sweep: float  # nominal (no dynamic stuffing), nominal bit times
    bits_per_sweep_worst: float  # with worst-case stuffing
    bitrate: float
    data_bitrate: float | None
    rate_hz: float
    load: float  # fraction of the bus, nominal
    load_worst: float
    messages_per_second: float
    sweep_ms: float  # time on the wire of one sweep, nominal

    @property
    def fits(self) -> bool:
        """Whether the traffic fits even with worst-case stuffing (load ≤ 100 %)."""
        return self.load_worst <= 1.0

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["fits"] = self.fits
        return out

    def describe(self) -> str:
        """One line for the tools to print."""
        rate = f"{self.bitrate / 1e6:g} Mbit/s"
        if self.data_bitrate:
            rate += f" (data {self.data_bitrate / 1e6:g} Mbit/s)"
        return (f"{self.taxels} taxels → {self.messages_per_sweep} messages/sweep; "
                f"at {self.rate_hz:g} Hz on {rate}: bus load {100 * self.load:.0f} % "
                f"(worst-case stuffing {100 * self.load_worst:.0f} %)"
                + ("" if self.fits else " — does NOT fit"))


def bus_load(taxels: TaxelMap, *, bitrate: float = 1_000_000, rate_hz: float = 10.0,
             data_bitrate: float | None = None) -> BusLoad:
    """Bus load of ``taxels`` (layout + frame format) sending ``rate_hz`` sweeps per second.

    Parameters
    ----------
    taxels : TaxelMap
    bitrate : float
        Nominal (arbitration) bitrate in bit/s, > 0.
    rate_hz : float
        Sweeps per second, > 0.
    data_bitrate : float, optional
        CAN FD data-phase bitrate (bit/s); defaults to ``bitrate``. Ignored for classic CAN.
    """
    if bitrate <= 0 or rate_hz <= 0:
        raise InputError(f"bitrate and rate must be > 0, got {bitrate} and {rate_hz}")
    fmt: FrameFormat = taxels.fmt
    if not fmt.fd:
        data_bitrate = None
    lengths = taxels.payload_lengths()
    kw = dict(extended=fmt.ids == "extended", fd=fmt.fd, bitrate=bitrate,
              data_bitrate=data_bitrate)
    nominal = sum(frame_bits(n, **kw) for n in lengths)
    worst = sum(frame_bits(n, worst_case=True, **kw) for n in lengths)
    return BusLoad(
        taxels=taxels.n_taxels, messages_per_sweep=len(lengths),
        payload_bytes_per_sweep=sum(lengths), bits_per_sweep=nominal,
        bits_per_sweep_worst=worst, bitrate=float(bitrate),
        data_bitrate=float(data_bitrate) if data_bitrate else None, rate_hz=float(rate_hz),
        load=nominal * rate_hz / bitrate, load_worst=worst * rate_hz / bitrate,
        messages_per_second=len(lengths) * rate_hz, sweep_ms=1000.0 * nominal / bitrate)
