"""Every decoder a service runs on received bytes survives broken input: accepted or refused."""

from __future__ import annotations

import pytest

from wallmap.common.codec import MAX_PAYLOAD_BYTES, MessageError, decode
from wallmap.fuzzing import fuzz, samples


@pytest.mark.parametrize("seed", [0, 1])
def test_no_decoder_crashes_on_broken_messages(seed: int) -> None:
    outcomes = fuzz(20_000, seed=seed)
    assert set(outcomes) == set(samples())
    for name, outcome in outcomes.items():
        assert not outcome.crashes, f"{name}: {dict(outcome.crashes)}"
        assert outcome.refused > 0, f"{name}: the fuzzer broke nothing"
        assert outcome.accepted + outcome.refused == outcome.messages


def test_oversized_payloads_are_refused_before_unpacking() -> None:
    with pytest.raises(MessageError, match="over the limit"):
        decode(b"\x80" * (MAX_PAYLOAD_BYTES + 1))
