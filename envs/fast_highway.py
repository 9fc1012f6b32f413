"""A fast, numpy-vectorised imitation of highway-env's ``highway-fast-v0``.

:class:`FastHighwayVec` steps ``n_envs`` independent highway scenes at once: every quantity is an
array over ``(n_envs, 1 + vehicles_count)`` (the ego in column 0), so one ``step`` costs a few dozen
numpy calls whatever the number of envs. :class:`FastHighwayEnv` wraps one such scene as a
``gymnasium.Env`` for single-env agents (SB3). Both use highway-env's defaults for
``highway-fast-v0``: 3 lanes of 4 m (centres y = 0, 4, 8; lane 0 leftmost, lane 2 rightmost),
20 other vehicles, 30 policy steps of 1 s, each simulated as 5 sub-steps of 0.2 s, the
``DiscreteMetaAction`` action space and the default ``Kinematics`` observation.

Two views of the state are computed exactly as highway-env computes them for the same vehicles
(:mod:`dospcot.envs.fast_highway_views`): ``"kinematics"`` (``KinematicObservation`` with default
arguments, the env's observation) and ``"occupancy"`` (``OccupancyGridObservation`` with default
arguments).

What is copied from highway-env (``HighwayEnvFast``):

- the ego (``MDPVehicle``): target speeds [20, 25, 30] m/s, FASTER/SLOWER from the index nearest to
  the current speed, lane changes to a reachable adjacent lane, and highway-env's proportional
  speed controller, cascaded lateral-position/heading controller and kinematic bicycle model,
  formula for formula (so a lane change takes as long as there: 90 % of the 4 m in 1 s, done in 2 s);
- the others' IDM longitudinal control (``IDMVehicle`` constants, target speed = initial speed
  clipped to the 30 m/s speed limit, exponent drawn in [3.5, 4.5] as ``randomize_behavior``
  does rather than a fixed 4), following the nearest vehicle ahead whose centre is within 3 m
  of their lane centre (``Road.neighbour_vehicles`` with ``on_lane(margin=1)``), the ego included;
- crashed vehicles brake with acceleration ``-speed`` and steer straight (``clip_actions``); only
  collisions involving the ego are detected, as in ``HighwayEnvFast``;
- the reward formula, ``terminated`` on a crash and ``truncated`` once ``time >= duration``.

Where the dynamics differ from highway-env:

- **No lane changes for the others.** highway-env's ``IDMVehicle`` changes lane with MOBIL (and
  aborts or yields while doing so); here the other vehicles keep their initial lane for the whole
  episode, so their ``y`` and ``heading`` never change.
- **Collision model.** highway-env intersects the (rotated) vehicle rectangles with a separating
  axis test and also predicts collisions one sub-step ahead, pushing the two vehicles apart
  (``impact``). Here a crash is an axis-aligned box overlap, ``|dx| < LENGTH and |dy| < WIDTH``,
  checked after each sub-step, with no predicted collision and no impact displacement. The ego is
  at most a few degrees off the road axis, so the two tests disagree only on grazing contacts.
- **Placement.** ``Vehicle.create_random`` is copied in distribution (uniform lane, others' speed
  uniform in [21, 24] m/s, spacing ``(12 + speed) * exp(-5 / 40 * lanes_count)`` times
  ``ego_spacing`` or ``1 / vehicles_density`` and a uniform factor in [0.9, 1.1], each vehicle
  ahead of the previous ones, ego first), but the random numbers come from our own generator, so
  the same seed does not give highway-env's scene.
- **Road.** The road is an unbounded straight road: highway-env's 10 km lane ends are never
  reached in a 30 s episode, so the ego is always on the road (``on_road_reward`` is always 1).
- **Reset info.** highway-env reports a randomly sampled action in the reset ``info``; here it is
  ``None``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from dospcot.envs.fast_highway_views import VIEW_FUNCTIONS, VIEW_NAMES, view_space
from dospcot.envs.highway_constants import (
    EGO_INITIAL_SPEED,
    IDM_ACC_MAX,
    IDM_COMFORT_ACC_MAX,
    IDM_COMFORT_ACC_MIN,
    IDM_DELTA_RANGE,
    IDM_DISTANCE_WANTED,
    IDM_TIME_WANTED,
    KIN_FEATURES,
    KIN_VEHICLES,
    KP_A,
    KP_HEADING,
    KP_LATERAL,
    LANE_WIDTH,
    LENGTH,
    MAX_SPEED,
    MAX_STEERING_ANGLE,
    MIN_SPEED,
    SPEED_LIMIT,
    TARGET_SPEEDS,
    WIDTH,
    lmap,
    not_zero,
)

LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = range(5)


@dataclass(frozen=True)
class FastHighwayConfig:
    """The scene and reward settings; the defaults are ``highway-fast-v0``'s.

    :param lanes_count: number of lanes.
    :param vehicles_count: number of other vehicles.
    :param duration: episode length [s]; with ``policy_frequency`` 1, in policy steps.
    :param ego_spacing: spacing ratio in front of the ego at placement.
    :param vehicles_density: the others are placed with spacing ratio ``1 / vehicles_density``.
    :param collision_reward: weight of the crash indicator.
    :param right_lane_reward: weight of ``target_lane / (lanes_count - 1)``.
    :param high_speed_reward: weight of the forward speed mapped from ``reward_speed_range`` to [0, 1].
    :param reward_speed_range: [m/s] forward speeds mapped to 0 and 1.
    :param normalize_reward: map the reward from ``[collision_reward, high_speed + right_lane]`` to [0, 1].
    :param simulation_frequency: sub-steps per second [Hz].
    :param policy_frequency: actions per second [Hz].
    """

    lanes_count: int = 3
    vehicles_count: int = 20
    duration: int = 30
    ego_spacing: float = 1.5
    vehicles_density: float = 1.0
    collision_reward: float = -1.0
    right_lane_reward: float = 0.1
    high_speed_reward: float = 0.4
    reward_speed_range: tuple[float, float] = (20.0, 30.0)
    normalize_reward: bool = True
    simulation_frequency: int = 5
    policy_frequency: int = 1

    def __post_init__(self) -> None:
        for name in ("lanes_count", "vehicles_count", "duration", "simulation_frequency", "policy_frequency"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ValueError(f"{name} must be an int, got {value!r}")
        if self.lanes_count < 1:
            raise ValueError(f"lanes_count must be >= 1, got {self.lanes_count}")
        if self.vehicles_count < 0:
            raise ValueError(f"vehicles_count must be >= 0, got {self.vehicles_count}")
        if self.duration < 1:
            raise ValueError(f"duration must be >= 1, got {self.duration}")
        if self.policy_frequency < 1 or self.simulation_frequency < self.policy_frequency:
            raise ValueError(
                "need 1 <= policy_frequency <= simulation_frequency, got "
                f"policy_frequency={self.policy_frequency}, simulation_frequency={self.simulation_frequency}"
            )
        for name in ("ego_spacing", "vehicles_density"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        for name in ("collision_reward", "right_lane_reward", "high_speed_reward"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        speed_range = tuple(self.reward_speed_range)
        if len(speed_range) != 2 or not all(math.isfinite(v) for v in speed_range):
            raise ValueError(f"reward_speed_range must be two finite speeds, got {self.reward_speed_range!r}")
        if not speed_range[0] < speed_range[1]:
            raise ValueError(f"reward_speed_range must be increasing, got {self.reward_speed_range!r}")
        # A frozen dataclass: coerce a list to the documented tuple so configs compare and hash equal.
        object.__setattr__(self, "reward_speed_range", (float(speed_range[0]), float(speed_range[1])))
        if self.normalize_reward and self.collision_reward == self.high_speed_reward + self.right_lane_reward:
            raise ValueError(
                "normalize_reward needs collision_reward != high_speed_reward + right_lane_reward "
                "(the reward range would be empty)"
            )


def _speed_to_index(speed: np.ndarray) -> np.ndarray:
    """``MDPVehicle.speed_to_index``: the index of the target speed nearest to ``speed``."""
    x = (speed - TARGET_SPEEDS[0]) / (TARGET_SPEEDS[-1] - TARGET_SPEEDS[0])
    return np.clip(np.round(x * (TARGET_SPEEDS.size - 1)), 0, TARGET_SPEEDS.size - 1).astype(np.intp)


class FastHighwayVec:
    """``n_envs`` independent highway scenes stepped together in numpy.

    State arrays (public; V = 1 + vehicles_count, the ego in column 0):

    - ``x``, ``y`` (n, V) positions [m]; ``speed`` (n, V) [m/s]; ``heading`` (n, V) [rad];
    - ``lane`` (n, V) int: the others' lane (fixed), the ego's nearest lane in column 0;
    - ``target_speed`` (n, V) [m/s]: the ego's set-point in column 0, the others' IDM target speed;
    - ``idm_delta`` (n, V): the others' IDM exponent (column 0 unused);
    - ``target_lane`` (n,) int and ``speed_index`` (n,) int: the ego's lane and speed set-points;
    - ``crashed`` (n,) bool: the ego crashed; ``vehicle_crashed`` (n, V) bool: per vehicle;
    - ``time`` (n,) [s] since the episode start; ``steps`` (n,) int policy steps taken.

    After each :meth:`step`, ``final_obs`` (n, 5, 5) holds the observation reached before any
    automatic reset, and ``reward_components`` the unweighted reward terms (n,) of that step.

    :param n_envs: number of envs.
    :param config: scene and reward settings.
    :param seed: seed of the ``np.random.default_rng`` that places the vehicles.
    """

    def __init__(self, n_envs: int, config: FastHighwayConfig = FastHighwayConfig(), seed: int | None = None):
        if isinstance(n_envs, bool) or not isinstance(n_envs, int | np.integer) or n_envs < 1:
            raise ValueError(f"n_envs must be an int >= 1, got {n_envs!r}")
        if not isinstance(config, FastHighwayConfig):
            raise ValueError(f"config must be a FastHighwayConfig, got {type(config).__name__}")
        self.n_envs = int(n_envs)
        self.config = config
        self.n_vehicles = 1 + config.vehicles_count
        self.frames = config.simulation_frequency // config.policy_frequency
        self.dt = 1.0 / config.simulation_frequency
        self.rng = np.random.default_rng(seed)
        shape = (self.n_envs, self.n_vehicles)
        self.x = np.zeros(shape)
        self.y = np.zeros(shape)
        self.speed = np.zeros(shape)
        self.heading = np.zeros(shape)
        self.lane = np.zeros(shape, dtype=np.intp)
        self.target_speed = np.zeros(shape)
        self.idm_delta = np.full(shape, 4.0)
        self.vehicle_crashed = np.zeros(shape, dtype=bool)
        self.target_lane = np.zeros(self.n_envs, dtype=np.intp)
        self.speed_index = np.zeros(self.n_envs, dtype=np.intp)
        self.time = np.zeros(self.n_envs)
        self.steps = np.zeros(self.n_envs, dtype=np.intp)
        self.final_obs = np.zeros((self.n_envs, KIN_VEHICLES, KIN_FEATURES), dtype=np.float32)
        self.reward_components: dict[str, np.ndarray] = {}
        self._reset_envs(np.arange(self.n_envs))

    @property
    def crashed(self) -> np.ndarray:
        """(n,) bool: whether each env's ego has crashed."""
        return self.vehicle_crashed[:, 0]

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start a new episode in every env; ``seed`` reseeds the generator first.

        :return: (n, 5, 5) float32 kinematics observations.
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._reset_envs(np.arange(self.n_envs))
        return self.observe("kinematics")

    def _reset_envs(self, envs: np.ndarray) -> None:
        """Place new vehicles in ``envs`` (an index array) as ``HighwayEnv._create_vehicles`` does."""
        k, n_vehicles, cfg, rng = envs.size, self.n_vehicles, self.config, self.rng
        if k == 0:
            return
        lanes = rng.integers(0, cfg.lanes_count, size=(k, n_vehicles))
        speed = np.empty((k, n_vehicles))
        speed[:, 0] = EGO_INITIAL_SPEED
        speed[:, 1:] = rng.uniform(0.7 * SPEED_LIMIT, 0.8 * SPEED_LIMIT, size=(k, n_vehicles - 1))
        spacing = np.full(n_vehicles, 1.0 / cfg.vehicles_density)
        spacing[0] = cfg.ego_spacing
        offset = spacing * (12.0 + speed) * np.exp(-5.0 / 40.0 * cfg.lanes_count)
        gaps = offset * rng.uniform(0.9, 1.1, size=(k, n_vehicles))
        # create_random puts each vehicle ahead of the frontmost one so far (3 offsets for the first).
        gaps[:, 0] += 3.0 * offset[:, 0]
        self.x[envs] = np.cumsum(gaps, axis=1)
        self.y[envs] = LANE_WIDTH * lanes
        self.speed[envs] = speed
        self.heading[envs] = 0.0
        self.lane[envs] = lanes
        self.target_speed[envs] = np.clip(speed, 0.0, SPEED_LIMIT)
        self.idm_delta[envs] = rng.uniform(*IDM_DELTA_RANGE, size=(k, n_vehicles))
        self.vehicle_crashed[envs] = False
        self.target_lane[envs] = lanes[:, 0]
        self.target_speed[envs, 0] = EGO_INITIAL_SPEED
        self.speed_index[envs] = _speed_to_index(speed[:, 0])
        self.time[envs] = 0.0
        self.steps[envs] = 0

    def observe(self, name: str) -> np.ndarray:
        """One view of every env's current state: (n, *view_space(name).shape) float32."""
        if name not in VIEW_FUNCTIONS:
            raise ValueError(f"unknown view {name!r}; allowed: {list(VIEW_NAMES)}")
        return VIEW_FUNCTIONS[name](self.x, self.y, self.speed, self.heading, self.config.lanes_count)

    def _apply_meta_actions(self, actions: np.ndarray) -> None:
        """``MDPVehicle.act``: move the ego's speed index or target lane."""
        faster, slower = actions == FASTER, actions == SLOWER
        if faster.any() or slower.any():
            shifted = _speed_to_index(self.speed[:, 0]) + faster.astype(np.intp) - slower.astype(np.intp)
            shifted = np.clip(shifted, 0, TARGET_SPEEDS.size - 1)
            change = faster | slower
            self.speed_index = np.where(change, shifted, self.speed_index)
            self.target_speed[:, 0] = np.where(
                change, TARGET_SPEEDS[self.speed_index], self.target_speed[:, 0]
            )
        shift = (actions == LANE_RIGHT).astype(np.intp) - (actions == LANE_LEFT).astype(np.intp)
        candidate = np.clip(self.target_lane + shift, 0, self.config.lanes_count - 1)
        # StraightLane.is_reachable_from: within two lane widths laterally.
        reachable = np.abs(self.y[:, 0] - LANE_WIDTH * candidate) <= 2 * LANE_WIDTH
        self.target_lane = np.where((shift != 0) & reachable, candidate, self.target_lane)

    def _substep(self) -> None:
        """One ``Road.act`` + ``Road.step`` of ``dt`` seconds, then the ego's collision check."""
        x, y, speed, heading, dt = self.x, self.y, self.speed, self.heading, self.dt
        crashed = self.vehicle_crashed
        ego_speed, ego_heading = speed[:, 0], heading[:, 0]

        # Ego: ControlledVehicle.steering_control / speed_control on a straight lane.
        ego_not_zero = not_zero(ego_speed)
        lateral = y[:, 0] - LANE_WIDTH * self.target_lane
        heading_command = np.arcsin(np.clip(-KP_LATERAL * lateral / ego_not_zero, -1, 1))
        heading_ref = np.clip(heading_command, -np.pi / 4, np.pi / 4)
        heading_error = ((heading_ref - ego_heading + np.pi) % (2 * np.pi)) - np.pi
        slip = np.arcsin(np.clip(LENGTH / 2 / ego_not_zero * (KP_HEADING * heading_error), -1, 1))
        steering = np.clip(np.arctan(2 * np.tan(slip)), -MAX_STEERING_ANGLE, MAX_STEERING_ANGLE)
        ego_acc = KP_A * (self.target_speed[:, 0] - ego_speed)

        # Others: IDM behind the nearest vehicle ahead within 3 m of their lane centre
        # (Road.neighbour_vehicles with on_lane margin 1); ties go to the later vehicle, as there.
        vx = speed * np.cos(heading)
        acc = np.zeros_like(speed)
        acc[:, 0] = ego_acc
        if self.n_vehicles > 1:
            x_o, y_o, v_o = x[:, 1:], y[:, 1:], speed[:, 1:]
            ahead = (x[:, None, :] >= x_o[:, :, None]) & (
                np.abs(y[:, None, :] - y_o[:, :, None]) <= LANE_WIDTH / 2 + 1
            )
            idx = np.arange(self.n_vehicles - 1)
            ahead[:, idx, idx + 1] = False
            front_x = np.where(ahead, x[:, None, :], np.inf)[:, :, ::-1]
            front = self.n_vehicles - 1 - np.argmin(front_x, axis=2)
            has_front = ahead.any(axis=2)
            target = not_zero(self.target_speed[:, 1:])
            free = IDM_COMFORT_ACC_MAX * (
                1 - np.power(np.maximum(v_o, 0) / np.abs(target), self.idm_delta[:, 1:])
            )
            gap = np.take_along_axis(x, front, axis=1) - x_o
            dv = v_o - np.take_along_axis(vx, front, axis=1)
            ab = -IDM_COMFORT_ACC_MAX * IDM_COMFORT_ACC_MIN
            desired = IDM_DISTANCE_WANTED + v_o * IDM_TIME_WANTED + v_o * dv / (2 * np.sqrt(ab))
            interaction = IDM_COMFORT_ACC_MAX * np.power(desired / not_zero(gap), 2)
            acc[:, 1:] = np.clip(free - np.where(has_front, interaction, 0.0), -IDM_ACC_MAX, IDM_ACC_MAX)

        # Vehicle.clip_actions: crashed vehicles brake to a stop and steer straight; speed limits.
        acc = np.where(crashed, -speed, acc)
        steering = np.where(crashed[:, 0], 0.0, steering)
        acc = np.where(speed > MAX_SPEED, np.minimum(acc, MAX_SPEED - speed), acc)
        acc = np.where(speed < MIN_SPEED, np.maximum(acc, MIN_SPEED - speed), acc)

        # Vehicle.step (kinematic bicycle); the others never steer, so only the ego turns.
        beta = np.arctan(0.5 * np.tan(steering))
        x[:, 1:] += speed[:, 1:] * dt
        x[:, 0] += ego_speed * np.cos(ego_heading + beta) * dt
        y[:, 0] += ego_speed * np.sin(ego_heading + beta) * dt
        heading[:, 0] += ego_speed * np.sin(beta) / (LENGTH / 2) * dt
        speed += acc * dt
        # get_closest_lane_index: the nearest lane centre, the lower index on a tie.
        nearest = np.ceil(y[:, 0] / LANE_WIDTH - 0.5).astype(np.intp)
        self.lane[:, 0] = np.clip(nearest, 0, self.config.lanes_count - 1)

        if self.n_vehicles > 1:
            hit = (np.abs(x[:, 1:] - x[:, :1]) < LENGTH) & (np.abs(y[:, 1:] - y[:, :1]) < WIDTH)
            crashed[:, 1:] |= hit
            crashed[:, 0] |= hit.any(axis=1)

    def _rewards(self) -> dict[str, np.ndarray]:
        """``HighwayEnv._rewards`` per env: the unweighted terms, each (n,) float64."""
        cfg = self.config
        forward_speed = self.speed[:, 0] * np.cos(self.heading[:, 0])
        low, high = cfg.reward_speed_range
        on_road = (self.y[:, 0] >= -LANE_WIDTH / 2) & (
            self.y[:, 0] <= LANE_WIDTH * (cfg.lanes_count - 1) + LANE_WIDTH / 2
        )
        return {
            "collision_reward": self.crashed.astype(np.float64),
            "right_lane_reward": self.target_lane / max(cfg.lanes_count - 1, 1),
            "high_speed_reward": np.clip(lmap(forward_speed, low, high, 0.0, 1.0), 0.0, 1.0),
            "on_road_reward": on_road.astype(np.float64),
        }

    def _reward(self, terms: dict[str, np.ndarray]) -> np.ndarray:
        """``HighwayEnv._reward``: weighted sum, optionally normalised, times the on-road term."""
        cfg = self.config
        reward = (
            cfg.collision_reward * terms["collision_reward"]
            + cfg.right_lane_reward * terms["right_lane_reward"]
            + cfg.high_speed_reward * terms["high_speed_reward"]
        )
        if cfg.normalize_reward:
            reward = lmap(
                reward, cfg.collision_reward, cfg.high_speed_reward + cfg.right_lane_reward, 0.0, 1.0
            )
        return reward * terms["on_road_reward"]

    def _advance(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Step every env without resetting: (obs, reward, terminated, truncated)."""
        actions = np.asarray(actions)
        integral = np.issubdtype(actions.dtype, np.integer) or (
            np.issubdtype(actions.dtype, np.floating) and bool(np.all(np.mod(actions, 1) == 0))
        )
        if actions.size != self.n_envs or not integral or np.any((actions < 0) | (actions > SLOWER)):
            raise ValueError(f"actions must be {self.n_envs} integers in [0, 5), got {actions!r}")
        actions = actions.reshape(self.n_envs).astype(np.intp)
        self.time += 1.0 / self.config.policy_frequency
        self.steps += 1
        self._apply_meta_actions(actions)
        for _ in range(self.frames):
            self._substep()
        obs = self.observe("kinematics")
        self.reward_components = self._rewards()
        reward = self._reward(self.reward_components)
        terminated = self.crashed.copy()
        truncated = self.time >= self.config.duration
        return obs, reward, terminated, truncated

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Apply one meta-action per env for ``1 / policy_frequency`` seconds.

        :param actions: (n,) ints in [0, 5): LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER.
        :return: obs (n, 5, 5) float32, reward (n,) float64, terminated (n,) bool, truncated (n,) bool.
            Envs that ended are reset: their returned obs is the new episode's first one (the last one
            of the ended episode is in ``final_obs``).
        """
        obs, reward, terminated, truncated = self._advance(actions)
        self.final_obs = obs
        done = np.flatnonzero(terminated | truncated)
        if done.size:
            obs = obs.copy()
            self._reset_envs(done)
            fresh = self.observe("kinematics")
            obs[done] = fresh[done]
        return obs, reward, terminated, truncated


class FastHighwayEnv(gym.Env):
    """One fast highway scene (a :class:`FastHighwayVec` of size 1, no auto-reset) as a gymnasium env.

    :param config: scene and reward settings (defaults: ``highway-fast-v0``'s).
    :param overrides: :class:`FastHighwayConfig` fields replacing those of ``config``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, config: FastHighwayConfig | None = None, **overrides: Any) -> None:
        super().__init__()
        self.check_overrides(overrides)
        config = dataclasses.replace(config or FastHighwayConfig(), **overrides)
        self.config = config
        self.observation_space = view_space("kinematics")
        self.action_space = gym.spaces.Discrete(5)
        self.vec = FastHighwayVec(1, config)
        self._started = False
        self._seen: dict[str, np.ndarray] = {}
        """The views of the current state computed so far: a sensor wrapper asks again for the one
        ``step`` returned."""

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``seed`` seeds ``self.np_random``, which places the vehicles."""
        super().reset(seed=seed)
        self.vec.rng = self.np_random
        obs = self.vec.reset()[0]
        self._started = True
        self._seen = {"kinematics": obs}
        return obs.copy(), self._info(self.vec._rewards(), None)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply a meta-action (0 LANE_LEFT, 1 IDLE, 2 LANE_RIGHT, 3 FASTER, 4 SLOWER) for one policy step."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if not self.action_space.contains(action):
            raise ValueError(f"action must be an int in [0, 5), got {action!r}")
        obs, reward, terminated, truncated = self.vec._advance(np.array([int(action)]))
        self._seen = {"kinematics": obs[0]}
        info = self._info(self.vec.reward_components, action)
        return obs[0].copy(), float(reward[0]), bool(terminated[0]), bool(truncated[0]), info

    def _info(self, terms: dict[str, np.ndarray], action: Any) -> dict[str, Any]:
        return {
            "speed": float(self.vec.speed[0, 0]),
            "crashed": bool(self.vec.crashed[0]),
            "action": action,
            "rewards": {name: float(value[0]) for name, value in terms.items()},
        }

    @staticmethod
    def check_overrides(overrides: dict[str, Any]) -> None:
        """Raise ``ValueError`` for a key that is no :class:`FastHighwayConfig` field, naming the allowed
        ones, or for values the config rejects."""
        allowed = [field.name for field in dataclasses.fields(FastHighwayConfig)]
        unknown = sorted(set(overrides) - set(allowed))
        if unknown:
            raise ValueError(f"unknown FastHighwayConfig key(s) {unknown}; allowed: {', '.join(allowed)}")
        FastHighwayConfig(**overrides)

    def view_space(self, name: str) -> gym.spaces.Box:
        """The ``Box`` of a view (the sensor interface of :mod:`dospcot.envs.sensors`)."""
        return view_space(name)

    def observe(self, name: str) -> np.ndarray:
        """One view of the current state, of shape ``view_space(name).shape`` (float32), computed once
        per state."""
        if name not in self._seen:
            self._seen[name] = self.vec.observe(name)[0]
        return self._seen[name].copy()
