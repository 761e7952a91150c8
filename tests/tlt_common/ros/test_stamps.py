"""Float seconds into Time/Duration fields: a whole second reached by summing steps is stamped as
that second, never a second early (the twin's /clock once jumped back 1 s at many whole seconds)."""

from __future__ import annotations

from builtin_interfaces.msg import Duration, Time

from tlt_common.ros.stamps import set_stamp, split_seconds


def test_sim_time_summed_in_steps_is_stamped_in_order_and_on_the_whole_second():
    t, stamps = 0.0, []
    for step in range(1, 10_001):
        t += 0.01  # as the twin advances: 36.99999999996 where 37 is meant
        msg = Time()
        set_stamp(msg, t)
        stamps.append((msg.sec, msg.nanosec))
        if step % 100 == 0:
            assert (msg.sec, msg.nanosec) == (step // 100, 0), (step, t, msg)
    assert stamps == sorted(stamps)


def test_split_seconds():
    assert split_seconds(1.5) == (1, 500_000_000)
    assert split_seconds(2.9999999999) == (3, 0)
    assert split_seconds(0.0) == (0, 0)
    assert split_seconds(-0.25) == (-1, 750_000_000)  # Time's convention: nanosec is never negative
    d = Duration()
    set_stamp(d, 12.000000001)
    assert (d.sec, d.nanosec) == (12, 1)
