"""The doctor's conclusion from the facts: the command that maps a recording, or why none does.

Only here do facts become advice. The verdict is drawn from the gathered `Report` alone (which
sensor the player chose, which pose sources it accepts and how many frames each poses), so
the same facts always give the same advice, and the command it gives is one the player runs
as the facts say it will.
"""

import shlex

from wallmap.common.level import Level
from wallmap.doctor_facts import PoseFacts, Report, Verdict
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.pose_sources import parse_pose_source
from wallmap.services.player.tum_folder import TUM_INTRINSICS

# At least this share of sensor frames must get a pose for a pose source to count as complete.
READY_SHARE = 0.95


def _up(path: str, *options: str) -> str:
    """The ``wallmap up`` command line for this recording."""
    return " ".join(["wallmap", "up", shlex.quote(path), "--fast", *options])


def refusal(reason: str) -> Verdict:
    """The verdict when the player refuses the run, with its reason."""
    return Verdict("refused", f"cannot be played: {reason}")


def bag_verdict(
    report: Report, requested: str | None, *, several: bool, asked: str | None = None
) -> tuple[Verdict, PoseFacts | None]:
    """Conclude: which command maps this bag (and with which pose source), or why none does.

    ``requested``: the ``--sensor-topic`` given. ``several``: the player refused to choose
    among several usable sensor topics. ``asked``: the ``--pose-source`` given, judged as the
    player would take it.

    Returns:
        The verdict, and the pose source it recommends (None: none).
    """
    sensor = report.sensor
    assert sensor is not None  # set for every readable bag
    topic_option = ("--sensor-topic", shlex.quote(requested)) if requested else ()
    if sensor.topic is None:
        if several:
            command = _up(report.path, "--sensor-topic", "TOPIC")
            text = f"choose a sensor topic: `{command}` (check it first with doctor --sensor-topic)"
            return Verdict("choose-sensor", text), None
        if requested:  # the player's own reason for refusing that topic
            return Verdict("no-sensor", f"cannot be played: {sensor.decision}"), None
        poses = [p.source for p in report.poses if p.available]
        also = f"; it holds poses only ({', '.join(poses)})" if poses else ""
        return Verdict("no-sensor", f"cannot be played: no usable sensor topic{also}"), None
    if asked is not None:
        return _asked_verdict(report, asked, topic_option)
    accepted = [p for p in report.poses if p.player == "ok" and p.frames_with_pose]
    odometry = _up(report.path, *topic_option, "--odometry")
    if not accepted or not sensor.frames:
        text = f"no poses: use `--pose-source none` with `wallmap odometry` (`{odometry}`)"
        return Verdict("no-poses", text, odometry), None
    # The default (map -> base_link, localised) when it poses enough frames; else the source
    # posing most frames, the first listed on a tie.
    best = max(accepted, key=lambda p: p.frames_with_pose or 0)
    default = next((p for p in accepted if p.default), None)
    if default is not None and (default.frames_with_pose or 0) >= READY_SHARE * sensor.frames:
        best = default
    pose_option = () if best.default else ("--pose-source", shlex.quote(best.source))
    command = _up(report.path, *topic_option, *pose_option)
    share = (best.frames_with_pose or 0) / sensor.frames
    if share >= READY_SHARE:
        return Verdict("ready", f"ready: `{command}`", command), best
    text = (
        f"partly posed: {share:.0%} of frames get a pose from {best.source} (`{command}`); "
        f"or estimate them all from the scans (`{odometry}`)"
    )
    return Verdict("partial-poses", text, command), best


def _asked_verdict(
    report: Report, asked: str, topic_option: tuple[str, ...]
) -> tuple[Verdict, PoseFacts | None]:
    """The verdict with the ``--pose-source`` given: the player's answer for it, no other."""
    try:
        spec = parse_pose_source(asked)
    except PlayerError as err:
        return refusal(str(err)), None
    command = _up(report.path, *topic_option, "--pose-source", shlex.quote(asked))
    if spec.kind == "none":
        text = f"ready, the poses sent by another program (the mapper waits for them): `{command}`"
        return Verdict("ready", text, command), None
    named = [p for p in report.poses if p.source == str(spec)]
    if spec.kind in ("odom", "pose") and spec.topic is None:  # the one topic of that kind
        named = [p for p in report.poses if p.source.startswith(f"{spec.kind}:") and p.available]
        named = named if len(named) == 1 else []
    pose = named[0] if named else None
    with_it = f"cannot be played with --pose-source {asked}"
    if pose is None or not pose.available:
        held = ", ".join(p.source for p in report.poses if p.available) or "none"
        return Verdict("refused", f"{with_it}: the bag has no such poses (it has: {held})"), None
    if pose.player != "ok" or not pose.frames_with_pose or report.sensor is None:
        return Verdict("refused", f"{with_it}: {pose.player or 'no frame gets a pose'}"), None
    share = pose.frames_with_pose / max(report.sensor.frames, 1)
    if share >= READY_SHARE:
        return Verdict("ready", f"ready: `{command}`", command), pose
    text = f"partly posed: {share:.0%} of frames get a pose from {pose.source} (`{command}`)"
    return Verdict("partial-poses", text, command), pose


def tum_verdict(
    report: Report,
    intrinsics: tuple[float, float, float, float],
    depth_scale: float,
    level: Level | None,
) -> Verdict:
    """Conclude for a TUM RGB-D folder, whose one pose source is its trajectory file.

    Args:
        report: The folder's facts (its sensor and its one pose source).
        intrinsics: The camera given (``--intrinsics``).
        depth_scale: The depth units per metre the folder is read with.
        level: What the survey of its frames found: no floor in any frame with TUM's own
            intrinsics says the camera is another one.
    """
    assert report.sensor is not None  # set for every readable folder
    frames, pose = report.sensor.frames, report.poses[0]
    camera = ["--intrinsics", ",".join(f"{v:g}" for v in intrinsics)]
    given = () if pose.default else ("--pose-source", pose.source)
    command = _up(report.path, *camera, "--depth-scale", f"{depth_scale:g}", *given)
    if not pose.available or not pose.frames_with_pose:
        return Verdict("no-poses", f"no poses: give --pose-source tum:FILE (`{command}`)")
    if intrinsics == TUM_INTRINSICS and level and level.frames and level.floor is None:
        # A carried camera sees the floor: with none in any frame, the guessed camera is wrong.
        text = (
            f"check the camera: no floor seen in {level.frames} frames with TUM's intrinsics; "
            f"give the recording's own (`{_up(report.path, '--intrinsics', 'FX,FY,CX,CY')}`)"
        )
        return Verdict("check-camera", text)
    if pose.frames_with_pose >= READY_SHARE * frames:
        return Verdict("ready", f"ready: `{command}`", command)
    share = pose.frames_with_pose / frames
    text = f"partly posed: {share:.0%} of frames get a pose from {pose.source} (`{command}`)"
    return Verdict("partial-poses", text, command)
