"""What the stage comparisons of unseen.testing share."""

from dataclasses import dataclass


@dataclass(frozen=True)
class StageMistake:
    """A known way to get a stage wrong: its ``name`` (what the emulation is called by) and
    the ``text`` a report names it with."""

    name: str
    text: str
