"""`wallmap status`'s table: counters, and what a live source hears of the robot."""

from __future__ import annotations

from wallmap.status import format_status


def test_a_live_source_s_topics_and_what_is_missing_are_in_the_table() -> None:
    services = [
        {"service": "detector", "live": True, "uptime": 12.0, "counters": {"received": 40}},
        {
            "service": "ros2",
            "live": True,
            "uptime": 11.0,
            "counters": {"frames": 40},
            "topics": {
                "robot1/scan": {"messages": 40, "hz": 10.0, "last_s": 0.1},
                "robot1/tf_static": {"messages": 0, "hz": 0.0, "last_s": None},
            },
            "missing": ["robot1/tf_static: nothing heard"],
        },
    ]
    lines = format_status(services, "wallmap").splitlines()
    assert lines[1].split() == ["detector", "12", "s", "received", "40"]
    assert lines[2].split()[:3] == ["ros2", "11", "s"]
    assert lines[3].strip() == "robot1/scan: 40 messages, 10.0 Hz, last 0.1 s ago"
    assert lines[4].strip() == "robot1/tf_static: 0 messages, 0.0 Hz, never"
    assert lines[5].strip() == "missing: robot1/tf_static: nothing heard"
