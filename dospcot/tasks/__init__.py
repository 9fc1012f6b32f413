"""The tasks a run can train on, one module each, and the adapters they share: the grid adapter
(:mod:`dospcot.tasks.grid`) and the sensor adapter (:mod:`dospcot.tasks.sensor`)."""
