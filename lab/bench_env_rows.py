"""The rows of ``dospcot-lab bench`` on envs and stores: the fast highway against highway-env, MiniGrid's
sensor wrappers, the key store's memory and the co-trainer's scaling with the pool."""

from __future__ import annotations

import math
import statistics
import time

import gymnasium as gym
import numpy as np

from dospcot.config.run_configs import TrainConfig
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.envs import StateActionMask
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config
from dospcot_lab.bench_measure import Row, alternating


def _random_steps_per_second(env: gym.Env, steps: int, seed: int) -> float:
    env.action_space.seed(seed)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def _fast_highway_steps_per_second(steps: int, n_envs: int, seed: int) -> float:
    from dospcot.envs.fast_highway import FastHighwayVec

    env = FastHighwayVec(n_envs, seed=seed)
    actions = np.random.default_rng(seed).integers(0, 5, (steps, n_envs))
    env.reset(seed=seed)
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    return steps * n_envs / (time.perf_counter() - start)


def _highway_env_steps_per_second(steps: int, seed: int) -> float:
    from dospcot.envs.masked_highway import make_highway

    return _random_steps_per_second(make_highway("highway-fast-v0"), steps, seed)


def bench_fast_highway(quick: bool, repeats: int) -> Row:
    """Env steps per second with random actions: our vectorised highway env against highway-fast-v0."""
    n_envs, vec_steps, peer_steps = 64, (50 if quick else 500), (60 if quick else 600)
    ours, peer = alternating(
        repeats,
        lambda rep: _fast_highway_steps_per_second(vec_steps, n_envs, rep),
        lambda rep: _highway_env_steps_per_second(peer_steps, rep),
    )
    return Row.measured(
        "FastHighwayVec vs highway-env's highway-fast-v0: env steps per second",
        f"random actions, resets included; ours {n_envs} envs x {vec_steps} steps, "
        f"highway-fast-v0 {peer_steps} steps (its Kinematics observation)",
        "steps/s",
        ours,
        peer,
        higher_is_better=True,
        target=50.0,
    )


def bench_minigrid_wrappers(quick: bool, repeats: int) -> Row:
    """Env steps per second with random actions: MiniGrid through what the ``minigrid-lavagap-dospcot``
    preset adds to every training step (the keyed reward mask, the first view observed, the pool
    store, which reads every view on a pair's first visit) against the bare MiniGrid env."""
    from dospcot.adapters.sensor_store import KeyedStepStore, SensorStoreWrapper
    from dospcot.envs.gym_sensors import make_masked_gym

    steps = 2_000 if quick else 20_000
    cfg = load_config("minigrid-lavagap-dospcot")
    assert isinstance(cfg, TrainConfig)
    # "module:id": gymnasium imports minigrid, which registers its ids, for both envs alike.
    env_id = cfg.gym.env_id
    views = {name: cfg.gym.views[name] for name in cfg.views}

    def ours(rep: int) -> gym.Env:
        env = make_masked_gym(
            env_id,
            cfg.views[0],
            tuple(views),
            cfg.training.label_fraction,
            rep,
            view_specs=views,
            state_key=cfg.gym.state_key,
        )
        shapes = {v: env.get_wrapper_attr("view_space")(v).shape for v in views}
        return SensorStoreWrapper(env, KeyedStepStore(shapes))

    ours_rate, peer = alternating(
        repeats,
        lambda rep: _random_steps_per_second(ours(rep), steps, rep),
        lambda rep: _random_steps_per_second(gym.make(env_id), steps, rep),
    )
    return Row.measured(
        f"{env_id.split(':')[-1]} through dospcot's wrappers vs bare: env steps per second",
        f"random actions, resets included, {steps} steps; ours: reward mask over (state key, action) "
        f"pairs ({cfg.training.label_fraction:.0%}), the {cfg.views[0]} view observed, a fresh keyed "
        f"pool store recording every view ({', '.join(f'{n}: {v}' for n, v in views.items())}) of each "
        "new pair",
        "steps/s",
        ours_rate,
        peer,
        higher_is_better=True,
        target=round(1 / 1.3, 3),
    )


def _filled_run(n: int, seed: int) -> CoTrainingRun:
    """A `grid16-dospcot` co-trainer whose shared store holds ``n`` steps of a uniform random policy
    from uniformly drawn states, revealed by the run's mask."""
    cfg = load_config("grid16-dospcot", [f"seed={seed}"])
    run = build_run(cfg)
    mdp, rng = run.task.mdp, np.random.default_rng(seed)
    labelled = StateActionMask(mdp.n_states, mdp.n_actions, cfg.training.label_fraction, seed).labelled
    states, actions = rng.integers(0, mdp.n_states, n), rng.integers(0, mdp.n_actions, n)
    for s, a in zip(states.tolist(), actions.tolist(), strict=True):
        reward = float(mdp.reward[s, a])
        run.store.add(s, a, int(mdp.next_state[s, a]), bool(labelled[s, a]), reward, reward)
    return run


def _store_bytes(run: CoTrainingRun) -> int:
    """Bytes the shared store and the reward table hold."""
    arrays = [*run.store.state_dict().values(), *run.table.state_dict().values()]
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


def _raw_bytes(run: CoTrainingRun, n: int) -> int:
    """Bytes of the raw arrays of ``n`` steps: each view's observation and next observation
    (float32), the action, the reward and the done flag."""
    width = sum(run.task.mdp.views[v].shape[1] for v in run.cfg.views)
    return n * (2 * width * 4 + 8 + 4 + 1)


def bench_store_memory(quick: bool, repeats: int) -> Row:
    """Memory of the shared transition store per million steps against the raw arrays of those steps."""
    n = 100_000 if quick else 1_000_000
    ours, peer = [], []
    for rep in range(repeats):
        run = _filled_run(n, rep)
        ours.append(_store_bytes(run) / n * 1e6 / 2**20)
        peer.append(_raw_bytes(run, n) / n * 1e6 / 2**20)
    views = " + ".join(f"{v} ({run.task.mdp.views[v].shape[1]} floats)" for v in run.cfg.views)
    return Row.measured(
        "Shared transition store vs the raw arrays: memory per million steps",
        f"16 x 16 grid, views {views}, {n:,} steps measured",
        "MiB",
        ours,
        peer,
        higher_is_better=False,
        target=1.5,
    )


SCALING_SIZES = (10_000, 30_000, 100_000, 300_000, 1_000_000)


def bench_cotraining_scaling(quick: bool, repeats: int) -> Row:
    """Wall time of one co-training step (select, fit, score, relabel) as the store grows, against
    n log n growth from the smallest size."""
    sizes = SCALING_SIZES[:3] if quick else SCALING_SIZES
    seconds: dict[int, list[float]] = {n: [] for n in sizes}
    for rep in range(repeats):
        for n in sizes:
            run = _filled_run(n, rep)
            start = time.perf_counter()
            run.cotrain()
            seconds[n].append(time.perf_counter() - start)
    small, large = sizes[0], sizes[-1]
    growth = [seconds[large][r] / seconds[small][r] for r in range(repeats)]
    bound = large * math.log(large) / (small * math.log(small))
    curve = ", ".join(f"{n:,}: {statistics.median(seconds[n]):.3f} s" for n in sizes)
    return Row.measured(
        f"One co-training step, {large:,} vs {small:,} stored steps: growth against n log n",
        f"`grid16-dospcot`, median seconds per size: {curve}",
        "x",
        growth,
        [bound] * repeats,
        higher_is_better=False,
        target=1.0,
    )
