"""A reply in the format its query asked for: msgpack or JSON, the schema version in both."""

from __future__ import annotations

import json

from wallmap.common.codec import SCHEMA_VERSION, decode, encode, encode_as


def test_a_reply_carries_the_schema_version_in_either_format() -> None:
    body = {"frame": "map", "rooms": [{"id": 0, "area": 16.4}], "doors": []}
    assert encode_as(body, "msgpack") == encode(body)
    assert decode(encode_as(body, "msgpack")) == {"v": SCHEMA_VERSION, **body}
    assert json.loads(encode_as(body, "json")) == {"v": SCHEMA_VERSION, **body}
