"""The one exception a bad config raises."""


class ConfigError(ValueError):
    """A config that cannot run; the message is one line naming the key, the value and what is allowed."""
