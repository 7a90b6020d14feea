"""What a campaign's coordinator holds, declared once for the parts of it that use it.

:class:`coordinator.state.Coordinator` is made of parts, each in its own module: its joins, runs and roster
(:class:`coordinator.admission.Admission`), what arrives and how it is handled (:class:`coordinator.receiving.Receiving`),
the histories, migrants and global best (:class:`coordinator.intake.Intake`). Each part works on the state the
coordinator sets up in its ``__init__``; :class:`Held`, the parts' common base, names that state and its types for
the type checker (it holds nothing at run time).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections import Counter, OrderedDict

    import numpy as np

    from coordinator.histories import Gaps, HistoryChecks
    from coordinator.inbox import Inbox
    from coordinator.keys import CampaignKeys
    from coordinator.members import Membership
    from coordinator.progress import IslandView
    from coordinator.records import RunInfo, StoredBest
    from coordinator.sharing import Sharing
    from coordinator.store import Store
    from coordinator.thinning import HistoryPolicy
    from hysid_model.objective import Objective
    from hysid_model.thesis_port import ThesisObjective
    from island.config import CampaignConfig
    from island.island_messages import Migrants
    from island.sealing import ReplayGuard
    from island.secret import CampaignSecret


class Held:
    """The state :class:`coordinator.state.Coordinator` holds (set in its ``__init__``, where each is described), as its
    parts use it."""

    if TYPE_CHECKING:
        store: Store
        config: CampaignConfig
        name: str
        prefix: str
        run_id: str
        keys: CampaignKeys
        signing: bytes
        secret: CampaignSecret
        objective: Objective | ThesisObjective
        inbox: Inbox
        runs: dict[tuple[str, str], RunInfo]
        current: dict[str, str]
        checks: HistoryChecks
        sharing: Sharing
        membership: Membership
        gaps: Gaps
        policy: HistoryPolicy
        islands: dict[tuple[str, str], IslandView]
        run_evaluations: dict[tuple[str, str], int]
        evaluations: int
        migrations: int
        rejected: int
        rejected_backlog: Counter[str]
        rows_since_commit: int
        changed: bool
        stop_reason: str | None
        query_seq: int
        control_seq: int
        control_at: float
        announced_events: int
        follows_migrants: bool
        best: StoredBest | None
        best_message: bytes | None
        best_trace: list[tuple[float, float, int, np.ndarray]]
        _replays: ReplayGuard
        _evaluated: OrderedDict[bytes, float]
        _candidates: dict[str, Migrants]
