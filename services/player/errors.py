"""Errors the player reports to its users, and the refusals its choices return.

Everything that can go wrong with a user's bag, topic choice or pose source is raised as a
`PlayerError` whose message is one readable line: the CLI prints ``str(err)`` instead of a
traceback, so the message must say what is wrong and, where possible, what to do about it.

The choices made about a bag (``choices``, ``pose_choice``) do not raise: they return a
`Refusal` carrying that line, so ``wallmap doctor`` can report a refusal as a fact while the
player turns it into a `PlayerError`.
"""

from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")


class PlayerError(Exception):
    """A problem with the player's input that the user can fix (bag, topic, pose source)."""


@dataclass(frozen=True)
class Refusal:
    """A choice the player cannot make about a bag.

    Attributes:
        reason: One readable line saying why, exactly as the player's error says it.
    """

    reason: str


def decided(choice: T | Refusal) -> T:
    """The choice made, or the refusal raised as the player's error.

    Raises:
        PlayerError: ``choice`` is a refusal (its reason is the message).
    """
    if isinstance(choice, Refusal):
        raise PlayerError(choice.reason)
    return choice
