"""jaxparam.clock.StageClock: wall-clock seconds per stage."""
import json

import pytest

from jaxparam.clock import StageClock


class FakeTimer:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_stages_run_from_the_previous_mark():
    t = FakeTimer()
    clock = StageClock(timer=t)
    t.now = 1.5
    assert clock("load") == 1.5
    t.now = 4.0
    clock("solve")
    assert clock == {"load": 1.5, "solve": 2.5} and clock.total == 4.0
    assert clock.seconds == {"load": 1.5, "solve": 2.5} and type(clock.seconds) is dict
    assert json.loads(json.dumps(clock)) == clock.seconds      # a plain dict for reports


def test_restart_and_stage_leave_out_what_ran_before():
    t = FakeTimer()
    clock = StageClock(timer=t)
    t.now = 10.0
    clock.restart()                      # ten seconds that belong to no stage
    t.now = 11.0
    clock("a")
    t.now = 20.0
    with clock.stage("b"):
        t.now = 22.0
    assert clock.seconds == {"a": 1.0, "b": 2.0}
    with pytest.raises(RuntimeError):
        with clock.stage("c"):
            t.now = 25.0
            raise RuntimeError("boom")
    assert clock["c"] == 3.0             # recorded although the block raised


def test_real_timer_is_monotone():
    clock = StageClock()
    assert clock("x") >= 0.0
