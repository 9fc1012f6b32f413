"""Sweeps: configs x a grid of keys x seeds, each trial an ordinary run folder, run on a process pool
or Ray (:mod:`~dospcot.sweeps.sweep`, declared by :mod:`~dospcot.sweeps.sweep_spec`), and their
reports: a table per metric over seeds and a plot (:mod:`~dospcot.sweeps.report`), with the seed
paper's Tables 1-4 for its protocol (:mod:`~dospcot.sweeps.paper_tables`)."""
