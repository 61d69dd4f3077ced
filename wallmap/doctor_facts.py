"""The facts ``wallmap doctor`` reports, as plain dataclasses that turn into JSON as they are.

Kept apart from the code that gathers them (``doctor_inspect`` and the modules it calls), the
code that concludes from them (``doctor_verdict``) and the code that words them (``doctor_text``)
so a script reading ``wallmap doctor --json`` has one place that says what each field means.
Times called ``start``/``at`` are seconds since the report's ``t0`` (the first sensor header
stamp, or the first pose stamp of a bag without a sensor), because absolute ROS stamps are
unreadable and may come from a simulated clock.
"""

from dataclasses import dataclass, field
from typing import Any, Literal

# How long poses may be missing before it is worth saying (tf2 and odometry publish at 10 Hz
# or more), and how far consecutive stamps may be apart before it counts as a clock jump.
GAP_LIMIT = 0.5
JUMP_LIMIT = 1.0
# Intervals listed one by one in the JSON; more are only counted.
LISTED = 10

VerdictStatus = Literal[
    "ready", "partial-poses", "no-poses", "choose-sensor", "no-sensor", "check-camera", "refused"
]


@dataclass
class Gap:
    """A stretch of time: ``start`` s after t0, lasting ``length`` s (negative: a step back)."""

    start: float
    length: float


@dataclass
class Intervals:
    """Gaps or clock steps of one stream: how many, the largest, and the first few.

    Attributes:
        count: How many there are.
        largest: The longest (for steps back: the farthest back), or None if there are none.
        first: The first ``LISTED`` of them, in time order.
    """

    count: int = 0
    largest: Gap | None = None
    first: list[Gap] = field(default_factory=list)


@dataclass
class FileFacts:
    """What the file itself says, readable or not.

    Attributes:
        size: Bytes on disk (the sum over a ROS 2 bag folder's files).
        magic: The first line of the file (of the storage file for a folder), printable.
        format: ``ros1``, ``ros2-sqlite3`` or ``ros2-mcap``; None when the magic is none of them.
        name_matches: Whether the file name's suffix is the one rosbags needs for that format.
        ros1_header: A ROS 1 bag 2.0's header record (``chunk_count``, ``conn_count``,
            ``index_pos``), which says where the index should be even when it is damaged.
    """

    size: int
    magic: str
    format: str | None
    name_matches: bool
    ros1_header: dict[str, int] | None = None


@dataclass
class TopicFacts:
    """One topic: its name as spelled in the bag, message type and message count."""

    name: str
    type: str
    count: int


@dataclass
class SensorFacts:
    """The sensor topic the player chooses (BagSource's decision), and what its frames hold.

    Attributes:
        topic: The chosen topic, or None when the player finds none or several.
        type: Its message type.
        decision: Why this topic, or the player's own reason for having none.
        frames: Number of messages.
        rate_hz: Median rate from the header stamps.
        frame_ids: Sensor frame names (without a leading '/') and how many messages use each.
        geometry: Size and layout: width/height/fields/point_step of a cloud, width/height/
            encoding of a depth image, beams/angles (rad)/range limits (m) of a scan.
        invalid: Share of points with no return, as the player decodes them.
        invalid_frames: How many frames ``invalid`` was measured on (every scan; the first few
            clouds or images).
    """

    topic: str | None
    type: str | None
    decision: str
    frames: int = 0
    rate_hz: float | None = None
    frame_ids: dict[str, int] = field(default_factory=dict)
    geometry: dict[str, Any] = field(default_factory=dict)
    invalid: float | None = None
    invalid_frames: int = 0


@dataclass
class EdgeFacts:
    """One tf link parent -> child: static (/tf_static) or dynamic, with its samples' times."""

    parent: str
    child: str
    static: bool
    samples: int
    start: float | None = None
    end: float | None = None
    gaps: Intervals = field(default_factory=Intervals)


@dataclass
class ChainFacts:
    """Whether tf connects two frames, through which frames, and how each link is published.

    Attributes:
        source: The first frame named (e.g. the sensor frame, or map).
        target: The second (e.g. base_link).
        found: Whether a chain exists.
        path: The frames along the chain, from source to target.
        kinds: ``static`` or ``dynamic`` for each link of the path.
        reason: Why there is no chain.
    """

    source: str
    target: str
    found: bool
    path: list[str] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)
    reason: str | None = None


@dataclass
class TfFacts:
    """The bag's tf tree: frames, links, the chains the player needs, refused transforms."""

    frames: list[str] = field(default_factory=list)
    edges: list[EdgeFacts] = field(default_factory=list)
    chains: list[ChainFacts] = field(default_factory=list)
    refused: int = 0
    refused_example: str | None = None


@dataclass
class PoseFacts:
    """One candidate ``--pose-source``: what it covers, and whether the player accepts it.

    Attributes:
        source: The ``--pose-source`` value, e.g. ``tf:map>base_link`` or ``odom:/odom``.
        default: Whether it is the player's default (``tf``).
        available: Whether the bag holds its data (the tf chain, or messages on the topic).
        reason: Why it is not available.
        samples: Pose samples (for tf: those of the sparsest dynamic link; 0 if all static).
        start: First covered time (None: a static chain covers all times).
        end: Last covered time.
        gaps: Stretches longer than ``GAP_LIMIT`` without a sample.
        player: ``ok`` when BagSource opens the bag with this pose source, else its error;
            None when not checked (the bag has no sensor topic to open it with).
        warnings: What BagSource assumed with this source (e.g. an identity mounting).
        placement: How the player places frames with this source: the tilt of the fixed frame
            and its floor found from the depth data, how sure, and the band the sensor sees.
        frames_with_pose: Sensor frames that get a pose, as the player interpolates them.
        frames_in_gaps: Sensor frames whose pose is interpolated across a gap.
    """

    source: str
    default: bool
    available: bool
    reason: str | None = None
    samples: int = 0
    start: float | None = None
    end: float | None = None
    gaps: Intervals = field(default_factory=Intervals)
    player: str | None = None
    warnings: list[str] = field(default_factory=list)
    placement: str | None = None
    frames_with_pose: int | None = None
    frames_in_gaps: int | None = None


@dataclass
class ClockFacts:
    """The stamps of one topic in bag order: steps back, jumps, and header vs receive time.

    Attributes:
        topic: The topic.
        messages: How many messages.
        backward: Header stamps earlier than the one before (lengths < 0).
        jumps: Header stamps more than ``JUMP_LIMIT`` after the one before.
        receive_jumps: The same for the recorder's receive times (start: since the bag's start).
        zero_stamps: Header stamps left at zero; the player uses the receive time for those.
        offset: Median of header stamp minus receive time (s): transport delay, or a sign that
            header stamps come from another clock (simulation time) when it is large.
        offset_spread: Largest distance of a message's offset from that median (s).
    """

    topic: str
    messages: int
    backward: Intervals = field(default_factory=Intervals)
    jumps: Intervals = field(default_factory=Intervals)
    receive_jumps: Intervals = field(default_factory=Intervals)
    zero_stamps: int = 0
    offset: float | None = None
    offset_spread: float | None = None


@dataclass
class Verdict:
    """The one-line conclusion and the command it recommends, if any."""

    status: VerdictStatus
    text: str
    command: str | None = None


@dataclass
class LatencyFacts:
    """The pose source's latency the mapper would use, as the walls estimate it.

    Attributes:
        seconds: The latency (s): the source's pose of an instant is stamped this much later;
            None where it could not be estimated (``note`` says why).
        sd: Its standard deviation (s).
        frames: The frames it was estimated from.
        note: Why there is no estimate, or how it was had.
    """

    seconds: float | None
    sd: float | None
    frames: int
    note: str


@dataclass
class Report:
    """Everything ``wallmap doctor`` says about one bag.

    Attributes:
        path: The bag as given.
        file: What the file itself says.
        chunks: How a ROS 1 bag's chunks are compressed (``none``, ``lz4``, ``bz2``); None for
            a ROS 2 bag, or one nothing reads.
        readable: Whether the player can read the bag at all.
        start: Receive time of the first message, seconds since the epoch.
        duration: Seconds from the first message to the last.
        t0: Origin of the relative times in this report (a header stamp, seconds).
        topics: Every topic with its type and count.
        sensor: The player's sensor decision and what the sensor frames hold.
        tf: The tf tree.
        poses: Every candidate pose source, the default (tf) first.
        clock: Stamps of the sensor topic and the pose topics.
        warnings: What the player would warn about with the recommended pose source.
        placement: How the player would place the frames with it (level, floor, band).
        latency: The pose source's latency the mapper would use (``--latency``: estimated).
        verdict: The conclusion.
    """

    path: str
    file: FileFacts
    chunks: str | None = None
    readable: bool = False
    start: float | None = None
    duration: float | None = None
    t0: float | None = None
    topics: list[TopicFacts] = field(default_factory=list)
    sensor: SensorFacts | None = None
    tf: TfFacts = field(default_factory=TfFacts)
    poses: list[PoseFacts] = field(default_factory=list)
    clock: list[ClockFacts] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    placement: str | None = None
    latency: LatencyFacts | None = None
    verdict: Verdict = field(default_factory=lambda: Verdict("refused", "not inspected"))

    @property
    def exit_status(self) -> int:
        """1 when the player would refuse the run, else 0 (even if the bag has no sensor).

        It refuses a bag it cannot read at all, and a ``--pose-source`` the bag cannot give.
        """
        return 0 if self.readable and self.verdict.status != "refused" else 1
