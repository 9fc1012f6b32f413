"""The one exception a bad config raises."""


def one_line(text: str) -> str:
    """``text`` on one line: line breaks (which a value a person typed may hold) written as ``\\n``."""
    return text.replace("\r", "\\r").replace("\n", "\\n")


class ConfigError(ValueError):
    """A config that cannot run; the message is one line naming the key, the value and what is allowed
    (a line break in it, from a value as given, is written as ``\\n``)."""

    def __init__(self, message: str = "") -> None:
        super().__init__(one_line(str(message)))
