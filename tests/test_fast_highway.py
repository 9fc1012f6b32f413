"""Tests of the vectorised highway env against highway-env's ``highway-fast-v0``."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest

from dospcot.envs.fast_highway import FastHighwayConfig, FastHighwayEnv, FastHighwayVec
from dospcot.envs.fast_highway_views import VIEW_NAMES, view_space
from dospcot.envs.masked_highway import make_masked_highway

IDLE, FASTER = 1, 3


def to_highway_env(fast: FastHighwayVec, index: int, env: gym.Env) -> None:
    """Put env ``index`` of ``fast`` into the (reset) highway-env env ``env``, in place.

    The ego (``env.unwrapped.vehicle``) gets column 0, the road's other vehicles the other columns in
    order; every vehicle's position, heading, speed, crash flag and lane are set, plus the ego's
    set-points and the others' IDM target speed and exponent. The others' MOBIL lane changes are
    switched off, as the fast env has none.
    """
    from highway_env.vehicle.behavior import IDMVehicle

    unwrapped = env.unwrapped
    road = unwrapped.road
    ego = unwrapped.vehicle
    assert road.vehicles[0] is ego, "highway-env lists the ego first"
    while len(road.vehicles) < fast.n_vehicles:
        road.vehicles.append(IDMVehicle(road, np.zeros(2)))
    del road.vehicles[fast.n_vehicles :]
    for j, vehicle in enumerate(road.vehicles):
        vehicle.position = np.array([fast.x[index, j], fast.y[index, j]], dtype=np.float64)
        vehicle.heading = float(fast.heading[index, j])
        vehicle.speed = float(fast.speed[index, j])
        vehicle.crashed = bool(fast.vehicle_crashed[index, j])
        vehicle.impact = None
        vehicle.lane_index = road.network.get_closest_lane_index(vehicle.position, vehicle.heading)
        vehicle.lane = road.network.get_lane(vehicle.lane_index)
        vehicle.target_speed = float(fast.target_speed[index, j])
        if j > 0:
            vehicle.target_lane_index = vehicle.lane_index
            vehicle.enable_lane_change = False
            vehicle.DELTA = float(fast.idm_delta[index, j])
    ego.target_lane_index = (*ego.lane_index[:2], int(fast.target_lane[index]))
    ego.speed_index = int(fast.speed_index[index])


@pytest.fixture(scope="module")
def highway() -> gym.Env:
    pytest.importorskip("highway_env")
    env = gym.make("highway-fast-v0")
    env.reset(seed=0)
    yield env
    env.close()


def _states() -> list[FastHighwayVec]:
    """Copies of vector states: after resets, after random steps, and two crafted scenes."""
    states = []
    fast = FastHighwayVec(8, seed=3)
    states.append(_copy(fast))
    rng = np.random.default_rng(0)
    for step in range(12):
        # Lane changes are over-represented so that many states are caught mid lane change.
        fast.step(rng.choice(5, size=8, p=[0.3, 0.1, 0.3, 0.2, 0.1]))
        if step % 3 == 2:
            states.append(_copy(fast))

    # Offsets from the ego [m] at the edges of the views: 2 lengths behind, the grid's edges, 200 m.
    # In env 0, vehicle 2 shares the ego's grid cell (the ego must win it) and vehicles 1 and 3 share
    # one (vehicle 1 must win); in env 1, the ego is mid lane change and the nearest vehicles are
    # just inside and just outside the kinematics' "behind" limit.
    offsets = [
        [3.0, -1.0, 4.9, -9.9, -10.5, -30.0, 26.0, 27.6, 199.0, 250.0, -26.0, -7.5],
        [-10.5, 12.0, -9.9, 40.0, 27.6, 199.0, 250.0, -26.0, -30.0, 60.0, 80.0, -10.0],
    ]
    crafted = FastHighwayVec(2, seed=4)
    for i, (dx, ego_y, ego_heading) in enumerate(zip(offsets, (4.0, 1.4), (0.0, -0.05), strict=True)):
        ego_x = crafted.x[i, 0]
        crafted.x[i, 1 : 1 + len(dx)] = ego_x + np.array(dx)
        crafted.x[i, 1 + len(dx) :] = ego_x + 300.0 + 10.0 * np.arange(crafted.n_vehicles - 1 - len(dx))
        crafted.y[i, 0], crafted.heading[i, 0] = ego_y, ego_heading
        crafted.lane[i, 1:4] = 1
        crafted.y[i, 1:] = 4.0 * crafted.lane[i, 1:]
    states.append(crafted)
    return states


def _copy(fast: FastHighwayVec) -> FastHighwayVec:
    clone = FastHighwayVec(fast.n_envs, fast.config, seed=0)
    for name in ("x", "y", "speed", "heading", "lane", "target_speed", "idm_delta", "vehicle_crashed"):
        setattr(clone, name, getattr(fast, name).copy())
    clone.target_lane = fast.target_lane.copy()
    clone.speed_index = fast.speed_index.copy()
    return clone


def test_env_checkers_pass() -> None:
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    gym_check_env(FastHighwayEnv())
    sb3_check_env(FastHighwayEnv())


def test_views_match_highway_env_exactly(highway: gym.Env) -> None:
    from highway_env.envs.common.observation import observation_factory

    mid_lane_change = behind = close_behind = 0
    for fast in _states():
        kinematics = fast.observe("kinematics")
        occupancy = fast.observe("occupancy")
        rewards = fast._reward(fast._rewards())
        for i in range(fast.n_envs):
            to_highway_env(fast, i, highway)
            unwrapped = highway.unwrapped
            expected_kin = observation_factory(unwrapped, {"type": "Kinematics"}).observe()
            expected_occ = observation_factory(unwrapped, {"type": "OccupancyGrid"}).observe()
            np.testing.assert_allclose(kinematics[i], expected_kin, atol=1e-5)
            np.testing.assert_allclose(occupancy[i], expected_occ, atol=1e-5)
            assert rewards[i] == pytest.approx(unwrapped._reward(IDLE), abs=1e-12)
            mid_lane_change += abs(fast.y[i, 0] - 4.0 * np.round(fast.y[i, 0] / 4.0)) > 0.25
            dx = fast.x[i, 1:] - fast.x[i, 0]
            behind += np.any(dx < -10.0)
            close_behind += np.any((dx < 0) & (dx > -10.0))
    # The states must cover what the views treat specially.
    assert mid_lane_change >= 3 and behind >= 3 and close_behind >= 2


def test_dynamics_match_highway_env_without_lane_changes(highway: gym.Env) -> None:
    """Crash-free steps move every vehicle as highway-env does once MOBIL is switched off."""
    fast = FastHighwayVec(8, seed=11)
    rng = np.random.default_rng(5)
    compared = 0
    for _ in range(6):
        actions = rng.integers(0, 5, size=8)
        before = _copy(fast)
        after = _copy(fast)
        after._advance(actions)
        for i in range(fast.n_envs):
            to_highway_env(before, i, highway)
            _, _, terminated, _, _ = highway.step(int(actions[i]))
            if terminated or after.crashed[i]:
                continue
            vehicles = highway.unwrapped.road.vehicles
            np.testing.assert_allclose(after.x[i], [v.position[0] for v in vehicles], atol=1e-9)
            np.testing.assert_allclose(after.y[i], [v.position[1] for v in vehicles], atol=1e-9)
            np.testing.assert_allclose(after.speed[i], [v.speed for v in vehicles], atol=1e-9)
            np.testing.assert_allclose(after.heading[i], [v.heading for v in vehicles], atol=1e-9)
            assert after.target_lane[i] == highway.unwrapped.vehicle.target_lane_index[2]
            compared += 1
        fast.step(actions)
    assert compared >= 20


def _lone_ego(lane: int, speed: float, **overrides: object) -> FastHighwayEnv:
    """An env whose ego drives alone in ``lane`` at its set-point ``speed`` (20, 25 or 30 m/s)."""
    env = FastHighwayEnv(**overrides)
    env.reset(seed=0)
    vec = env.vec
    vec.y[0, 0] = 4.0 * lane
    vec.target_lane[0] = lane
    vec.speed[0, 0] = vec.target_speed[0, 0] = speed
    vec.speed_index[0] = round((speed - 20.0) / 5.0)
    vec.x[0, 1:] = vec.x[0, 0] + 1000.0 + 50.0 * np.arange(vec.n_vehicles - 1)
    return env


@pytest.mark.parametrize(
    ("lane", "speed", "expected"),
    [(2, 30.0, 1.0), (0, 20.0, 1 / 1.5 * (1 + 0)), (1, 25.0, (1 + 0.05 + 0.2) / 1.5)],
)
def test_reward_formula(lane: int, speed: float, expected: float) -> None:
    env = _lone_ego(lane, speed)
    _, reward, terminated, truncated, info = env.step(IDLE)
    assert reward == pytest.approx(expected, abs=1e-12)
    assert not terminated and not truncated
    assert info["speed"] == pytest.approx(speed)
    assert info["crashed"] is False and info["action"] == IDLE
    assert info["rewards"] == pytest.approx(
        {
            "collision_reward": 0.0,
            "right_lane_reward": lane / 2,
            "high_speed_reward": (speed - 20.0) / 10.0,
            "on_road_reward": 1.0,
        }
    )


def test_crash_terminates_with_collision_reward() -> None:
    env = _lone_ego(2, 30.0)
    vec = env.vec
    vec.x[0, 1], vec.y[0, 1] = vec.x[0, 0] + 2.0, vec.y[0, 0]  # overlapping the ego's box
    _, reward, terminated, truncated, info = env.step(IDLE)
    assert terminated and not truncated and info["crashed"]
    # The crash happens in the first sub-step; the crashed ego then brakes with a = -speed for 4 more.
    speed = 30.0 * 0.8**4
    assert info["speed"] == pytest.approx(speed)
    raw = -1.0 + 0.1 * 1.0 + 0.4 * np.clip((speed - 20.0) / 10.0, 0.0, 1.0)
    assert reward == pytest.approx((raw + 1.0) / 1.5, abs=1e-12)
    assert info["rewards"]["collision_reward"] == 1.0


def test_duration_truncates_at_step_30() -> None:
    env = FastHighwayEnv(vehicles_count=0)
    env.reset(seed=1)
    for step in range(1, 31):
        _, _, terminated, truncated, _ = env.step(IDLE)
        assert not terminated
        assert truncated == (step == 30)


def test_vector_auto_resets_ended_envs() -> None:
    fast = FastHighwayVec(3, FastHighwayConfig(duration=4), seed=2)
    fast.x[0, 1], fast.y[0, 1] = fast.x[0, 0] + 1.0, fast.y[0, 0]  # env 0 crashes on its first step
    obs, _, terminated, truncated = fast.step(np.full(3, IDLE))
    assert terminated.tolist() == [True, False, False] and not truncated.any()
    assert fast.steps.tolist() == [0, 1, 1] and not fast.crashed.any()
    np.testing.assert_array_equal(obs, fast.observe("kinematics"))
    assert not np.array_equal(fast.final_obs[0], obs[0])
    for _ in range(2):
        _, _, terminated, truncated = fast.step(np.full(3, FASTER))
    assert not terminated.any() and not truncated.any()
    obs, _, terminated, truncated = fast.step(np.full(3, IDLE))
    assert truncated.tolist() == [False, True, True]
    assert fast.steps.tolist() == [3, 0, 0] and fast.time.tolist() == [3.0, 0.0, 0.0]
    # A new episode: the ego is back at its starting speed and set-point, behind every other vehicle.
    assert fast.speed[1:, 0].tolist() == [25.0, 25.0] and fast.speed_index[1:].tolist() == [1, 1]
    assert np.all(fast.x[1:, 1:] > fast.x[1:, :1])
    np.testing.assert_array_equal(obs[1:], fast.observe("kinematics")[1:])


def test_same_seed_same_trajectories() -> None:
    actions = np.random.default_rng(0).integers(0, 5, size=(40, 4))
    runs = []
    for seed in (9, 9, 10):
        fast = FastHighwayVec(4, seed=seed)
        trajectory = [fast.reset(seed=seed)]
        for a in actions:
            obs, reward, terminated, truncated = fast.step(a)
            trajectory += [obs, reward, terminated, truncated, fast.x.copy()]
        runs.append(trajectory)
    assert all(np.array_equal(a, b) for a, b in zip(runs[0], runs[1], strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(runs[0], runs[2], strict=True))

    env_a, env_b = FastHighwayEnv(), FastHighwayEnv()
    obs_a, _ = env_a.reset(seed=5)
    obs_b, _ = env_b.reset(seed=5)
    np.testing.assert_array_equal(obs_a, obs_b)
    for a in actions[:, 0]:
        out_a, out_b = env_a.step(int(a)), env_b.step(int(a))
        np.testing.assert_array_equal(out_a[0], out_b[0])
        assert out_a[1:4] == out_b[1:4]
        if out_a[2] or out_a[3]:
            break


def test_bad_arguments_raise_value_errors() -> None:
    with pytest.raises(ValueError, match=r"allowed: lanes_count, .*policy_frequency"):
        FastHighwayEnv(lane_count=4)
    with pytest.raises(ValueError, match=r"unknown view 'pixels'; allowed: \['kinematics', 'occupancy'\]"):
        view_space("pixels")
    with pytest.raises(ValueError, match="allowed"):
        FastHighwayVec(2).observe("pixels")
    with pytest.raises(ValueError, match="allowed"):
        FastHighwayEnv().observe("pixels")
    with pytest.raises(ValueError, match="lanes_count"):
        FastHighwayConfig(lanes_count=0)
    with pytest.raises(ValueError, match="reward_speed_range"):
        FastHighwayConfig(reward_speed_range=(30.0, 20.0))
    with pytest.raises(ValueError, match="policy_frequency"):
        FastHighwayConfig(policy_frequency=10)
    with pytest.raises(ValueError, match="actions"):
        FastHighwayVec(2).step(np.array([0, 5]))
    assert FastHighwayEnv(lanes_count=4).config == FastHighwayConfig(lanes_count=4)


def test_views_and_spaces_match_highway_fast_v0() -> None:
    pytest.importorskip("highway_env")
    reference = gym.make("highway-fast-v0")
    env = FastHighwayEnv()
    assert env.observation_space == reference.observation_space
    assert env.action_space == reference.action_space
    assert view_space("kinematics") == reference.observation_space
    reference.close()

    env.reset(seed=0)
    fast = FastHighwayVec(3, seed=0)
    for name in VIEW_NAMES:
        space = view_space(name)
        assert space.dtype == np.float32 and space.shape == env.observe(name).shape
        assert fast.observe(name).shape == (3, *space.shape)
        assert fast.observe(name).dtype == np.float32
    assert view_space("occupancy").shape == (4, 11, 11)


def _counted_view_calls(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Count the fast env's calls of each view function from now on, by view."""
    from dospcot.envs import fast_highway

    calls = {name: 0 for name in VIEW_NAMES}
    for name, fn in list(fast_highway.VIEW_FUNCTIONS.items()):

        def counted(*args, _name=name, _fn=fn):
            calls[_name] += 1
            return _fn(*args)

        monkeypatch.setitem(fast_highway.VIEW_FUNCTIONS, name, counted)
    return calls


def test_a_sensor_step_computes_each_view_once(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _counted_view_calls(monkeypatch)
    env = make_masked_highway("dospcot/FastHighway-v0", "kinematics", VIEW_NAMES)
    env.reset(seed=0)
    for _ in range(5):
        *_, info = env.step(IDLE)
    assert calls == {name: 6 for name in VIEW_NAMES}  # the reset and five steps, each view once
    np.testing.assert_array_equal(env.unwrapped.observe("kinematics"), info["views"]["kinematics"])


def test_lazy_views_are_computed_when_read_once_and_never_for_a_past_state(monkeypatch: pytest.MonkeyPatch):
    calls = _counted_view_calls(monkeypatch)
    env = make_masked_highway("dospcot/FastHighway-v0", "kinematics", VIEW_NAMES)
    env.set_wrapper_attr("lazy_views", True, force=False)
    env.reset(seed=0)
    for _ in range(5):
        *_, info = env.step(IDLE)
    # Only the observed view, for the reset and five steps: nothing read the other.
    assert calls == {name: 6 if name == "kinematics" else 0 for name in VIEW_NAMES}
    *_, info = env.step(IDLE)
    for name in VIEW_NAMES:  # read twice, computed once
        np.testing.assert_array_equal(info["views"][name], info["views"][name])
    assert calls == {name: 7 if name == "kinematics" else 1 for name in VIEW_NAMES}
    np.testing.assert_array_equal(env.unwrapped.observe("occupancy"), info["views"]["occupancy"])
    *_, unread = env.step(IDLE)
    env.step(IDLE)
    with pytest.raises(RuntimeError, match="before the env stepped on"):
        unread["views"]["occupancy"]  # computed now, it would describe a later state
    np.testing.assert_array_equal(info["views"]["occupancy"], info["views"]["occupancy"])  # read in time


def test_a_copy_of_lazy_views_keeps_what_was_read_and_never_copies_the_env(monkeypatch: pytest.MonkeyPatch):
    calls = _counted_view_calls(monkeypatch)
    env = make_masked_highway("dospcot/FastHighway-v0", "kinematics", VIEW_NAMES)
    env.set_wrapper_attr("lazy_views", True, force=False)
    env.reset(seed=0)
    *_, info = env.step(IDLE)

    def no_copy(self, memo):
        raise AssertionError("the env was deep-copied with its views")

    monkeypatch.setattr(type(env.unwrapped), "__deepcopy__", no_copy, raising=False)
    copied = copy.deepcopy(info)  # what SB3's DummyVecEnv does to every step's infos
    np.testing.assert_array_equal(copied["views"]["kinematics"], info["views"]["kinematics"])
    assert copied["views"]["kinematics"] is not info["views"]["kinematics"]
    with pytest.raises(RuntimeError, match="before the env stepped on"):
        copied["views"]["occupancy"]  # never read before the copy: the copy cannot observe
    assert calls["occupancy"] == 0
    np.testing.assert_array_equal(env.unwrapped.observe("occupancy"), info["views"]["occupancy"])  # live
