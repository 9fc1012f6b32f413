"""The co-training core, free of any task: self-paced selection, consensus, the reward classifiers,
the co-trainer, reward classes, key pools, segment labels, and the run that drives SB3 agents round by
round (:mod:`dospcot.core.sb3_round`)."""
