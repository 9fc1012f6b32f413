"""Every private member of stable-baselines3 that dospcot reads, writes, calls or overrides, by the SB3
class that holds it: one list for the whole project.

The agents subclass SB3's ``DQN`` and ``ReplayBuffer`` through their documented extension hooks, whose
names are private (``_setup_model``, ``_sample_action``, ``_get_samples``, ...), and the batched engine
(:mod:`dospcot.core.sb3_engine`) steps agents one env step at a time through the attributes SB3's own
``collect_rollouts`` uses. ``pyproject.toml`` pins SB3 to the tested range;
``tests/test_sb3_engine.py`` checks that each member exists on the installed SB3 and that the code
touches no private SB3 name this list lacks.
"""

from __future__ import annotations

SB3_PRIVATE_MEMBERS: dict[str, tuple[str, ...]] = {
    "stable_baselines3.dqn.DQN": (
        "_current_progress_remaining",
        "_episode_num",
        "_excluded_save_params",
        "_last_obs",
        "_n_calls",
        "_n_updates",
        "_sample_action",
        "_setup_learn",
        "_setup_model",
        "_store_transition",
        "_update_info_buffer",
        "_update_learning_rate",
        "_vec_normalize_env",
    ),
    "stable_baselines3.common.buffers.ReplayBuffer": ("_get_samples", "_normalize_obs", "_normalize_reward"),
    "stable_baselines3.common.callbacks.BaseCallback": ("_on_step",),
}
"""The private members by the import path of the SB3 class that defines or sets them."""
