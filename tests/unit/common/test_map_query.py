"""Which walls a map query's ``bbox`` holds: those with a segment that meets the box."""

from __future__ import annotations

import numpy as np

from wallmap.common.map_query import MapQuery, segment_crosses_box


def test_a_segment_is_in_a_box_only_where_it_meets_it_not_where_its_extent_does() -> None:
    diagonal = ((0.0, 0.0), (4.0, 4.0))
    assert segment_crosses_box(*diagonal, (1.5, 1.5, 2.0, 2.5))
    # The segment's bounding box overlaps this one, the segment passes beside it.
    assert not segment_crosses_box(*diagonal, (3.0, 0.0, 4.0, 1.0))
    assert segment_crosses_box((1.0, -5.0), (1.0, 5.0), (0.0, 0.0, 2.0, 1.0)), "vertical, through"
    assert not segment_crosses_box((3.0, -5.0), (3.0, 5.0), (0.0, 0.0, 2.0, 1.0))
    assert segment_crosses_box((-1.0, 0.5), (0.0, 0.5), (0.0, 0.0, 2.0, 1.0)), "touching an edge"


def test_a_query_holds_a_wall_when_any_of_its_segments_meets_the_box() -> None:
    """Segments as the mapper has them (arrays) or as a map reply carries them (tuples)."""
    wall = [((0.0, 0.0), (4.0, 4.0)), ((6.0, 6.0), (8.0, 8.0))]
    assert MapQuery().crosses(wall), "without a box, every wall"
    assert MapQuery(bbox=(6.5, 6.0, 7.5, 8.0)).crosses(wall)
    assert MapQuery(bbox=(6.5, 6.0, 7.5, 8.0)).crosses(np.array(wall))
    assert not MapQuery(bbox=(3.0, 0.0, 4.0, 1.0)).crosses(wall)
