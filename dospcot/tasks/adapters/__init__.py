"""What a task builds for one co-training run: the adapters a
:class:`~dospcot.core.cotraining_run.CoTrainingRun` drives (their envs, stores, pools and evaluators).
They import torch and the envs; the task specs of :mod:`dospcot.tasks` import them only to build."""
