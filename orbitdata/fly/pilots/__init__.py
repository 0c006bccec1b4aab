"""The built-in pilots, the three levels of the dataset: expert (OMPL RRT* + PD tracking; on the
dynamic tier MPPI over the episode's true dynamics, :mod:`~orbitdata.fly.pilots.dynamic_expert`),
risky and exploratory, with their controller, planner and trajectory; and ``expert-snapshot``, the
static expert as a weak pilot of the dynamic tier. Make one by name with
:func:`orbitdata.fly.make_pilot`; their settings are :mod:`orbitdata.fly.pilots.config`.
"""
