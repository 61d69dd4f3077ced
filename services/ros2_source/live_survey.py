"""A live robot's first frames surveyed, as the player surveys a bag before it plays it.

A bag's survey looks at frames spread over the recording before the first is played; a live
robot has only what it has sent so far. So the first posed depth frames (``FRAMES`` of them, or
those of the ``SECONDS`` from the first) are held, with the poses that came meanwhile, and
surveyed (``placement.survey``): which way is up in the fixed frame, where the floor is, and the
height band the sensor sees. Then they go out placed, and every later frame and pose with them.
A scan (one line, no floor) or a robot without poses has nothing to survey.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wallmap.common.messages import Pose
from wallmap.services.player.placement import Placement, Sample, survey

FRAMES = 10  # frames surveyed: the floor and the walls from a few views...
SECONDS = 2.0  # ...or from what the robot's first seconds show, when it sends fewer
SURVEY_ROWS = 60  # rows of an image or cloud read for the survey, spread over its height


@dataclass
class LiveSurvey:
    """The held frames' samples, until there are enough to survey.

    Attributes:
        samples: One per held frame: its points, T_fixed_sensor and sensor frame.
    """

    samples: list[Sample] = field(default_factory=list)
    _first: float | None = None

    def add(
        self,
        stamp: float,
        points: np.ndarray,
        pose: Pose | None,
        mount: np.ndarray,
        sensor_frame: str,
        rows: slice = slice(None),
    ) -> None:
        """A held frame (the first starts the clock); one without a pose is not surveyed.

        ``rows``: the image rows ``points`` holds (``survey_rows``).
        """
        self._first = stamp if self._first is None else min(self._first, stamp)
        if pose is not None:
            self.samples.append(Sample(points, pose.matrix @ mount, sensor_frame, rows))

    def complete(self, newest: float) -> bool:
        """Whether enough is held: ``FRAMES`` frames, or ``SECONDS`` of the robot's time."""
        if self._first is None:
            return False
        return len(self.samples) >= FRAMES or newest - self._first >= SECONDS

    def placement(self, robot_frame: str) -> Placement:
        """The levelled fixed frame and the band (``placement.survey``).

        ``robot_frame`` is the frame the poses describe (its forward axis gives the yaw).
        """
        return survey(self.samples, robot_frame)


def survey_rows(height: int) -> slice:
    """The rows of a frame ``height`` high that the survey reads: ``SURVEY_ROWS``, evenly."""
    return slice(None, None, max(1, height // SURVEY_ROWS))
