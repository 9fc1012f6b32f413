"""The lab beside the library: sweeps and their reports, the benchmarks and the published studies
with their page writers. Nothing in the library imports it; ``dospcot sweep``, ``report``, ``bench``
and ``study`` do."""
