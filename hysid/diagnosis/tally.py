"""How far a diagnosis is, for its progress callback: work done against an estimate of the work to come.

A diagnosis does not know at its start how many effects it will name, so how
many fits it will make. :class:`Tally` counts in fits, a fit of a model whose
force has memory (Bouc-Wen: computed sample by sample) weighing
:data:`MEMORY_FIT_WEIGHT` of the others: each stage says how much it expects
before it runs (:meth:`Tally.expect`; a negative amount when it turns out to
need less, as a round whose contenders are known, or rounds that never come),
and every fit done advances the share done by its part of all that is left
(:meth:`Tally.done`). So the share done never falls when the estimate grows, it
moves on faster when the estimate shrinks, and it reaches 1 only at
:meth:`Tally.finish`: one unit stays expected until then. The callback gets
``(done, total, what)``: ``done`` the work done (in fits, weighted), ``total``
what that makes in all at the share done (``done / total`` is the share).

A stage of its own (a discovery stage, say) calls ``expect(n)`` before its
``n`` fits and ``done(what)`` after each.
"""

from __future__ import annotations

from collections.abc import Callable

MEMORY_FIT_WEIGHT = 8.0
"""What a fit of a model with memory costs in fits of memoryless ones (a diagnosis of the Synth set at 30
points per branch: Bouc-Wen's refits 5.8 and 15.6 s, the others of the same rounds 0.05-2.3 s, 0.9 s on average)."""
Report = Callable[[float, float, str], None]
"""``progress(done, total, what)`` (see the module docstring)."""


class Tally:
    """The work of a diagnosis done and expected, in fits, reported to ``report`` (None: counted only)."""

    def __init__(self, report: Report | None = None) -> None:
        self.report = report
        self.work = 0.0
        """Work done."""
        self.left = 1.0
        """Work still expected, the closing unit of :meth:`finish` included (never below it)."""
        self.share = 0.0
        """The share of the work done, from 0 to 1; it never falls."""

    def expect(self, amount: float) -> None:
        """``amount`` more work is to come (less than expected, if negative; the closing unit stays)."""
        self.left = max(self.left + amount, 1.0)

    def done(self, what: str, weight: float = 1.0) -> None:
        """A fit of ``weight`` done (``what`` it was): the share done grows by its part of what is left; work
        nobody expected counts as if expected, so that the share still grows and stays below 1."""
        self.left = max(self.left, weight + 1.0)
        self.share += (1.0 - self.share) * weight / self.left
        self.left -= weight
        self.work += weight
        self._tell(what)

    def finish(self, what: str) -> None:
        """The work is done: the share is 1."""
        self.share, self.left = 1.0, 0.0
        self._tell(what)

    def _tell(self, what: str) -> None:
        if self.report is not None:
            self.report(self.work, self.work / self.share if self.share > 0 else self.left, what)
