"""The tf tree of a bag as ``wallmap doctor`` reports it: frames, links, and the chains needed.

The player needs tf for two things, the sensor's mounting (sensor frame -> base_link) and the
robot's pose (map or odom -> base_link); a missing link is the commonest reason a bag plays
badly, so each chain is reported as found (through which frames, static or not) or as missing,
with why: no tf at all, a frame tf does not know, or two separate trees.
"""

from collections import deque

import numpy as np

from wallmap.common.ros_poses import DEFAULT_CHILD, DEFAULT_PARENT
from wallmap.doctor_facts import ChainFacts, EdgeFacts, TfFacts
from wallmap.doctor_times import gap_spans, span_summary
from wallmap.services.player.bag_contents import BagContents, TfLink

MOST_SENSOR_FRAMES = 2  # sensor frames whose tf chain to base_link is reported


def chain(contents: BagContents, source: str, target: str) -> ChainFacts:
    """The shortest chain of links between two frames, whichever way each link points."""
    neighbours: dict[str, list[tuple[str, TfLink]]] = {}
    for link in contents.tf_links.values():
        neighbours.setdefault(link.parent, []).append((link.child, link))
        neighbours.setdefault(link.child, []).append((link.parent, link))
    facts = ChainFacts(source, target, found=False)
    if not neighbours:
        facts.reason = "the bag has no tf"
        return facts
    absent = [repr(f) for f in (source, target) if f not in neighbours]
    if absent:
        facts.reason = f"{' and '.join(absent)} {'is' if len(absent) == 1 else 'are'} not in tf"
        return facts
    previous: dict[str, tuple[str, TfLink] | None] = {source: None}
    queue = deque([source])
    while queue and target not in previous:
        frame = queue.popleft()
        for neighbour, link in neighbours[frame]:
            if neighbour not in previous:
                previous[neighbour] = (frame, link)
                queue.append(neighbour)
    if target not in previous:
        facts.reason = f"{source!r} and {target!r} are in separate tf trees"
        return facts
    path, kinds, frame = [target], [], target
    while (step := previous[frame]) is not None:
        frame, link = step
        path.append(frame)
        kinds.append("static" if link.static else "dynamic")
    facts.found, facts.path, facts.kinds = True, path[::-1], kinds[::-1]
    return facts


def dynamic_links(contents: BagContents, found: ChainFacts) -> list[TfLink]:
    """The dynamic links along a found chain: where the chain's poses can be missing."""
    pairs = zip(found.path, found.path[1:], strict=False)
    links = [contents.tf_links.get((a, b)) or contents.tf_links[(b, a)] for a, b in pairs]
    return [link for link in links if not link.static]


def tf_facts(contents: BagContents, sensor_frames: dict[str, int], t0: float) -> TfFacts:
    """The tf tree: frames, links, and the chains the player needs.

    Args:
        contents: The bag's contents.
        sensor_frames: The sensor's frame names, the most used first.
        t0: The report's time origin (s).
    """
    tf = TfFacts(frames=contents.tf.frames)
    tf.refused = len(contents.tf_refused)
    tf.refused_example = next(iter(contents.tf_refused), None)
    links = sorted(contents.tf_links.values(), key=lambda e: (e.static, e.parent, e.child))
    for link in links:
        facts = EdgeFacts(link.parent, link.child, link.static, len(link.stamps))
        if not link.static:
            facts.start = round(min(link.stamps) - t0, 3)
            facts.end = round(max(link.stamps) - t0, 3)
            facts.gaps = span_summary(gap_spans(np.asarray(link.stamps)), t0)
        tf.edges.append(facts)
    # The sensor's mounting (its most used frames; a frame already base_link needs none).
    mounts = [f for f in sensor_frames if f and f != DEFAULT_CHILD][:MOST_SENSOR_FRAMES]
    pairs = [(frame, DEFAULT_CHILD) for frame in mounts]
    pairs += [(DEFAULT_PARENT, DEFAULT_CHILD), ("odom", DEFAULT_CHILD)]
    tf.chains = [chain(contents, source, target) for source, target in pairs]
    return tf
