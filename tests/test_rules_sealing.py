"""The replay rule of island/sealing.py's ReplayGuard: of a sender run's last ``window`` numbers each is taken
once; a number ``window`` or more below the highest one taken is a replay, whether it was seen or not."""

from __future__ import annotations

from island.sealing import ReplayGuard

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
