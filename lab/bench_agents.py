"""The agents' rows of ``dospcot-lab bench``: one gradient step of the agent on MiniGrid's egocentric map
(2,535 inputs of 0 and 1, 98 of them on in LavaGapS7), with the sparse first layer and fused Adam of
numerics 3 against the dense layer and Adam of numerics 1 and 2, in one run.

Both agents are the preset's (``[dqn]``: batch 64, ``net_arch`` [128, 128]) on the same env and seed,
their buffers filled by the same uniform steps, each step's reward counted (every sample weighs 1, so
that every gradient step is taken). A measurement is the CPU time (:class:`Clock`) of ``train`` over
``steps`` gradient steps: sampling, both forward passes, the backward pass, clipping and Adam.
"""

from __future__ import annotations

from dospcot.policies import ExpectedSarsaDQN
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config
from dospcot_lab.bench_measure import Clock, Row, alternating

EGO_PRESET, EGO_VIEW = "minigrid-lavagap-dospcot", "ego"
"""The task and view of the agents' rows."""


def ego_agent(sparse_inputs: bool, fused_adam: bool, fill: int, seed: int = 0) -> ExpectedSarsaDQN:
    """The preset's agent on the egocentric map, its buffer holding ``fill`` uniform steps (no gradient
    step taken yet), every stored reward counted as observed.

    :param sparse_inputs: the first layer from the inputs that are on (``ExpectedSarsaDQN``'s).
    :param fused_adam: Adam in one fused kernel.
    """
    cfg = load_config(EGO_PRESET, ["training.rounds=1", f"seed={seed}"])
    run = build_run(cfg)
    env = run.agents[cfg.views.index(EGO_VIEW)].get_env()
    kwargs = {**cfg.dqn.sb3_kwargs(), "buffer_size": fill, "learning_starts": fill}
    agent = ExpectedSarsaDQN(
        "MlpPolicy", env, seed=seed, sparse_inputs=sparse_inputs, fused_adam=fused_adam, **kwargs
    )
    agent.learn(fill)
    agent.replay_buffer.observed[:] = True  # type: ignore[union-attr]
    return agent


def gradient_step_ms(agent: ExpectedSarsaDQN, steps: int) -> float:
    """CPU milliseconds per gradient step over ``steps`` steps of ``agent.train``."""
    clock = Clock("cpu")
    clock.start()
    agent.train(steps, agent.batch_size)
    return 1e3 * clock.stop() / steps


def bench_ego_gradient_step(quick: bool, repeats: int) -> Row:
    """CPU time per gradient step of the egocentric map's agent: numerics 3's sparse first layer and
    fused Adam against the dense layer and Adam."""
    fill, steps = (1_000, 100) if quick else (5_000, 500)
    ours, peer = ego_agent(True, True, fill), ego_agent(False, False, fill)
    for agent in (ours, peer):  # warm-up: allocations and Adam's state
        gradient_step_ms(agent, 10)
    ours_ms, peer_ms = alternating(
        repeats, lambda _: gradient_step_ms(ours, steps), lambda _: gradient_step_ms(peer, steps)
    )
    return Row.measured(
        "Egocentric map's Q-network gradient step, sparse first layer and fused Adam (numerics 3) vs "
        "dense (1, 2): CPU time per step",
        f"`{EGO_PRESET}` view `{EGO_VIEW}` (2,535 inputs), batch 64, [128, 128], {fill:,} uniform steps "
        f"in the buffer, {steps} steps a measurement",
        "CPU-ms",
        ours_ms,
        peer_ms,
        higher_is_better=False,
        target=1 / 3,
    )
