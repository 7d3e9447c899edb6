"""Test helpers shared by the protocol tests: feed bytes in a given chunking, compare outcomes."""

from __future__ import annotations

import random

from effortface.capture_tool.protocols import Decoder, HrSample, get_decoder

#: chunkings every decoder must be indifferent to
CHUNKINGS = ("1", "3", "random", "whole")


def split(data: bytes, chunking: str, seed: int = 7) -> list[bytes]:
    """Cut ``data`` into reads of 1 byte, 3 bytes, random sizes 1..64, or one read."""
    if chunking == "whole":
        return [data]
    if chunking == "random":
        rng, out, i = random.Random(seed), [], 0
        while i < len(data):
            n = rng.randint(1, 64)
            out.append(data[i : i + n])
            i += n
        return out
    n = int(chunking)
    return [data[i : i + n] for i in range(0, len(data), n)]


def decode(protocol: str, data: bytes, chunking: str = "whole", **options: object,
           ) -> tuple[list[HrSample], Decoder]:
    """Decode ``data`` fed in ``chunking`` (every read at t = 0), finish; return samples, decoder."""
    dec = get_decoder(protocol, **options)
    out: list[HrSample] = []
    for chunk in split(data, chunking):
        out += dec.feed(chunk, 0.0)
    return out + dec.finish(), dec
