"""The run: one config trained in its run folder (train, resume, evaluate), the files every round
writes, interrupts, and how each kind of config trains (co-training runs of SB3 agents; the seed
paper's tabular protocol)."""
