"""The goal-reaching task's own stages (docs/goal.md): reward and termination, the goal part of the
reset, and the goal part of the observation.

The task shares everything else with tracking: physics and PD control (`control.py`, absolute
targets), the reference state initialization from the motion library (`reset.py`'s
`reset_masked`, which `goal_reset` follows), and the character's own state in the observation
(`observe.py`'s `observe` with no reference blocks, which `goal_observe` follows by writing the
goal's three columns after it).

Goals lie on the ground (z is not used), at a distance in [min_distance, max_distance] from the
root in a uniform direction. Random numbers come from Warp's counter-based generator with the
reset's offset `(iteration * horizon + t) * N + n` and seeds of their own (`params.seed` for goals
drawn when one is reached, `params.seed + 1` for goals drawn at a reset), so a replayed graph
draws new goals with no host involvement.
"""

import warp as wp

from env.rotation import heading_inverse, qrotate

wp.set_module_options({"enable_backward": False})

# Bit of `failure[n]` for a fall: the root below an absolute height, the meaning tracking's
# LOW_ROOT cause has (tracking.py), so the rollout statistics count both the same way.
CAUSE_LOW_ROOT = wp.constant(4)
TWO_PI = wp.constant(6.283185307179586)

# Columns of `goal_counters[n, :]` (src/env/task.rs: GoalCounter).
GOALS_THIS_EPISODE = wp.constant(0)
EPISODES_ENDED = wp.constant(1)
GOALS_IN_ENDED_EPISODES = wp.constant(2)
FALLS = wp.constant(3)
FIRST_EPISODE_GOALS = wp.constant(4)
FIRST_EPISODE_FELL = wp.constant(5)


@wp.struct
class GoalParams:
    """Run-time parameters (config `[goal]`, `[ppo].horizon`, `[run].seed`)."""

    seed: wp.int32
    horizon: wp.int32
    # Goal distance range from the root (m) and the reach radius (horizontal, m).
    min_distance: wp.float32
    max_distance: wp.float32
    reach_radius: wp.float32
    # Reward: progress_weight * (decrease of the horizontal distance this step, m)
    # + bonus_weight per goal reached.
    progress_weight: wp.float32
    bonus_weight: wp.float32
    # A fall: the root below this height (m).
    fall_height: wp.float32
    max_episode_steps: wp.int32


@wp.func
def horizontal_distance(qpos: wp.array2d(dtype=wp.float32), n: wp.int32, goal: wp.array2d(dtype=wp.float32)) -> wp.float32:
    dx = goal[n, 0] - qpos[n, 0]
    dy = goal[n, 1] - qpos[n, 1]
    return wp.sqrt(dx * dx + dy * dy)


@wp.func
def place_goal(
    state: wp.uint32,
    qpos: wp.array2d(dtype=wp.float32),
    n: wp.int32,
    params: GoalParams,
    goal: wp.array2d(dtype=wp.float32),
) -> wp.float32:
    """A new goal around env n's root, direction and distance uniform; returns its distance."""
    angle = TWO_PI * wp.randf(state)
    distance = params.min_distance + (params.max_distance - params.min_distance) * wp.randf(state)
    goal[n, 0] = qpos[n, 0] + distance * wp.cos(angle)
    goal[n, 1] = qpos[n, 1] + distance * wp.sin(angle)
    return distance


@wp.kernel
def goal_reward_termination(
    qpos: wp.array2d(dtype=wp.float32),
    params: GoalParams,
    t: wp.int32,
    iteration: wp.array(dtype=wp.int32),
    episode_step: wp.array(dtype=wp.int32),
    goal: wp.array2d(dtype=wp.float32),
    goal_distance: wp.array(dtype=wp.float32),
    rewards: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    done: wp.array(dtype=wp.int32),
    failure: wp.array(dtype=wp.int32),
    goal_counters: wp.array2d(dtype=wp.int32),
):
    """One thread per env n, after the physics substeps: `d` the root's horizontal distance to
    its goal, reward `progress_weight * (goal_distance[n] - d)` plus `bonus_weight` when
    `d < reach_radius` (the goal is reached, and the next one is placed at once around the root,
    `goal_distance[n]` its distance; otherwise `goal_distance[n] = d`); failure (a fall, the
    LOW_ROOT bit) when the root is below `fall_height`; truncation at `max_episode_steps`.
    Writes `rewards/terminated/truncated[t, n]`, `done[n]`, `failure[n]`, advances
    `episode_step[n]` and the env's counters (`goal_counters[n, :]`: goals this episode; episodes
    ended, goals in them and falls, since the counters were cleared; the first ended episode's
    goals and whether it fell)."""
    n = wp.tid()
    d = horizontal_distance(qpos, n, goal)
    reward = params.progress_weight * (goal_distance[n] - d)
    goals = goal_counters[n, GOALS_THIS_EPISODE]
    if d < params.reach_radius:
        reward = reward + params.bonus_weight
        goals = goals + 1
        state = wp.rand_init(params.seed, (iteration[0] * params.horizon + t) * done.shape[0] + n)
        d = place_goal(state, qpos, n, params, goal)
    goal_distance[n] = d

    step = episode_step[n]
    failed = 0
    causes = 0
    if qpos[n, 2] < params.fall_height:
        failed = 1
        causes = CAUSE_LOW_ROOT
    ended = 0
    if step + 1 >= params.max_episode_steps:
        ended = 1
    over = wp.max(failed, ended)

    rewards[t, n] = reward
    terminated[t, n] = failed
    truncated[t, n] = ended
    done[n] = over
    failure[n] = causes
    episode_step[n] = step + 1
    goal_counters[n, GOALS_THIS_EPISODE] = goals
    if over != 0:
        if goal_counters[n, EPISODES_ENDED] == 0:
            goal_counters[n, FIRST_EPISODE_GOALS] = goals
            goal_counters[n, FIRST_EPISODE_FELL] = failed
        goal_counters[n, EPISODES_ENDED] = goal_counters[n, EPISODES_ENDED] + 1
        goal_counters[n, GOALS_IN_ENDED_EPISODES] = goal_counters[n, GOALS_IN_ENDED_EPISODES] + goals
        goal_counters[n, FALLS] = goal_counters[n, FALLS] + failed


@wp.kernel
def goal_reset(
    done: wp.array(dtype=wp.int32),
    params: GoalParams,
    t: wp.int32,
    iteration: wp.array(dtype=wp.int32),
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    goal: wp.array2d(dtype=wp.float32),
    goal_distance: wp.array(dtype=wp.float32),
    goal_counters: wp.array2d(dtype=wp.int32),
):
    """After `reset_masked` (which put env n at a reference state of the library), for every env
    with done[n] != 0: at rest (qvel 0), a new goal around the new root, `goal_distance[n]` its
    distance, no goals yet this episode."""
    n = wp.tid()
    if done[n] == 0:
        return
    for k in range(qvel.shape[1]):
        qvel[n, k] = 0.0
    state = wp.rand_init(params.seed + 1, (iteration[0] * params.horizon + t) * done.shape[0] + n)
    goal_distance[n] = place_goal(state, qpos, n, params, goal)
    goal_counters[n, GOALS_THIS_EPISODE] = 0


@wp.kernel
def goal_observe(
    qpos: wp.array2d(dtype=wp.float32),
    goal: wp.array2d(dtype=wp.float32),
    column: wp.int32,
    obs: wp.array2d(dtype=wp.float32),
):
    """One thread per env: the goal in the heading frame of the root, `obs[n, column..+3]` = x, y
    of (goal - root) rotated by the root's inverse heading, and the horizontal distance. Runs
    after `observe`, which writes the character's own state in the columns before."""
    n = wp.tid()
    h = heading_inverse(wp.vec4(qpos[n, 3], qpos[n, 4], qpos[n, 5], qpos[n, 6]))
    rel = wp.vec3(goal[n, 0] - qpos[n, 0], goal[n, 1] - qpos[n, 1], 0.0)
    local = qrotate(h, rel)
    obs[n, column] = local[0]
    obs[n, column + 1] = local[1]
    obs[n, column + 2] = wp.sqrt(rel[0] * rel[0] + rel[1] * rel[1])

# Launch contracts (docs/kernels.md, "Launch contracts"). Kept at the end of the file: Warp's
# generated CUDA quotes source line numbers, so lines added above a kernel would change its PTX.
LAUNCH = {
    "goal_reward_termination": (
        "dim == len(done)",
        "dim <= extent(qpos, 0)",
        "dim <= len(episode_step)",
        "dim <= extent(goal, 0)",
        "dim <= len(goal_distance)",
        "dim <= extent(rewards, 1)",
        "dim <= extent(terminated, 1)",
        "dim <= extent(truncated, 1)",
        "dim <= len(failure)",
        "dim <= extent(goal_counters, 0)",
    ),
    "goal_reset": (
        "dim == len(done)",
        "dim <= extent(qpos, 0)",
        "dim <= extent(qvel, 0)",
        "dim <= extent(goal, 0)",
        "dim <= len(goal_distance)",
        "dim <= extent(goal_counters, 0)",
    ),
    "goal_observe": (
        "dim == extent(obs, 0)",
        "dim <= extent(qpos, 0)",
        "dim <= extent(goal, 0)",
    ),
}
