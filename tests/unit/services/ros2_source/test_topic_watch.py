"""What the live source says it hears: messages, rates, silences, and what never came."""

from __future__ import annotations

from wallmap.services.ros2_source.topic_watch import TopicWatch


def test_rates_silences_and_what_never_came() -> None:
    watch = TopicWatch(
        {
            "sensor": "robot1/scan",
            "tf": "robot1/tf",
            "tf_static": "robot1/tf_static",
            "pose": "robot1/odom",
        }
    )
    for k in range(50):  # 10 Hz for 5 s
        watch.heard("sensor", 100.0 + 0.1 * k)
        watch.heard("tf", 100.0 + 0.1 * k)
    watch.heard("tf_static", 100.0)
    report = watch.report(now=105.0)
    assert report["topics"]["robot1/scan"] == {"messages": 50, "hz": 10.0, "last_s": 0.1}
    assert report["topics"]["robot1/tf_static"]["messages"] == 1
    assert report["topics"]["robot1/odom"] == {"messages": 0, "hz": 0.0, "last_s": None}
    assert report["missing"] == ["robot1/odom: nothing heard"]  # tf_static is sent once: fine
    later = watch.report(now=110.0)
    assert later["topics"]["robot1/scan"]["hz"] == 0.0
    assert later["missing"] == [
        "robot1/scan: silent for 5 s",
        "robot1/tf: silent for 5 s",
        "robot1/odom: nothing heard",
    ]
