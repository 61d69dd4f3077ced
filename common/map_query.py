"""Which walls a query of ``{prefix}/map/walls`` asks for: one value, read and written here.

A query's selector parameters (``min_obs``, ``tentative``, ``bbox``, ``since``, ``trajectory``,
``format``) are parsed and checked here for the mapper (``MapQuery.from_parameters``), and
written here for clients (``MapQuery.to_parameters``), so the two cannot drift apart. A wrong
parameter is refused with a reply that says which one and why. Pure: asking and answering over
Zenoh is ``common.map_requests``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class MapQuery:
    """Which walls a reply holds: the selector parameters of ``{prefix}/map/walls``.

    Attributes:
        min_obs: walls seen at least this many times.
        tentative: also walls not yet confirmed (possible phantoms).
        bbox: (xmin, ymin, xmax, ymax): walls whose extent crosses this box.
        since: walls seen at or after this stamp.
        trajectory: add the keyframe trajectory.
    """

    min_obs: int = 1
    tentative: bool = False
    bbox: tuple[float, float, float, float] | None = None
    since: float | None = None
    trajectory: bool = False

    @classmethod
    def from_parameters(cls, params: Mapping[str, str]) -> MapQuery:
        """Parse selector parameters; ValueError says which one is wrong and why."""
        unknown = set(params) - {"min_obs", "tentative", "bbox", "since", "trajectory", "format"}
        if unknown:
            msg = f"unknown parameter {sorted(unknown)[0]!r}"
            raise ValueError(msg)
        try:
            min_obs = int(params.get("min_obs") or 1)
        except ValueError:
            msg = f"min_obs must be an integer, got {params.get('min_obs')!r}"
            raise ValueError(msg) from None
        bbox = None
        if params.get("bbox"):
            try:
                xmin, ymin, xmax, ymax = (float(v) for v in params["bbox"].split(","))
            except ValueError:
                msg = f"bbox must be xmin,ymin,xmax,ymax in metres, got {params['bbox']!r}"
                raise ValueError(msg) from None
            if not (xmin <= xmax and ymin <= ymax):
                msg = f"bbox must have xmin <= xmax and ymin <= ymax, got {params['bbox']!r}"
                raise ValueError(msg)
            bbox = (xmin, ymin, xmax, ymax)
        since = None
        if params.get("since"):
            try:
                since = float(params["since"])
            except ValueError:
                msg = f"since must be a stamp in seconds, got {params['since']!r}"
                raise ValueError(msg) from None
        flags = {}
        for name in ("tentative", "trajectory"):
            value = params.get(name, "false")
            if value not in ("true", "false"):
                msg = f"{name} must be true or false, got {value!r}"
                raise ValueError(msg)
            flags[name] = value == "true"
        return cls(min_obs, flags["tentative"], bbox, since, flags["trajectory"])

    def to_parameters(self) -> dict[str, str]:
        """The selector parameters that ask for this selection (defaults left out)."""
        params: dict[str, str] = {}
        if self.min_obs != 1:
            params["min_obs"] = str(self.min_obs)
        if self.tentative:
            params["tentative"] = "true"
        if self.bbox is not None:
            params["bbox"] = ",".join(repr(v) for v in self.bbox)
        if self.since is not None:
            params["since"] = repr(self.since)
        if self.trajectory:
            params["trajectory"] = "true"
        return params

    def crosses(self, segments: Iterable[Sequence[Sequence[float]]]) -> bool:
        """Whether a wall of these segments ((x, y), (x, y)) is in the ``bbox``: one meets it.

        Any wall is, without a ``bbox``. The mapper and a fleet's merge service select alike.
        """
        return self.bbox is None or any(segment_crosses_box(p, q, self.bbox) for p, q in segments)


def segment_crosses_box(
    p: Sequence[float], q: Sequence[float], box: tuple[float, float, float, float]
) -> bool:
    """Whether segment p-q meets the box (xmin, ymin, xmax, ymax): Liang-Barsky clipping."""
    start, end = 0.0, 1.0
    for axis in (0, 1):
        p0, d = float(p[axis]), float(q[axis]) - float(p[axis])
        lo, hi = box[axis], box[axis + 2]
        if abs(d) < 1e-12:
            if not lo <= p0 <= hi:
                return False
            continue
        t0, t1 = sorted(((lo - p0) / d, (hi - p0) / d))
        start, end = max(start, t0), min(end, t1)
    return start <= end
