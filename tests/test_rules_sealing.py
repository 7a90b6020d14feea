"""The replay rules of island/sealing.py's ReplayGuard: of a sender run's last ``window`` numbers each is taken
once; a number ``window`` or more below the highest one taken is a replay, whether it was seen or not; a number may
run ahead by the burst and the rate since (a token bucket); the least recently heard run is forgotten first."""

from __future__ import annotations

import pytest

from island.sealing import ReplayGuard, check_replay
from island.wire import MessageRejected

KEY = ("history", "island-a", "run-1")


def test_a_number_is_fresh_once_within_the_window_and_a_replay_at_its_edge():
    """Window 8: after numbers 0 and 8, number 1 (7 below the highest) is still inside the window and fresh once;
    number 0 again, and any number 8 or more below the highest (here 8 below 16: number 8 itself), is a replay."""
    guard = ReplayGuard(window=8, burst=64)
    assert [guard.check(KEY, n, now=0.0) for n in (0, 8)] == ["fresh", "fresh"]
    assert guard.check(KEY, 0, now=0.0) == "replay"  # 8 below the highest: at the window's edge
    assert guard.check(KEY, 1, now=0.0) == "fresh" and guard.check(KEY, 1, now=0.0) == "replay"
    assert guard.check(KEY, 16, now=0.0) == "fresh"
    assert guard.check(KEY, 8, now=0.0) == "replay" and guard.check(KEY, 9, now=0.0) == "fresh"
    assert guard.high(KEY) == 16


def test_numbers_never_seen_inside_the_window_are_fresh_after_a_jump():
    """A jump of exactly the window (0 -> 8) forgets nothing it should keep: 1..7 were never seen and are fresh."""
    guard = ReplayGuard(window=8, burst=64)
    guard.check(KEY, 0, now=0.0)
    guard.check(KEY, 8, now=0.0)
    assert [guard.check(KEY, n, now=0.0) for n in range(1, 8)] == ["fresh"] * 7
    assert [guard.check(KEY, n, now=0.0) for n in range(0, 9)] == ["replay"] * 9


def test_a_jump_inside_the_window_keeps_what_was_seen():
    """Window 8: after 0, a jump to 7 keeps 0 as seen (7 below the highest, inside the window): it is a replay."""
    guard = ReplayGuard(window=8, burst=64)
    assert [guard.check(KEY, n, now=0.0) for n in (0, 7)] == ["fresh", "fresh"]
    assert guard.check(KEY, 0, now=0.0) == "replay" and guard.check(KEY, 3, now=0.0) == "fresh"


def test_a_number_may_run_ahead_by_the_burst_and_the_rate_since():
    """Burst 8, 100 a second: from 0, 8 ahead is fresh and 9 more is not until 0.09 s later refilled it; a run's first
    number may be 8 + 100 a second since what is known of it (its join) ahead of that, and anything without it."""
    guard = ReplayGuard(window=64, rate=100.0, burst=8)
    assert guard.check(KEY, 0, now=0.0) == "fresh"
    assert guard.check(KEY, 9, now=0.0) == "ahead" and guard.high(KEY) == 0  # refused: nothing remembered
    assert guard.check(KEY, 8, now=0.0) == "fresh"
    assert guard.check(KEY, 9, now=0.0) == "ahead" and guard.check(KEY, 9, now=0.0099) == "ahead"
    assert guard.check(KEY, 9, now=0.0101) == "fresh"
    assert guard.check(KEY, 9 + 8, now=10.0) == "fresh" and guard.check(KEY, 9 + 17, now=10.0) == "ahead"  # refilled to the burst only
    assert guard.check(("history", "b", "r"), 7 + 8 + 100, known=(7, 1.0), now=0.0) == "fresh"
    assert guard.check(("history", "c", "r"), 7 + 8 + 101, known=(7, 1.0), now=0.0) == "ahead"
    assert guard.check(("history", "d", "r"), 7 + 9, known=(7, -5.0), now=0.0) == "ahead"  # a time ahead counts as none
    assert guard.check(("history", "e", "r"), 2**63 - 1, now=0.0) == "fresh" and guard.high(("history", "none", "r")) == -1


def test_the_least_recently_heard_run_is_forgotten_first():
    guard = ReplayGuard(window=8, runs=2, burst=64)
    a, b, c = (("history", name, "r") for name in "abc")
    guard.check(a, 5, now=0.0)
    guard.check(b, 5, now=0.0)
    guard.check(a, 6, now=0.0)  # a heard last: b goes first
    guard.check(c, 5, now=0.0)
    assert (guard.high(a), guard.high(b), guard.high(c)) == (6, -1, 5)
    assert guard.fresh(a, 4) and not guard.fresh(a, 4) and not guard.fresh(a, 100)


def test_a_replay_or_a_number_too_far_ahead_is_rejected_by_name():
    guard = ReplayGuard(window=8, burst=8)
    check_replay(guard, "history", "isl", "r1", 3)
    with pytest.raises(MessageRejected, match=r"^rejected message \(replay\): history message 3 of 'isl' run 'r1' was seen before$") as seen:
        check_replay(guard, "history", "isl", "r1", 3)
    assert seen.value.reason == "replay"
    with pytest.raises(MessageRejected, match=r"^rejected message \(ahead\): migrants message 20 of 'isl' run 'r2' is further ahead") as ahead:
        check_replay(guard, "migrants", "isl", "r2", 20, known=(3, 0.0))
    assert ahead.value.reason == "ahead"
    check_replay(guard, "history", "isl", "r2", 3)  # another kind or run numbers on its own


def test_the_number_a_jump_reaches_is_itself_seen_and_each_run_numbers_on_its_own():
    guard = ReplayGuard(window=8, burst=64)
    assert [guard.check(KEY, n, now=0.0) for n in (0, 3, 3)] == ["fresh", "fresh", "replay"]
    other = ("history", "island-b", "run-1")
    assert guard.fresh(KEY, 4) and guard.fresh(other, 4) and not guard.fresh(other, 4)


def test_the_burst_refills_from_the_time_of_the_last_number_taken():
    """At 100 s on the clock as at 0: burst 8, 100 a second; 8 ahead right after 8 ahead is refused, 0.1 s later taken."""
    guard = ReplayGuard(window=64, rate=100.0, burst=8)
    assert [guard.check(KEY, n, now=100.0) for n in (0, 8)] == ["fresh", "fresh"]
    assert guard.check(KEY, 16, now=100.0) == "ahead" and guard.check(KEY, 16, now=100.1) == "fresh"


def test_a_run_takes_no_more_memory_than_its_window_however_many_numbers_it_sends():
    """What the guard remembers of a run is a mask of its last ``window`` numbers (a few hundred bytes at the default
    4096), however long the run lives: after 20,000 numbers in order and as many in steps of 3, window 64 keeps at
    most 64 bits of them (the highest number and its mask, as the guard stores them)."""
    guard = ReplayGuard(window=64, burst=64)
    for n in (*range(20_000), *range(20_000, 80_000, 3)):
        assert guard.check(KEY, n, now=float(n)) == "fresh"
    high, mask, *_ = guard._seen[KEY]
    assert high == 79_997 and 0 < mask < 2**64
