"""The basis sizes the controller's hot kernels are compiled for with constant loop lengths.

Numba compiles a loop whose length is a compile-time constant into straight, scheduled code; one whose
length is read at run time into a generic loop, 1.5 to 2 times as slow at these sizes. The adaptation
(:mod:`.adaptation`), the front end and the adaptive laws therefore inline their bodies once per size
listed here, with the size as a constant, and once more for any n (a user's basis); all copies run the
same sums in the same order, so they give the same numbers bit for bit. The sizes are derived from the
shipped bases (not typed), and a test fails if a shipped basis's n is not among them
(``tests/test_adaptation_specialised.py``).
"""
from __future__ import annotations

N_SPECIALISED_SLOTS = 3
"""How many basis sizes the hot kernels are compiled for with constant loop lengths (each one is a copy
of the step in the compiled code, so first-import compile time grows with it)."""


def _specialised_sizes() -> tuple[int, ...]:
    """The n of every shipped basis: the paper's, the extended one's and the learned one's for each shipped
    network (13 + h), smallest first, at most :data:`N_SPECIALISED_SLOTS` of them (the others run the
    generic loops; ``tests/test_adaptation_specialised.py`` fails if a shipped basis's n is left out)."""
    from ..bases import N_PHYSICS, extended, learned

    sizes = {N_PHYSICS, extended.N} | {extended.N + h for h, _, _ in learned.shipped_architectures()}
    return tuple(sorted(sizes))[:N_SPECIALISED_SLOTS]


SPECIALISED_N = _specialised_sizes()
"""The numbers of parameters the hot kernels are also compiled for with constant loop lengths, derived from
the shipped bases (:func:`_specialised_sizes`: 8 for the paper's, 13 for the extended, 17 for the learned
with the shipped h = 4); any other n (a user's basis) runs the same code with loops of run-time length
(1.5-2 times as long). The values are frozen into the compiled code when it is cached: a shipped network
with another h after that runs the generic loops (same numbers) until the package's source changes."""
_SLOT_N = SPECIALISED_N + (0,) * (N_SPECIALISED_SLOTS - len(SPECIALISED_N))
N_SLOT_0 = _SLOT_N[0]
N_SLOT_1 = _SLOT_N[1]
N_SLOT_2 = _SLOT_N[2]
"""The three compiled sizes as the global constants Numba freezes (an unused slot holds 0: no basis has
zero parameters)."""

__all__ = ["N_SLOT_0", "N_SLOT_1", "N_SLOT_2", "N_SPECIALISED_SLOTS", "SPECIALISED_N"]
