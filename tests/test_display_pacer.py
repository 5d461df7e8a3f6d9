"""The live tools' display pacer: never more than a window of images in flight to the page, the newest
frame waits (older ones are dropped), no pacing before the page acknowledges, no stall on a lost ack.

The pacer reads ``time.monotonic()``; the tests replace it with a clock they move by hand, so a
paused or loaded machine cannot change what they see (no sleeps, no wall-clock figures).
"""

from __future__ import annotations

import time

import pytest

from dtscal_lib.ui import frameloop
from dtscal_lib.ui.frameloop import DisplayPacer, ack_widgets


class FakeClock:
    """Stands in for the ``time`` module inside frameloop: ``monotonic()`` moves only by :meth:`advance`."""

    def __init__(self):
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds

    def __getattr__(self, name):  # anything else (perf_counter of the frame loop) is the real one
        return getattr(time, name)


@pytest.fixture(autouse=True)
def clock(monkeypatch) -> FakeClock:
    c = FakeClock()
    monkeypatch.setattr(frameloop, "time", c)
    return c


def _pacer(**kw):
    shown = []
    return DisplayPacer(shown.append, **kw), shown


def test_without_acknowledgements_every_frame_is_shown_at_once():
    p, shown = _pacer(window=1)
    for i in range(10):
        assert p.offer(p.next_token(), i)
    assert shown == list(range(10)) and not p.pacing


def test_at_most_window_in_flight_and_only_the_newest_waits():
    p, shown = _pacer(window=1, min_lag=10, timeout=10)
    t1 = p.next_token()
    assert p.offer(t1, "a")
    p.ack(t1)  # the page runs the hook: pacing from now on
    t2 = p.next_token()
    assert p.offer(t2, "b")
    for name in "cde":  # the page has not displayed b yet: c and d are dropped, e waits
        assert not p.offer(p.next_token(), name)
    assert shown == ["a", "b"] and p.dropped == 2
    p.ack(t2)
    assert shown == ["a", "b", "e"]
    p.ack(t2)  # a repeated acknowledgement changes nothing
    assert shown == ["a", "b", "e"]


def test_a_window_of_two_keeps_one_image_in_transit_while_the_next_goes():
    p, shown = _pacer(window=2, min_lag=10, timeout=10)
    t = [p.next_token() for _ in range(4)]
    p.offer(t[0], 0)
    p.ack(t[0])
    assert p.offer(t[1], 1) and p.offer(t[2], 2)
    assert not p.offer(t[3], 3)
    p.ack(t[2])  # 1 was replaced in the page before it loaded: 2's acknowledgement clears both
    assert shown == [0, 1, 2, 3]
    assert p.offer(p.next_token(), 4)


def test_a_page_that_lags_holds_the_next_frame_back(clock):
    p, shown = _pacer(window=10, min_lag=0.05, timeout=10)
    t1 = p.next_token()
    p.offer(t1, "a")
    p.ack(t1)
    assert p.offer(p.next_token(), "b") and p.offer(p.next_token(), "c")  # the page keeps up: nothing waits
    clock.advance(0.04)  # b has been on its way for less than the lag limit: c goes at once
    assert p.offer(p.next_token(), "c2") and p.held == 0
    clock.advance(0.04)  # now b has been on its way longer than the lag limit (0.08 s > 0.05 s)
    t4 = p.next_token()
    assert not p.offer(t4, "d") and p.held == 1
    p.ack(t4 - 1)  # c2 displayed (b and c were replaced in the page): d goes
    assert shown == ["a", "b", "c", "c2", "d"]


def test_a_lost_acknowledgement_does_not_stall_the_view(clock):
    p, shown = _pacer(window=1, min_lag=0.01, timeout=0.05)
    t1 = p.next_token()
    p.offer(t1, "a")
    p.ack(t1)
    p.offer(p.next_token(), "b")  # its acknowledgement never comes
    assert not p.offer(p.next_token(), "c")
    clock.advance(0.049)  # just inside the timeout: b still holds the next frame back
    assert not p.offer(p.next_token(), "c2")
    clock.advance(0.002)  # past it: b is forgotten, d goes
    assert p.offer(p.next_token(), "d")
    assert shown == ["a", "b", "d"]


def test_an_older_frame_never_replaces_a_newer_one():
    p, shown = _pacer(window=1, min_lag=10, timeout=10)
    t1, t2 = p.next_token(), p.next_token()
    p._do_show(t2, "new")
    p._do_show(t1, "old")
    assert shown == ["new"]


def test_ack_widgets_forward_the_page_token():
    p, shown = _pacer(window=1, min_lag=10, timeout=10)
    box = ack_widgets(p)
    text = box.children[0]
    t1 = p.next_token()
    p.offer(t1, "a")
    text.value = str(t1)
    assert p.pacing and len(p.round_trips) == 1
    text.value = "not a number"  # ignored
    assert "dtscal-ack" in text._dom_classes and "onerror" in box.children[1].value
