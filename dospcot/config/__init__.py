"""The one configuration tree of a run: frozen dataclasses per section, read from TOML presets and
``--set`` overrides, validated without I/O."""
