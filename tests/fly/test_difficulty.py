"""The contract's difficulty promise (DESIGN): at v0 = 2 m/s with 5 obstacles a straight flight
collides in most episodes, while the expert succeeds in at least 95 % of them: the evaluation
grid, 140 episodes without rendering.
"""

from orbitdata.fly import fly_grid

EPISODES = 20  # per setting, as in the README's table


def test_the_expert_succeeds_where_straight_flight_collides():
    expert = fly_grid("expert", [1, 3, 5], [1.0, 2.0], EPISODES)
    risky = fly_grid("risky", [5], [2.0], EPISODES)[0]
    for cell in expert:
        assert cell.success_rate >= 0.95, cell
    hard = next(c for c in expert if (c.obstacles, c.speed) == (5, 2.0))
    print(
        f"\nexpert: {sum(c.success for c in expert)}/{len(expert) * EPISODES} successes on the grid, "
        f"{hard.success}/{EPISODES} at 5 obstacles and 2 m/s; straight flight (risky) there: "
        f"{risky.collision}/{EPISODES} collisions"
    )
    assert risky.collision / risky.episodes > 0.5, risky
