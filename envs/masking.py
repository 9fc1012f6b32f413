"""Reward masking: the true reward of a transition reaches the learner only when it is labelled.

Three modes (docs/design.md section 1):

- ``"state-action"``: a fixed, seeded subset of the (s, a) keys of a discrete env, of share
  ``label_fraction``, is labelled; the subset is drawn once from ``mask_seed`` and stays the same
  across resets.
- ``"transition"``: each step is revealed with probability ``label_fraction``, from a generator
  seeded by ``mask_seed`` (and re-seeded from ``mask_seed`` and the seed of every seeded reset).
- ``"key"``: as state-action mode for an env whose states are not known in advance: the env names
  each state by a hashable key (``state_key()``, e.g. a MiniGrid agent's pose, load and map),
  and a (key, action) pair is labelled when a hash of it and ``mask_seed`` falls below
  ``label_fraction`` (:func:`key_is_labelled`), so every visit of a pair is labelled or none is.

Segment labels (docs/segments.md): with ``segment_length`` k > 1 no single reward is revealed. The
steps of an episode fall into segments of k (the last one shorter where the episode ends), and a
segment is labelled with probability ``label_fraction`` as a whole: the step that ends it carries
``info["segment_end"] = True`` and, where labelled, ``info["segment_label"]``, the sum of its hidden
rewards (a rater scoring a clip). Segments are drawn in every mode from the generator of transition
mode, so a seeded reset replays them.

State-dependent monitors (the monitored-MDP setting, docs/preregistration.md): what is revealed may
depend on where the agent is. In state-action mode ``monitored_states`` names states whose every
reward is revealed (``label_fraction`` then is the share of the other keys); in transition mode the
first ``reveal_first_steps`` steps of every episode are revealed. Reading hidden rewards as 0 is then
biased, not a rescaling.

A masked step returns reward 0.0 with ``info["reward_observed"] = False``, and loses the reward's
parts an env reports in ``info`` (:data:`REWARD_INFO_KEYS`). The true reward is kept in
``info["hidden_reward"]`` for metrics only.
"""

from __future__ import annotations

import hashlib
from collections.abc import Hashable
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from dospcot.config.checks import check_label_fraction

MaskMode = Literal["state-action", "transition", "key"]
MASK_MODES: tuple[str, ...] = ("state-action", "transition", "key")
REWARD_INFO_KEYS: tuple[str, ...] = ("rewards",)
"""``info`` keys in which an env reports its reward's parts (highway-env and our fast highway do):
a masked step drops them."""


def key_is_labelled(key: Hashable, action: int, label_fraction: float, seed: int) -> bool:
    """Whether the reward of ``action`` in the state named ``key`` is revealed: a hash of
    ``(seed, key, action)`` read as a number in [0, 1) falls below ``label_fraction``.

    The hash is of the pair's ``repr`` (BLAKE2), not Python's ``hash``, which changes from process to
    process for strings: the same key is labelled in every worker and after a resume. A key is best a
    tuple of plain values (ints, strings), whose ``repr`` names it exactly.
    """
    digest = hashlib.blake2b(repr((seed, key, int(action))).encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") / 2.0**64 < label_fraction


class StateActionMask:
    """A seeded subset of the ``n_states * n_actions`` keys of a discrete env.

    Exactly ``round(label_fraction * n_keys)`` of the ``n_keys`` drawn keys are labelled (at least
    one): every key, or with ``monitored_states`` the keys of the other states, whose keys are all
    labelled.

    :param n_states: number of discrete states.
    :param n_actions: number of discrete actions.
    :param label_fraction: share of labelled keys, in (0, 1]; with ``queried``, 0: none drawn.
    :param seed: seed of the draw; the same seed always labels the same keys.
    :param monitored_states: bool (n_states,), states whose every key is labelled; None: none.
    :param queried: the labels are bought by reward queries (:mod:`dospcot.core.queries`), so a
        ``label_fraction`` of 0 is allowed.
    """

    def __init__(
        self,
        n_states: int,
        n_actions: int,
        label_fraction: float,
        seed: int,
        monitored_states: np.ndarray | None = None,
        *,
        queried: bool = False,
    ) -> None:
        fraction = check_label_fraction(label_fraction, queried=queried)
        monitored = (
            np.zeros(n_states, dtype=bool) if monitored_states is None else np.asarray(monitored_states)
        )
        if monitored.shape != (n_states,) or monitored.dtype != bool:
            raise ValueError(
                f"monitored_states must be a bool array of shape ({n_states},), got {monitored!r}"
            )
        labelled = np.repeat(monitored, n_actions)
        drawn = np.flatnonzero(~labelled)
        if drawn.size and fraction > 0:
            n_labelled = max(1, round(fraction * drawn.size))
            labelled[np.random.default_rng(seed).permutation(drawn)[:n_labelled]] = True
        self.labelled: np.ndarray = labelled.reshape(n_states, n_actions)
        """Boolean array of shape (n_states, n_actions): True where the reward is revealed."""

    def __contains__(self, key: tuple[int, int]) -> bool:
        state, action = key
        return bool(self.labelled[state, action])


class RewardMaskWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Hide the reward of unlabelled transitions.

    :param env: the env to mask. In ``"state-action"`` mode both spaces must be ``Discrete``; in
        ``"key"`` mode ``env.get_wrapper_attr("state_key")()`` must name the current state.
    :param label_fraction: share of labelled keys (state-action mode), probability that a step is
        revealed (transition mode) or that a (state key, action) pair is (key mode), in (0, 1]; with
        ``queried``, 0: none but what a monitor or ``revealed_keys`` reveal.
    :param mode: ``"state-action"``, ``"transition"`` or ``"key"``. In key mode ``info["state_key"]``
        holds the key of the state a step started from.
    :param mask_seed: seed of the mask, independent of the seed passed to ``reset``.
    :param monitored_states: state-action mode: bool (n_states,), states whose every reward is
        revealed (a monitor); ``label_fraction`` is then the share of the other keys.
    :param reveal_first_steps: transition mode: the first this many steps of every episode are
        revealed (a monitor); later steps with probability ``label_fraction``.
    :param revealed_keys: state-action mode: bool (n_states, n_actions), keys revealed besides the
        drawn ones, e.g. the steps of demonstrations whose rewards a rater gave; None: none.
    :param segment_length: k; above 1, whole k-step segments are labelled with their summed reward,
        each with probability ``label_fraction``, and no single reward is revealed (settable later,
        as :class:`dospcot.core.segments.SegmentLabelWrapper` does).
    :param queried: the labels are bought by reward queries (:mod:`dospcot.core.queries`), so a
        ``label_fraction`` of 0 (no random share) is allowed.
    """

    def __init__(
        self,
        env: gym.Env,
        label_fraction: float,
        mode: MaskMode = "state-action",
        mask_seed: int = 0,
        monitored_states: np.ndarray | None = None,
        reveal_first_steps: int = 0,
        revealed_keys: np.ndarray | None = None,
        segment_length: int = 1,
        queried: bool = False,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            label_fraction=label_fraction,
            mode=mode,
            mask_seed=mask_seed,
            monitored_states=monitored_states,
            reveal_first_steps=reveal_first_steps,
            revealed_keys=revealed_keys,
            segment_length=segment_length,
            queried=queried,
        )
        super().__init__(env)
        if mode not in MASK_MODES:
            raise ValueError(f"mode must be one of {MASK_MODES}, got {mode!r}")
        if revealed_keys is not None and mode != "state-action":
            raise ValueError("revealed_keys needs mode='state-action', whose keys are (state, action) pairs")
        if monitored_states is not None and mode != "state-action":
            raise ValueError(
                "monitored_states needs mode='state-action'; use reveal_first_steps in 'transition'"
            )
        if reveal_first_steps and mode != "transition":
            raise ValueError(
                "reveal_first_steps needs mode='transition'; use monitored_states in 'state-action'"
            )
        if reveal_first_steps < 0:
            raise ValueError(f"reveal_first_steps must be >= 0, got {reveal_first_steps}")
        self.reveal_first_steps = int(reveal_first_steps)
        self.label_fraction = check_label_fraction(label_fraction, queried=queried)
        self.mode: MaskMode = mode
        self.mask: StateActionMask | None = None
        if mode == "state-action":
            spaces = {"observation_space": env.observation_space, "action_space": env.action_space}
            for name, space in spaces.items():
                if not isinstance(space, gym.spaces.Discrete):
                    raise ValueError(
                        f"mode='state-action' needs a Discrete {name}, got {space}; "
                        f"use mode='transition' for other spaces"
                    )
            self.mask = StateActionMask(
                int(env.observation_space.n),
                int(env.action_space.n),
                self.label_fraction,
                mask_seed,
                monitored_states,
                queried=queried,
            )
            if revealed_keys is not None:
                if revealed_keys.shape != self.mask.labelled.shape:
                    raise ValueError(
                        f"revealed_keys must be (n_states, n_actions) = {self.mask.labelled.shape}, got "
                        f"{revealed_keys.shape}"
                    )
                self.mask.labelled |= revealed_keys.astype(bool)
        self._revealed_keys = revealed_keys
        self._monitored = monitored_states is not None and bool(np.any(monitored_states))
        self._state_key = env.get_wrapper_attr("state_key") if mode == "key" else None
        self._pair_labelled: dict[tuple[Hashable, int], bool] = {}
        self._mask_seed = mask_seed
        self._reveal_rng = np.random.default_rng(mask_seed)
        self._state: Any = None
        self._episode_step = 0
        self._segment_length = 1
        self._segment_step = 0
        self._segment_sum = 0.0
        self.segment_length = segment_length

    @property
    def segment_length(self) -> int:
        """k: 1 reveals single rewards; k > 1 labels whole k-step segments with their summed reward
        (``info["segment_label"]``) and reveals no single reward."""
        return self._segment_length

    @segment_length.setter
    def segment_length(self, k: int) -> None:
        if int(k) != k or k < 1:
            raise ValueError(f"segment_length must be an integer >= 1, got {k!r}")
        if k > 1 and (self.reveal_first_steps or self._monitored or self._revealed_keys is not None):
            raise ValueError(
                "segment labels reveal no single reward: they cannot be combined with a reward monitor "
                "or with revealed keys (labelled demonstrations)"
            )
        self._segment_length = int(k)

    def current_state_key(self) -> Hashable:
        """Key mode: the key of the state the env is in (the ``info["state_key"]`` of the next step);
        other modes: None."""
        return self._state if self._state_key is not None else None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._state = obs if self.mode == "state-action" else None
        if self._state_key is not None:
            self._state = self._state_key()
        self._episode_step = self._segment_step = 0
        self._segment_sum = 0.0
        if kwargs.get("seed") is not None:
            # A seeded reset replays the same reveals too, as gymnasium's determinism contract asks.
            self._reveal_rng = np.random.default_rng([self._mask_seed, kwargs["seed"]])
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._segment_length > 1:
            return obs, 0.0, terminated, truncated, self._segment_info(info, reward, terminated or truncated)
        if self.mask is not None:
            observed = (int(self._state), int(action)) in self.mask
            self._state = obs
        elif self._state_key is not None:
            pair = (self._state, int(action))
            observed = self._pair_labelled.get(pair)
            if observed is None:  # a pair's hash is drawn once: states recur, and hashing is costly
                observed = self._pair_labelled[pair] = key_is_labelled(
                    self._state, action, self.label_fraction, self._mask_seed
                )
            info = dict(info, state_key=self._state)
            self._state = self._state_key()
        else:  # the monitored first steps draw nothing, so reveal_first_steps=0 keeps every draw
            monitored = self._episode_step < self.reveal_first_steps
            observed = monitored or bool(self._reveal_rng.random() < self.label_fraction)
            self._episode_step += 1
        info = dict(info, reward_observed=observed, hidden_reward=float(reward))
        if not observed:
            for key in REWARD_INFO_KEYS:  # the reward's parts would give the hidden reward away
                info.pop(key, None)
        return obs, float(reward) if observed else 0.0, terminated, truncated, info

    def _segment_info(self, info: dict[str, Any], reward: float, episode_end: bool) -> dict[str, Any]:
        """A step under segment labels: its reward hidden, and the segment's sum where it ends one
        that is labelled."""
        if self._state_key is not None:  # the pool's pairs are still named by their state key
            info = dict(info, state_key=self._state)
            self._state = self._state_key()
        info = {key: value for key, value in info.items() if key not in REWARD_INFO_KEYS}
        info.update(reward_observed=False, hidden_reward=float(reward))
        self._segment_sum += float(reward)
        self._segment_step += 1
        if self._segment_step == self._segment_length or episode_end:
            info["segment_end"] = True
            if self._reveal_rng.random() < self.label_fraction:
                info["segment_label"] = self._segment_sum
            self._segment_step, self._segment_sum = 0, 0.0
        return info
