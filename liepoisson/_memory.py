"""The machine's physical memory, and the check that refuses, before anything is allocated, a
request whose arrays would not fit in it."""

from __future__ import annotations

import os

#: The largest share of the machine's physical memory one request may take.
MEMORY_FRACTION = 0.5
#: The physical memory assumed where the operating system does not report it (`os.sysconf`).
_FALLBACK_MEMORY = 2**40


def physical_memory() -> tuple[int, bool]:
    """The machine's physical memory in bytes (`os.sysconf`), and whether it was reported
    (else `_FALLBACK_MEMORY`, 1 TiB, is assumed)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not available on this platform
        return _FALLBACK_MEMORY, False
    return (int(total), True) if total > 0 else (_FALLBACK_MEMORY, False)


def memory_limit() -> int:
    """The bytes one request may take: `MEMORY_FRACTION` of `physical_memory()`."""
    return int(MEMORY_FRACTION * physical_memory()[0])


def gib(n_bytes: int) -> str:
    """`n_bytes` in GiB, three digits (any Python int: sizes beyond float's range too)."""
    if n_bytes.bit_length() > 1000:
        return f"about 2^{n_bytes.bit_length() - 31} GiB"
    return f"{n_bytes / 2**30:.3g} GiB"


def integer(n: int) -> str:
    """`n` with thousands separators, or its size in bits when it is too long to print."""
    return f"{n:,}" if n.bit_length() <= 200 else f"an integer of {n.bit_length()} bits"


def check_fits_in_memory(need: int, what: str, remedy: str) -> None:
    """`ValueError` if `need` bytes are more than `memory_limit()`: `what` (naming the
    argument) needs them, the memory there is, and `remedy`, how to ask for less."""
    if need <= memory_limit():
        return
    total, reported = physical_memory()
    memory = (f"the machine's {gib(total)} of physical memory" if reported else
              f"the {gib(total)} of physical memory assumed (the system does not report it)")
    raise ValueError(f"{what} would need {gib(need)} ({integer(need)} bytes), more than the {gib(memory_limit())} "
                     f"available to one request ({MEMORY_FRACTION:.0%} of {memory}); {remedy}")
