"""The built-in pilots, the three levels of the dataset: expert (OMPL RRT* + PD tracking), risky
and exploratory, with their controller, planner and trajectory. Make one by name with
:func:`orbitdata.fly.make_pilot`; their settings are :mod:`orbitdata.fly.pilots.config`.
"""
