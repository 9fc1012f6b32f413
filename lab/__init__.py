"""The lab of the dospcot repository: the published studies and their pages, the benchmarks and the
record's own figures. It imports the library and is never imported by it; it ships apart from the
library's wheel (``lab/pyproject.toml``), with its own command, ``dospcot-lab``."""
