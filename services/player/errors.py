"""Errors the player reports to its users.

Everything that can go wrong with a user's bag, topic choice or pose source is raised as a
`PlayerError` whose message is one readable line: the CLI prints ``str(err)`` instead of a
traceback, so the message must say what is wrong and, where possible, what to do about it.
"""


class PlayerError(Exception):
    """A problem with the player's input that the user can fix (bag, topic, pose source)."""
