"""Warnings that travel with the data to the result: files -> loops -> fit, campaign, diagnosis -> report.

A :class:`~hysid_model.errors.HysidWarning` goes to stderr (the command line) or
to Python's warnings; a reader of ``result.json`` or ``report.md`` would never see
it. So whatever hysid warns while it loads a dataset is also kept in
``loops.meta["warnings"]`` (a loop set made from those files carries it into
every fit, and a campaign's configuration into its database), and whatever it
warns while it fits is kept by the result; each result lists both, and its own
judgments (a model that misses the data, a parameter on a bound), as
``warnings``: plain ``{"code": ..., "message": ...}`` objects, ``code`` one of
:data:`CODES`.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, TypeVar

from hysid_model.errors import HysidWarning

CODES = {
    # reading the files
    "no_unit": "a displacement or force channel states no unit and is read as SI",
    "records_left_out": "files of the dataset directory that hold no record were left out",
    "preamble_skipped": "lines of free text before a CSV record's header were skipped (skip_rows says how many)",
    "estimated_frequencies": "no manifest: the records' frequencies were estimated from the data",
    "sub_loops": "a displacement that reverses more than twice per cycle (sub-loops, a clipped top)",
    "distortion": "the displacement is not a pure sine (THD above 5 %)",
    "clipping": "a flat displacement, force or velocity peak (a stroke, range or speed limit)",
    "drift": "the displacement or force amplitude drifts over the steady window",
    # data slips found from the physics (hysid_model.slips)
    "swapped_columns": "force and displacement look swapped: the loops generate energy",
    "sign_reversed": "the force's (or the displacement's) sign looks reversed: the loops generate energy",
    "energy_generated": "the loops generate energy, which no passive specimen does",
    "unit_slip_displacement": "the displacement's unit looks wrong (mm under a metre header, or the reverse)",
    "unit_slip_force": "the force's unit looks wrong (kN under a newton header, or the reverse)",
    "unit_slip": "a unit slip of the displacement, the force or the given mass, which the data cannot tell apart",
    "mass_contradicted": "the loops' inertia contradicts the given mass meq_kg",
    # the fit's own judgments (hysid.report.text.fit_warnings)
    "mass_unknown": "the mass is fitted but the loops show no inertia to estimate it from",
    "mass_implausible": "the fitted mass is not what the loops' inertia supports",
    "misfit": "the model does not describe the loops: what it leaves is not noise (hysid.adequacy)",
    "stderr_understated": "the residual exceeds the noise, so the standard errors understate the uncertainty",
    "on_bound": "parameters ended on a bound",
    "on_given_bound": "parameters ended on a bound given by the dataset or the call",
    "on_data_bound": "parameters ended on a search bound (from the data or a term's default) even after widening",
    "bounds_widened": "search bounds were widened within the physical ranges after an optimum on one",
    # running
    "single_node_fallback": "Zenoh could not open a session: the campaign ran its islands in one process",
    "warning": "any other warning",
}
"""Every warning code (stable: programs may act on them) and what it means; the message says the particulars."""
META_KEY = "warnings"
"""Where a loop set keeps the warnings of its loading (``loops.meta``)."""
MAX_MESSAGE = 2000
"""Characters of a message a result keeps (a list of hundreds of files left out is cut): a campaign's configuration
carries the loop set's warnings, and its wire format takes no string beyond 10,000."""


@dataclass(frozen=True)
class Notice:
    """One warning as a result keeps it; reads as its message (``f"**{notice}**"``)."""

    code: str
    message: str

    def __str__(self) -> str:
        return self.message

    def as_dict(self) -> dict[str, str]:
        return {"code": self.code, "message": self.message}


def of_warning(warning: HysidWarning) -> Notice:
    """A raised :class:`HysidWarning` as a notice (message on one line)."""
    return Notice(getattr(warning, "code", "warning"), " ".join(str(warning).split()))


def merged(*groups: Iterable[Notice | Mapping[str, Any]]) -> list[dict[str, str]]:
    """The notices of ``groups`` (notices or their dicts) as dicts, in order, each message once (at most
    ``MAX_MESSAGE`` characters)."""
    out: dict[str, dict[str, str]] = {}
    for group in groups:
        for item in group:
            code, message = (item.code, item.message) if isinstance(item, Notice) else (str(item["code"]), str(item["message"]))
            message = message if len(message) <= MAX_MESSAGE else message[: MAX_MESSAGE - 3] + "..."
            out.setdefault(message, {"code": code, "message": message})
    return list(out.values())


def stored(meta: Mapping[str, Any]) -> list[dict[str, str]]:
    """The warnings a loop set's ``meta`` carries (those of its loading); none when absent or malformed (a
    loops file written by hand, a configuration from another version)."""
    found = meta.get(META_KEY)
    if not isinstance(found, list):
        return []
    return merged(w for w in found if isinstance(w, Mapping) and isinstance(w.get("code"), str) and isinstance(w.get("message"), str))


@contextmanager
def recorded() -> Iterator[list[Notice]]:
    """Keep every :class:`HysidWarning` raised inside (whatever the filters say) in the list yielded, and
    warn it again on leaving, so that the command line still prints it and Python's filters still apply.
    Other warnings pass through untouched."""
    kept: list[Notice] = []
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", HysidWarning)
            yield kept
    finally:  # also when the work fails: what it warned before is said
        for w in caught:
            if isinstance(w.message, HysidWarning):
                kept.append(of_warning(w.message))
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)


Work = TypeVar("Work", bound=Callable[..., Any])


def keeps_warnings(work: Work) -> Work:
    """``work`` (a function returning a result with a ``raised`` list) with every :class:`HysidWarning` it raised
    kept in its result's ``raised`` (as dicts), and said as before."""

    @functools.wraps(work)
    def kept(*args: Any, **kwargs: Any) -> Any:
        with recorded() as raised:
            result = work(*args, **kwargs)
        result.raised = merged(raised)
        return result

    return kept  # type: ignore[return-value]
