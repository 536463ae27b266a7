"""Fixed-layout navigation message fields: one table per message, read by the decoders and written by
the simulator's encoder (so a layout is stated once).

A message is a big integer of ``n_bits`` (bit 0 = the first bit sent = the most significant). A
:class:`Field` is a list of (position, width) parts (BeiDou D1 splits fields around parity bits), a
scale factor (the ICD's LSB) and a signedness (two's complement).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

SC = 3.141592653589793  # semicircles -> rad (the ICDs' π)


@dataclass(frozen=True, slots=True)
class Field:
    parts: tuple[tuple[int, int], ...]  # (first bit, width), most significant part first
    lsb: float = 1.0  # the ICD's scale factor
    signed: bool = False

    @property
    def width(self) -> int:
        return sum(n for _, n in self.parts)


def field(pos: int, n: int, lsb: float = 1.0, signed: bool = False) -> Field:
    """A field in one piece."""
    return Field(((pos, n),), lsb, signed)


def split(*parts: tuple[int, int], lsb: float = 1.0, signed: bool = False) -> Field:
    """A field in several pieces (most significant first)."""
    return Field(tuple(parts), lsb, signed)


class BitReader:
    def __init__(self, value: int, n_bits: int) -> None:
        self.v, self.n = value, n_bits

    def u(self, pos: int, n: int) -> int:
        """Unsigned n bits at ``pos``."""
        return (self.v >> (self.n - pos - n)) & ((1 << n) - 1)

    def raw(self, f: Field) -> int:
        """The field's integer (two's complement resolved when signed)."""
        x = 0
        for pos, n in f.parts:
            x = (x << n) | self.u(pos, n)
        w = f.width
        return x - (1 << w) if f.signed and x >> (w - 1) else x

    def get(self, f: Field) -> float:
        """The field's value in the ICD's units (raw × LSB)."""
        return self.raw(f) * f.lsb


class BitWriter:
    def __init__(self, n_bits: int) -> None:
        self.v, self.n = 0, n_bits

    def put(self, pos: int, n: int, value: int) -> None:
        shift, mask = self.n - pos - n, (1 << n) - 1
        self.v = (self.v & ~(mask << shift)) | ((value & mask) << shift)

    def set_raw(self, f: Field, q: int) -> None:
        w = f.width
        lo, hi = (-(1 << (w - 1)), (1 << (w - 1)) - 1) if f.signed else (0, (1 << w) - 1)
        if not lo <= q <= hi:
            raise ValueError(f"navigation field at bit {f.parts[0][0]}: {q} does not fit {w} bits")
        q &= (1 << w) - 1
        shift = w
        for pos, n in f.parts:
            shift -= n
            self.put(pos, n, q >> shift)

    def set(self, f: Field, x: float) -> None:
        """Write ``x`` (ICD units) rounded to the field's LSB; ValueError when it does not fit."""
        self.set_raw(f, int(round(x / f.lsb)))


def get_all(r: BitReader, table: dict[str, Field]) -> dict[str, float]:
    return {name: r.get(f) for name, f in table.items()}


def set_all(w: BitWriter, table: dict[str, Field], values: dict[str, float]) -> None:
    for name, x in values.items():
        w.set(table[name], x)


def from_words(words: Sequence[int], bits_per_word: int) -> int:
    """The words' low ``bits_per_word`` bits, concatenated (word 0 most significant)."""
    v = 0
    for x in words:
        v = (v << bits_per_word) | (int(x) & ((1 << bits_per_word) - 1))
    return v


def to_words(value: int, n_words: int, bits_per_word: int) -> list[int]:
    """The inverse of :func:`from_words`."""
    m = (1 << bits_per_word) - 1
    return [(value >> (bits_per_word * (n_words - 1 - i))) & m for i in range(n_words)]
