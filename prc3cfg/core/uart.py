"""What a UART receives of characters sent at other line settings: the bytes a frame becomes on a
line whose two ends disagree about the baud rate or the character format (docs/line.md "The line").

    idle ‾‾‾‾|start| d0 d1 … d(n-1) |parity|stop…|‾‾‾‾ idle
              0     LSB first         even/odd  1

The sender's characters are laid out as levels in time, back to back; the receiver hunts for a
falling edge, samples the start bit, each data bit, the parity bit and the first stop bit in the
middle of its own bit times, and drops a character whose start bit was a glitch, whose parity is
wrong or whose stop bit is 0 (a framing error) — as a UART that reports those errors and a driver
that discards them. A receiver checks one stop bit only, as UARTs do: a line at 1 stop bit and
one at 2 understand each other, so no probe can tell them apart. A character of fewer than 8
data bits carries only a byte's low bits — even between ends that agree: a PRC 3 frame, binary,
needs 8.

Deterministic: the same bytes at the same settings always become the same bytes. Owns only this
model; who uses it (the emulator, as the far end of a line set up otherwise) is
`prc3cfg.shell.emulator`. Pure.
"""

from __future__ import annotations

from fractions import Fraction

from prc3cfg.core.line import LineSettings


def agree(a: LineSettings, b: LineSettings) -> bool:
    """Whether two ends of a line understand each other's characters: same baud, data bits, parity."""
    return (a.baud, a.data_bits, a.parity) == (b.baud, b.data_bits, b.parity)


def _levels(data: bytes, line: LineSettings) -> list[tuple[Fraction, int]]:
    """The sender's line: (time the level starts, level), in seconds from the first start bit."""
    bit = Fraction(1, line.baud)
    changes: list[tuple[Fraction, int]] = []
    t = Fraction(0)
    for byte in data:
        bits = [(byte >> i) & 1 for i in range(line.data_bits)]
        if line.parity != "none":
            bits.append((sum(bits) + (line.parity == "odd")) % 2)
        for level, length in [(0, bit), *((b, bit) for b in bits), (1, bit * Fraction(line.stop_bits))]:
            if not changes or changes[-1][1] != level:
                changes.append((t, level))
            t += length
    return changes


def received(data: bytes, sent: LineSettings, receiver: LineSettings) -> bytes:
    """The bytes a UART at `receiver`'s settings makes of `data` sent at `sent`'s."""
    if agree(sent, receiver):
        # the top bits never left
        return data if sent.data_bits == 8 else bytes(b & ((1 << sent.data_bits) - 1) for b in data)
    changes = _levels(data, sent)
    starts = [t for t, _ in changes]

    def level(t: Fraction) -> int:
        """The line at time t: the last change at or before it (idle, 1, before and after)."""
        lo, hi = 0, len(changes)
        while lo < hi:
            mid = (lo + hi) // 2
            if starts[mid] <= t:
                lo = mid + 1
            else:
                hi = mid
        return changes[lo - 1][1] if lo else 1

    bit = Fraction(1, receiver.baud)
    out = bytearray()
    hunt = Fraction(0)
    for edge, value in changes:
        if value != 0 or edge < hunt:
            continue  # not a falling edge, or one inside the character being received
        samples = [level(edge + bit * (Fraction(1, 2) + i))
                   for i in range(2 + receiver.data_bits + (receiver.parity != "none"))]
        start, bits, stop = samples[0], samples[1 : 1 + receiver.data_bits], samples[-1]
        hunt = edge + bit * (Fraction(1, 2) + len(samples) - 1)
        if start != 0:
            hunt = edge + bit / 2  # a glitch: hunt again after it
            continue
        parity_ok = (receiver.parity == "none"
                     or (sum(bits) + samples[-2] + (receiver.parity == "odd")) % 2 == 0)
        if parity_ok and stop == 1:
            out.append(sum(b << i for i, b in enumerate(bits)))
    return bytes(out)
